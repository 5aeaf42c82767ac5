#!/usr/bin/env bash
# Runs the libFuzzer targets of fuzz/ one after another, each from its seed corpus, and prints a
# line per target (executions, coverage, corpus). Any finding (crash, sanitizer report, leak, hang,
# allocation above the limit, uncaught non-caps exception) fails the run; its input is kept as
# <out>/<target>-crash-* (reproduce: <build>/fuzz/<target> <that file>).
#
#   scripts/fuzz.sh [--build DIR] [--out DIR] [--seconds N | --runs N] [target ...]
#
# The build directory is configured with CC=clang CXX=clang++ -DCAPS_FUZZ=ON (scripts/test.sh
# does it). Default: every target built there, 20 seconds each; the corpus each run grows is kept
# in <out>/corpus/<target> and used again by the next run.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$here/build-fuzz"
out=""
limit=(-max_total_time=20)
targets=()
while [ $# -gt 0 ]; do
  case "$1" in
    --build) build="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --seconds) limit=(-max_total_time="$2"); shift 2 ;;
    --runs) limit=(-runs="$2"); shift 2 ;;
    -h|--help) sed -n '2,12p' "$0"; exit 0 ;;
    *) targets+=("$1"); shift ;;
  esac
done
out="${out:-$build/fuzz/runs}"
if [ ${#targets[@]} -eq 0 ]; then
  for f in "$build"/fuzz/fuzz_*; do
    name="$(basename "$f")"
    [ -x "$f" ] && [ "$name" != fuzz_seeds ] && targets+=("$name")
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
failed=0
for t in "${targets[@]}"; do
  corpus="$out/corpus/$t"
  mkdir -p "$corpus"
  # The seeds, and the inputs of past findings (fuzz/regressions/<target>/), all run first.
  seeds=""
  for d in "$build/fuzz/seeds/$t" "$here/fuzz/regressions/$t"; do [ -d "$d" ] && seeds="$seeds $d"; done
  start=$(date +%s)
  rc=0
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
    printf '%-24s FINDING  %10s runs %6s s  (exit %d; %s)\n' "$t" "$execs" "$secs" "$rc" "$out/$t.log"
    grep -E 'ERROR|runtime error|SUMMARY|uncaught|Test unit written' "$out/$t.log" | head -5 | sed 's/^/    /'
    failed=1
  fi
done
exit $failed
