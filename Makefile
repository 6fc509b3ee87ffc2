# Two commands do everything on a fresh Debian 12 machine: `make demo` and `make test`.
# Debian's cmake is used explicitly: fmpy installs a pip cmake into .venv/bin.
CMAKE   := /usr/bin/cmake
CTEST   := /usr/bin/ctest
BUILD   ?= build
JOBS    ?= $(shell nproc)
PY      := .venv/bin/python
PYLIB   := plugins/python/stiff/_lib

# Regenerate the committed ABI baseline after an intended ABI change.
abi-baseline: build
	@mkdir -p abi && abidw --exported-interfaces-only --headers-dir capi/include/stiff --drop-private-types --no-show-locs --no-corpus-path --out-file abi/libstiff_c.abi $(BUILD)/capi/libstiff_c.so && echo "wrote abi/libstiff_c.abi"

.PHONY: abi-baseline all setup build install-python demo test test-cpp test-python bench fuzz clean format

all: build

setup:
	@bash scripts/setup.sh

$(BUILD)/build.ninja:
	@$(CMAKE) -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release \
	  >/dev/null

build: setup $(BUILD)/build.ninja
	@$(CMAKE) --build $(BUILD) -j $(JOBS) > $(BUILD)/build.log 2>&1 || { tail -n 60 $(BUILD)/build.log; echo "build failed (full log: $(BUILD)/build.log)"; exit 1; }
	@$(MAKE) --no-print-directory install-python

# Bundle the C library (and FMU binaries) into the Python package and install it into .venv.
install-python:
	@mkdir -p $(PYLIB)
	@cp -L $(BUILD)/capi/libstiff_c.so $(PYLIB)/libstiff_c.so
	@rm -rf plugins/python/stiff/_data && mkdir -p plugins/python/stiff/_data && cp -r examples/robots examples/paper examples/truths examples/paths plugins/python/stiff/_data/
	@if [ -d $(BUILD)/fmu/binaries ]; then rm -rf $(PYLIB)/fmu && cp -r $(BUILD)/fmu/binaries $(PYLIB)/fmu; fi
	@$(PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation ./plugins/python >/dev/null

demo: build
	@.venv/bin/stiff demo

test: build test-cpp test-python

test-cpp:
	@cd $(BUILD) && $(CTEST) --output-on-failure -j $(JOBS) -LE "slow|python"

test-python:
	@STIFF_BUILD_DIR=$(CURDIR)/$(BUILD) $(PY) -m pytest -q plugins/python/tests tests/fmu tests/bad_inputs

bench: build
	@bash bench/run

# Long libFuzzer runs (FUZZ_SECONDS_PER_TARGET, default 600 s each; new inputs in
# build-fuzz/corpus, `bash scripts/ci-fuzz.sh --merge` keeps those that add coverage). CI runs
# scripts/ci-fuzz.sh: fixed executions and seed, about a minute. Sanitizers: TESTING.md.
fuzz:
	@bash scripts/ci-fuzz.sh --long

clean:
	rm -rf $(BUILD) out $(PYLIB) plugins/python/stiff/_data plugins/python/build plugins/python/*.egg-info

format:
	@clang-format -i $$(git ls-files '*.cpp' '*.hpp' '*.h' '*.c')
