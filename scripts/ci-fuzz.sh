#!/usr/bin/env bash
# Fuzzing (docs/reliability.md): builds the libFuzzer targets of tests/fuzz with clang
# (CMakePresets.json "fuzz", build-fuzz, ASan + UBSan) and runs each on its seed corpus.
#   bash scripts/ci-fuzz.sh            # CI: deterministic, about a minute in total
#   bash scripts/ci-fuzz.sh --long     # make fuzz: FUZZ_SECONDS_PER_TARGET each (default 600)
#   bash scripts/ci-fuzz.sh --long gcode fit_json    # only these targets
#   bash scripts/ci-fuzz.sh --merge    # add the build-fuzz/corpus inputs that cover new edges
#                                      # to tests/fuzz/corpus (libFuzzer -merge=1)
# CI mode runs a fixed number of executions per target (RUNS below, or FUZZ_RUNS for all) with
# a fixed seed (FUZZ_SEED, default 1) on a fresh copy of tests/fuzz/corpus/<target>: the same
# code gives the same executions, so a CI failure is reproducible and not a lucky draw of a
# time-based run. It finds only what is close to the seeds; hunting is --long.
# --long writes new interesting inputs to build-fuzz/corpus/<target> (the repository's seeds
# are only read). A crash is saved to build-fuzz/artifacts/<target>/crash-*, the run fails and
# prints how to reproduce it. Add a fixed crash's input to tests/fuzz/corpus/<target>/ as a
# regression: the FuzzCorpus gtest replays it in `make test`. A summary (executions,
# coverage, seconds) is written to build-fuzz/fuzz-stats.md.
set -euo pipefail
cd "$(dirname "$0")/.."
CMAKE=/usr/bin/cmake
JOBS=${JOBS:-$(nproc)}
mode=ci
case ${1:-} in
  --long) mode=long; shift ;;
  --merge) mode=merge; shift ;;
esac
only=("$@")

# Executions per target in CI mode, sized on the 2-core development machine to about 60 s in
# all (5-7 s a target, capi_arrays 17 s; docs/reliability.md).
declare -A RUNS=(
  [measurements_csv]=40000 [robot_yaml]=20000 [robot_urdf]=4000 [fit_json]=40000
  [truth_yaml]=25000 [noise_yaml]=25000 [capi_arrays]=1000 [path_csv]=50000 [gcode]=15000
)

command -v clang++ >/dev/null ||
  { echo "ci-fuzz: clang++ not found (Debian packages clang, libclang-rt-14-dev: make setup)" >&2; exit 1; }

echo "== ci-fuzz: configure and build (build-fuzz)"
t0=$(date +%s)
"$CMAKE" --preset fuzz > /tmp/stiff-fuzz-configure.log 2>&1 ||
  { cat /tmp/stiff-fuzz-configure.log; exit 1; }
if ! "$CMAKE" --build build-fuzz -j "$JOBS" --target stiff_fuzzers > build-fuzz/build.log 2>&1; then
  tail -n 80 build-fuzz/build.log; echo "ci-fuzz: build failed (build-fuzz/build.log)"; exit 1
fi
echo "   build: $(($(date +%s) - t0)) s"

mapfile -t targets < build-fuzz/tests/fuzz/targets.txt
if ((${#only[@]})); then targets=("${only[@]}"); fi

export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
export LSAN_OPTIONS=suppressions=$PWD/tests/fuzz/lsan.supp:print_suppressions=0
common=(-timeout=20 -rss_limit_mb=2048)
# Inputs as large as a deep document that overflowed a parser's stack (50,000 nested URDF
# elements, 150 kB; YAML at 400 levels is 800 bytes): the readers refuse nesting beyond 64
# levels, and the fuzzers must be able to produce what would break that. The other targets keep
# 8 kB (large inputs only slow them down).
declare -A MAX_LEN=(
  [robot_urdf]=262144 [robot_yaml]=262144 [truth_yaml]=262144 [noise_yaml]=262144 [fit_json]=262144
)
max_len() { echo "-max_len=${MAX_LEN[$1]:-8192}"; }
# CI: no address-space randomisation, which would otherwise change which branches run
# (pointer comparisons, hash orders) and so which inputs libFuzzer keeps.
norandom=()
if [[ $mode == ci ]] && setarch "$(uname -m)" -R true 2>/dev/null; then
  norandom=(setarch "$(uname -m)" -R)
fi

if [[ $mode == merge ]]; then
  for t in "${targets[@]}"; do
    [[ -d build-fuzz/corpus/$t ]] || continue
    before=$(find "tests/fuzz/corpus/$t" -type f | wc -l)
    # -use_counters=0: keep an input only for new edges, not new hit counts (a small corpus).
    build-fuzz/tests/fuzz/stiff_fuzz_$t -merge=1 -use_counters=0 "${common[@]}" "$(max_len "$t")" \
      "tests/fuzz/corpus/$t" "build-fuzz/corpus/$t" > "build-fuzz/merge-$t.log" 2>&1 ||
      { tail -n 20 "build-fuzz/merge-$t.log"; exit 1; }
    echo "== ci-fuzz: $t: $before -> $(find "tests/fuzz/corpus/$t" -type f | wc -l) corpus files"
  done
  exit 0
fi

stats=build-fuzz/fuzz-stats.md
{
  echo "| target | mode | seconds | executions | exec/s | coverage (edges) | features | corpus | result |"
  echo "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |"
} > "$stats"
failed=()
start_all=$(date +%s.%N)
for t in "${targets[@]}"; do
  bin=build-fuzz/tests/fuzz/stiff_fuzz_$t
  [[ -x $bin ]] || { echo "ci-fuzz: no target $t" >&2; exit 2; }
  art=build-fuzz/artifacts/$t log=build-fuzz/fuzz-$t.log
  mkdir -p "$art"
  if [[ $mode == long ]]; then
    per=${FUZZ_SECONDS_PER_TARGET:-600}
    work=build-fuzz/corpus/$t
    mkdir -p "$work"
    args=(-max_total_time="$per" "$work" "tests/fuzz/corpus/$t")
    echo "== ci-fuzz: $t for ${per}s"
  else
    runs=${FUZZ_RUNS:-${RUNS[$t]:-5000}}
    # A fresh copy: libFuzzer adds inputs to its first corpus directory, and an input left
    # from an earlier run would change this one.
    work=build-fuzz/ci-corpus/$t
    rm -rf "$work" && mkdir -p "$work" && cp "tests/fuzz/corpus/$t"/* "$work"/
    args=(-runs="$runs" -seed="${FUZZ_SEED:-1}" -reload=0 "$work")
    echo "== ci-fuzz: $t, $runs executions, seed ${FUZZ_SEED:-1}"
  fi
  result=ok
  t1=$(date +%s.%N)
  if ! "${norandom[@]}" "$bin" "${args[@]}" -print_final_stats=1 "${common[@]}" "$(max_len "$t")" \
       -artifact_prefix="$art/" > "$log" 2>&1; then
    result=FAILED failed+=("$t")
    grep -E "ERROR|finding|SUMMARY|Test unit written" "$log" | head -n 20 || true
    echo "   reproduce: $bin $art/crash-*   (full log: $log)"
    [[ $mode == ci ]] && echo "   the same run: bash scripts/ci-fuzz.sh $t"
  fi
  secs=$(awk -v a="$t1" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -n1)
  last=$(grep -E '^#[0-9]+' "$log" | tail -n1 || true)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<< "$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<< "$last")
  corp=$(sed -n 's/.* corp: \([0-9]*\).*/\1/p' <<< "$last")
  printf '| %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' "$t" "$mode" "$secs" "${execs:-?}" \
    "${rate:-?}" "${cov:-?}" "${ft:-?}" "${corp:-?}" "$result" >> "$stats"
  echo "   ${secs}s, executions ${execs:-?}, ${rate:-?}/s, cov ${cov:-?}, ft ${ft:-?}, corpus ${corp:-?}: $result"
done
total=$(awk -v a="$start_all" -v b="$(date +%s.%N)" 'BEGIN { printf "%.0f", b - a }')
echo; cat "$stats"
if ((${#failed[@]})); then
  echo "ci-fuzz: findings in: ${failed[*]} (inputs under build-fuzz/artifacts/)" >&2
  exit 1
fi
echo "ci-fuzz: ${#targets[@]} targets, no findings, ${total} s of fuzzing"
