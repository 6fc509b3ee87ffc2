#!/usr/bin/env bash
# Fuzzing (docs/reliability.md): builds the libFuzzer targets of tests/fuzz with clang
# (CMakePresets.json "fuzz", build-fuzz, ASan + UBSan) and runs each on its seed corpus.
#   bash scripts/ci-fuzz.sh            # CI: about a minute in total (FUZZ_SECONDS, default 60)
#   bash scripts/ci-fuzz.sh --long     # make fuzz: FUZZ_SECONDS_PER_TARGET each (default 600)
#   bash scripts/ci-fuzz.sh --long gcode fit_json    # only these targets
# New interesting inputs go to build-fuzz/corpus/<target> (the repository's seeds in
# tests/fuzz/corpus/<target> are only read); a crash is saved to
# build-fuzz/artifacts/<target>/crash-*, the run fails and prints how to reproduce it. Add a
# fixed crash's input to tests/fuzz/corpus/<target>/ as a regression: the FuzzCorpus gtest
# replays it in `make test`. A summary (executions, coverage) is written to
# build-fuzz/fuzz-stats.md.
set -euo pipefail
cd "$(dirname "$0")/.."
CMAKE=/usr/bin/cmake
JOBS=${JOBS:-$(nproc)}
long=0
if [[ ${1:-} == --long ]]; then long=1; shift; fi
only=("$@")

command -v clang++ >/dev/null ||
  { echo "ci-fuzz: clang++ not found (Debian packages clang, libclang-rt-14-dev: make setup)" >&2; exit 1; }

echo "== ci-fuzz: configure and build (build-fuzz)"
"$CMAKE" --preset fuzz > /tmp/stiff-fuzz-configure.log 2>&1 ||
  { cat /tmp/stiff-fuzz-configure.log; exit 1; }
if ! "$CMAKE" --build build-fuzz -j "$JOBS" --target stiff_fuzzers > build-fuzz/build.log 2>&1; then
  tail -n 80 build-fuzz/build.log; echo "ci-fuzz: build failed (build-fuzz/build.log)"; exit 1
fi

mapfile -t targets < build-fuzz/tests/fuzz/targets.txt
if ((${#only[@]})); then targets=("${only[@]}"); fi
if ((long)); then
  per=${FUZZ_SECONDS_PER_TARGET:-600}
else
  total=${FUZZ_SECONDS:-60}
  per=$((total / ${#targets[@]})); ((per >= 3)) || per=3
fi

export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
export LSAN_OPTIONS=suppressions=$PWD/tests/fuzz/lsan.supp:print_suppressions=0
stats=build-fuzz/fuzz-stats.md
{
  echo "| target | seconds | executions | exec/s | coverage (edges) | features | corpus | result |"
  echo "| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |"
} > "$stats"
failed=()
for t in "${targets[@]}"; do
  bin=build-fuzz/tests/fuzz/stiff_fuzz_$t
  [[ -x $bin ]] || { echo "ci-fuzz: no target $t" >&2; exit 2; }
  work=build-fuzz/corpus/$t art=build-fuzz/artifacts/$t log=build-fuzz/fuzz-$t.log
  mkdir -p "$work" "$art"
  echo "== ci-fuzz: $t for ${per}s"
  result=ok
  if ! "$bin" -max_total_time="$per" -print_final_stats=1 -timeout=20 -rss_limit_mb=2048 \
       -max_len=8192 -artifact_prefix="$art/" "$work" "tests/fuzz/corpus/$t" > "$log" 2>&1; then
    result=FAILED failed+=("$t")
    grep -E "ERROR|finding|SUMMARY|Test unit written" "$log" | head -n 20 || true
    echo "   reproduce: $bin $art/crash-*   (full log: $log)"
  fi
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -n1)
  last=$(grep -E '^#[0-9]+' "$log" | tail -n1 || true)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<< "$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<< "$last")
  corp=$(sed -n 's/.* corp: \([0-9]*\).*/\1/p' <<< "$last")
  printf '| %s | %s | %s | %s | %s | %s | %s | %s |\n' "$t" "$per" "${execs:-?}" "${rate:-?}" \
    "${cov:-?}" "${ft:-?}" "${corp:-?}" "$result" >> "$stats"
  echo "   executions ${execs:-?}, ${rate:-?}/s, cov ${cov:-?}, ft ${ft:-?}, corpus ${corp:-?}: $result"
done
echo; cat "$stats"
if ((${#failed[@]})); then
  echo "ci-fuzz: findings in: ${failed[*]} (inputs under build-fuzz/artifacts/)" >&2
  exit 1
fi
echo "ci-fuzz: ${#targets[@]} targets, no findings"
