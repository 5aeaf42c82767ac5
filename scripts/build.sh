#!/usr/bin/env bash
# Installs what is missing, then configures and builds caps (Release) in ./build.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$here/scripts/setup.sh"
# ccache (installed by setup.sh) keeps compiled objects between builds: a rebuild after a small
# change, or a CI run on a machine that keeps ~/.cache/ccache, compiles only what changed.
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
cmake -S "$here" -B "$here/build" -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" >/dev/null
cmake --build "$here/build" -j"$(nproc)"
