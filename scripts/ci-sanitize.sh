#!/usr/bin/env bash
# Sanitizer CI (docs/reliability.md): builds everything (core, C ABI, C and C++ tests, FMU) with
# AddressSanitizer + UndefinedBehaviorSanitizer (CMakePresets.json "asan-ubsan", build-asan-ubsan)
# and runs the whole ctest suite except slow tests (label `slow`, or "Slow" in the name), the
# python ones and the outside-project install test (label `install`: it links an unsanitized
# consumer against the sanitized library); then builds the concurrency test with ThreadSanitizer (preset "tsan",
# build-tsan) and runs every test whose name contains "Threads".
#   bash scripts/ci-sanitize.sh            # both
#   bash scripts/ci-sanitize.sh asan       # or: tsan
# Uses Debian's /usr/bin/cmake (fmpy installs another one into .venv). JOBS=n sets parallelism.
set -euo pipefail
cd "$(dirname "$0")/.."
CMAKE=/usr/bin/cmake
CTEST=/usr/bin/ctest
JOBS=${JOBS:-$(nproc)}
what=${1:-all}
case $what in all | asan | tsan) ;; *) echo "usage: $0 [all|asan|tsan]" >&2; exit 2 ;; esac

step() { printf '\n== ci-sanitize: %s (%s)\n' "$1" "$(date +%H:%M:%S)"; }

configure_and_build() {  # preset, build dir, targets...
  local preset=$1 dir=$2; shift 2
  step "configure $preset"
  "$CMAKE" --preset "$preset" > "/tmp/stiff-$preset-configure.log" 2>&1 ||
    { cat "/tmp/stiff-$preset-configure.log"; exit 1; }
  step "build $preset ${*:-(all)}"
  local targets=(); for t in "$@"; do targets+=(--target "$t"); done
  if ! "$CMAKE" --build "$dir" -j "$JOBS" "${targets[@]}" > "$dir/build.log" 2>&1; then
    tail -n 80 "$dir/build.log"; echo "ci-sanitize: $preset build failed ($dir/build.log)"; exit 1
  fi
}

if [[ $what == all || $what == asan ]]; then
  configure_and_build asan-ubsan build-asan-ubsan
  step "ctest under ASan+UBSan"
  # detect_leaks: LeakSanitizer at exit; halt_on_error: the first UB report fails the test.
  export ASAN_OPTIONS=detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=1:check_initialization_order=1
  export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
  export LSAN_OPTIONS=suppressions=$PWD/tests/fuzz/lsan.supp:print_suppressions=0
  (cd build-asan-ubsan && "$CTEST" --output-on-failure --no-tests=error -j "$JOBS" \
     -LE "slow|python|install" -E "Slow" --timeout 900)
fi

if [[ $what == all || $what == tsan ]]; then
  configure_and_build tsan build-tsan stiff_threads_test
  step "ctest under TSan"
  export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1
  (cd build-tsan && "$CTEST" --output-on-failure --no-tests=error -R "Threads" --timeout 900)
fi
step "done"
