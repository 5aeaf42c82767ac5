#!/usr/bin/env bash
# Runs the libFuzzer targets of fuzz/ one after another (--jobs N: N at a time), each from its
# seed corpus, and prints a line per target (executions, coverage, corpus). Any finding (crash,
# sanitizer report, leak, hang, allocation above the limit, uncaught non-caps exception) fails the
# run; its input is kept as <out>/<target>-crash-* (reproduce: <build>/fuzz/<target> <that file>).
#
#   scripts/fuzz.sh [--build DIR] [--out DIR] [--seconds N] [--runs N] [--jobs N] [target ...]
#
# The build directory is configured with CC=clang CXX=clang++ -DCAPS_FUZZ=ON (scripts/test.sh
# does it). Default: every target built there, 20 seconds each; with both --seconds and --runs a
# target stops at whichever comes first (--runs 0: replay the seeds and findings only). The corpus
# each run grows is kept in <out>/corpus/<target> and used again by the next run.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$here/build-fuzz"
out=""
seconds=""
runs=""
jobs=1
targets=()
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --seconds) seconds="$2"; shift 2 ;;
    --runs) runs="$2"; shift 2 ;;
    --jobs) jobs="$2"; shift 2 ;;
    -h|--help) sed -n '2,14p' "$0"; exit 0 ;;
    *) targets+=("$1"); shift ;;
  esac
done
limit=()
[ -n "$seconds" ] && limit+=(-max_total_time="$seconds")
[ -n "$runs" ] && limit+=(-runs="$runs")
[ ${#limit[@]} -eq 0 ] && limit=(-max_total_time=20)
out="${out:-$build/fuzz/runs}"
if [ ${#targets[@]} -eq 0 ]; then
  # fuzz_server first: before its first input it builds the phantom's model (about 19 of its 30 s
  # under ASan, the others take their 10 s and a second). Started last, as the alphabet had it,
  # it ran alone for its last 8-10 s; started first, the others fill the second core beside it.
  [ -x "$build/fuzz/fuzz_server" ] && targets+=(fuzz_server)
  for f in "$build"/fuzz/fuzz_*; do
    name="$(basename "$f")"
    [ -x "$f" ] && [ "$name" != fuzz_seeds ] && [ "$name" != fuzz_server ] && targets+=("$name")
  done
fi
[ ${#targets[@]} -gt 0 ] || { echo "fuzz.sh: no fuzz targets in $build/fuzz" >&2; exit 2; }
mkdir -p "$out"
# The readers write their input under TMPDIR; a private one keeps parallel runs apart.
export TMPDIR="$out/tmp"
mkdir -p "$TMPDIR"
# Findings stop the program; the stack is printed. LeakSanitizer runs at the end of each input.
export ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1:symbolize=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}"
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$here/scripts/lsan.supp:print_suppressions=0}"
# One target: its line on stdout; a finding leaves <out>/<target>.failed.
run_one() {
  local t="$1" corpus="$out/corpus/$1" seeds="" start rc=0 secs execs last cov ft n
  mkdir -p "$corpus"
  rm -f "$out/$t.failed"
  # The seeds, and the inputs of past findings (fuzz/regressions/<target>/), all run first.
  for d in "$build/fuzz/seeds/$t" "$here/fuzz/regressions/$t"; do [ -d "$d" ] && seeds="$seeds $d"; done
  start=$(date +%s)
  # 64 MiB is what the volume targets allow a reader (fuzz_volume.hpp); an allocation above
  # 512 MiB is a finding, and so is an input taking longer than 20 s.
  "$build/fuzz/$t" "$corpus" $seeds "${limit[@]}" -rss_limit_mb=2048 \
    -malloc_limit_mb=512 -timeout=20 -print_final_stats=1 \
    -artifact_prefix="$out/$t-" >"$out/$t.log" 2>&1 || rc=$?
  secs=$(( $(date +%s) - start ))
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$out/$t.log" | grep -o '[0-9]*$' || echo "?")
  last=$(grep -E '^#[0-9]+' "$out/$t.log" | tail -1 || true)
  cov=$(echo "$last" | grep -o 'cov: [0-9]*' | grep -o '[0-9]*' || echo "?")
  ft=$(echo "$last" | grep -o 'ft: [0-9]*' | grep -o '[0-9]*' || echo "?")
  n=$(ls "$corpus" | wc -l)
  if [ $rc -eq 0 ]; then
    printf '%-24s ok       %10s runs %6s s  cov %6s  ft %7s  corpus %5s\n' "$t" "$execs" "$secs" "$cov" "$ft" "$n"
  else
    touch "$out/$t.failed"
    printf '%-24s FINDING  %10s runs %6s s  (exit %d; %s)\n' "$t" "$execs" "$secs" "$rc" "$out/$t.log"
    grep -E 'ERROR|runtime error|SUMMARY|uncaught|Test unit written' "$out/$t.log" | head -5 | sed 's/^/    /'
  fi
}
# --jobs N runs N targets at once (each is one process): on N free cores the same executions
# in 1/N of the time.
running=0
for t in "${targets[@]}"; do
  if [ "$jobs" -le 1 ]; then
    run_one "$t"
  else
    run_one "$t" &
    running=$((running + 1))
    if [ $running -ge "$jobs" ]; then wait -n || true; running=$((running - 1)); fi
  fi
done
wait
failed=0
for t in "${targets[@]}"; do if [ -e "$out/$t.failed" ]; then failed=1; fi; done
exit $failed
