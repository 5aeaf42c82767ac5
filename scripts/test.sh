#!/usr/bin/env bash
# The whole test suite on a fresh Debian 12 machine: installs what is missing, builds, runs ctest,
# then the hostile-input checks (scripts/sanitize.sh: the reader, plan and fem tests under
# ASan + UBSan built with clang, and every fuzz target for a bounded time). Any failure fails.
# `scripts/test.sh --fast`: the build and the tests labelled fast only (a developer's check).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$here/scripts/build.sh"
if [ "${1:-}" = "--fast" ]; then
  # A developer's check between changes: the tests labelled fast (tests/CMakeLists.txt), no
  # sanitizers or fuzzing. CI and the README run the whole suite.
  (cd "$here/build" && ctest --output-on-failure -j"$(nproc)" -L fast)
  exit 0
fi
(cd "$here/build" && ctest --output-on-failure -j"$(nproc)")
bash "$here/scripts/sanitize.sh" --seconds "${CAPS_FUZZ_SECONDS:-10}"
