#!/usr/bin/env bash
# The whole test suite on a fresh Debian 12 machine: installs what is missing, builds, runs ctest,
# then the hostile-input checks (scripts/sanitize.sh: the reader, plan and fem tests under
# ASan + UBSan built with clang, and every fuzz target for a bounded time). Any failure fails.
# Each phase's wall time (setup, build, ctest, sanitize) is printed as it ends and again at the
# end ("test.sh: ..."), so that a CI log shows where its time went.
# `scripts/test.sh --fast`: the build and the tests labelled fast only (a developer's check).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
times=""
phase=""
phase_start=0
begin() { phase="$1"; phase_start=$(date +%s); }
end() {
  local s=$(( $(date +%s) - phase_start ))
  echo "test.sh: $phase took $s s"
  times="$times $phase $s s,"
  phase=""
}
total_start=$(date +%s)
# Also when a phase fails: how long it ran until then.
summary() {
  [ -n "$phase" ] && times="$times $phase $(( $(date +%s) - phase_start )) s (failed),"
  echo "test.sh: wall time per phase:${times%,}; total $(( $(date +%s) - total_start )) s"
}
trap summary EXIT
# setup.sh alone first, so that its apt and npm time is not counted as build time (build.sh runs
# it again: with nothing missing that takes a second or two).
begin setup
bash "$here/scripts/setup.sh"
end
begin build
bash "$here/scripts/build.sh"
end
if [ "${1:-}" = "--fast" ]; then
  # A developer's check between changes: the tests labelled fast (tests/CMakeLists.txt), no
  # sanitizers or fuzzing. CI and the README run the whole suite.
  begin ctest
  (cd "$here/build" && ctest --output-on-failure -j"$(nproc)" -L fast)
  end
  exit 0
fi
# ctest -j runs the tests with the highest cost first: tests/CMakeLists.txt gives its own tests a
# COST, but the workflow tests and python_caps are defined in folders it cannot reach (CMake 3.25),
# and without a cost they start last, workflow_cohort_run (73-94 s) alone at the end. On a clean
# clone (no record of ctest's own yet) their costs are given in ctest's record file, which ctest
# reads for tests without a COST and then rewrites with what it measured (seconds, the 2-core
# machine, 6 December 2026; only the order depends on them).
costs="$here/build/Testing/Temporary/CTestCostData.txt"
if [ ! -f "$costs" ]; then
  mkdir -p "$(dirname "$costs")"
  printf '%s\n' "workflow_cohort_run 1 73" "workflow_cohort_plans 1 29" "python_caps 1 24" > "$costs"
fi
# The tests' files (each program's folders under the temporary directory) go into one folder
# of this run, removed when it ends: runs here used to leave them behind (14 GB over a few days).
tests_tmp="$(mktemp -d "${TMPDIR:-/tmp}/caps-tests.XXXXXX")"
# Searchable by other users, as /tmp is: the hostile-input tests run caps as an unprivileged user
# on files in their folders (mktemp makes it the owner's alone).
chmod 755 "$tests_tmp"
trap 'rm -rf "$tests_tmp"; summary' EXIT
begin ctest
(cd "$here/build" && TMPDIR="$tests_tmp" ctest --output-on-failure -j"$(nproc)")
end
rm -rf "$tests_tmp"
begin sanitize
bash "$here/scripts/sanitize.sh" --seconds "${CAPS_FUZZ_SECONDS:-10}"
end
