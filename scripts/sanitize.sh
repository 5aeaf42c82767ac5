#!/usr/bin/env bash
# Hostile-input checks (docs/reliability.md), run by scripts/test.sh after the test suite:
#  1. the reader, plan and fem test programs built with clang, AddressSanitizer and
#     UndefinedBehaviorSanitizer, run to the end: any sanitizer report fails;
#  2. every fuzz target of fuzz/ for a bounded time from its seed corpus and past findings
#     (scripts/fuzz.sh): any finding fails.
# Test programs and fuzz targets run as many at a time as there are cores.
# Both use one build directory, build-fuzz (CC=clang CXX=clang++ -DCAPS_FUZZ=ON).
#
#   scripts/sanitize.sh [--seconds N]   (N: fuzzing time per target, default 20)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
seconds=20
[ "${1:-}" = "--seconds" ] && seconds="$2"
build="$here/build-fuzz"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
data=()
[ -n "${CAPS_SHARED_DATA:-}" ] && data=(-DCAPS_SHARED_DATA="$CAPS_SHARED_DATA")
# No precompiled test header here (CAPS_PCH, cmake/CapsPch.cmake): for four test programs making
# it costs about what it saves (docs/benchmarks.md, "Build and test time").
# -O1, as AddressSanitizer's documentation advises: the compile takes a fifth less CPU than at
# -O2 (docs/reliability.md, "CI time").
CC=clang CXX=clang++ cmake -S "$here" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g -DNDEBUG" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g -DNDEBUG" \
  -DCAPS_FUZZ=ON -DCAPS_BUILD_TESTS=ON -DCAPS_PCH=OFF \
  "${launcher[@]}" "${data[@]}" >/dev/null
programs=(test_volume_io test_surface test_plan test_fem)
t0=$(date +%s)
cmake --build "$build" -j"$(nproc)" --target fuzzers "${programs[@]}"
t1=$(date +%s)
echo "sanitize: sanitized build $((t1 - t0)) s"

export TMPDIR="${TMPDIR:-/tmp}/caps-sanitize-$$"
mkdir -p "$TMPDIR"
trap 'rm -rf "$TMPDIR"' EXIT
export ASAN_OPTIONS="abort_on_error=1:detect_leaks=1:symbolize=1"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
# cairo's fontconfig keeps a 652-byte cache until exit: not ours (scripts/lsan.supp).
export LSAN_OPTIONS="suppressions=$here/scripts/lsan.supp:print_suppressions=0"
# The test programs run side by side, as many at a time as there are cores (each is one process
# and its tests use folders of their own under TMPDIR).
jobs="$(nproc)"
# One accuracy test is left to the unsanitized suite (ctest runs it): it builds the volume model
# of the full 1 mm phantom head, which took 3 of test_surface's 3.3 minutes under ASan; the other
# surface tests, the readers and the scan model keep running here.
# Nor the three threads solving at once (FemSolvers.SolvesAtOnce...): a crash test of MUMPS's
# shared state, which lives in the uninstrumented library; it took 58 of test_fem's 70 s here.
filter="-ScanModel.PhantomSkinMeshReproducesVolumeRSkin:FemSolvers.SolvesAtOnceInThreeThreadsEachGiveTheAnswerAlone"
run_test() {
  local p="$1" s
  s=$(date +%s)
  if "$build/tests/$p" --gtest_brief=1 --gtest_filter="$filter" >"$TMPDIR/$p.log" 2>&1; then
    echo "sanitize: $p clean ($(( $(date +%s) - s )) s)"
  else
    echo "sanitize: $p FAILED under ASan/UBSan:"
    grep -E 'ERROR|runtime error|SUMMARY|FAILED|Failure' "$TMPDIR/$p.log" | head -20 | sed 's/^/    /'
    touch "$TMPDIR/$p.failed"
  fi
}
running=0
for p in "${programs[@]}"; do
  run_test "$p" &
  running=$((running + 1))
  if [ $running -ge "$jobs" ]; then wait -n || true; running=$((running - 1)); fi
done
wait
failed=0
for p in "${programs[@]}"; do if [ -e "$TMPDIR/$p.failed" ]; then failed=1; fi; done
t2=$(date +%s)
# Every target fuzzes for the time given after replaying its seeds and past findings
# (fuzz/regressions/), as many at a time as there are cores.
bash "$here/scripts/fuzz.sh" --build "$build" --seconds "$seconds" --jobs "$jobs" || failed=1
echo "sanitize: tests $((t2 - t1)) s, fuzzing $(( $(date +%s) - t2 )) s"
exit $failed
