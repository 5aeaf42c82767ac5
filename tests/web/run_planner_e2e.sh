#!/usr/bin/env bash
# ctest's planner_e2e: builds the small phantom model, then runs planner_e2e.mjs (Playwright
# driving Debian's chromium headless) against `caps serve`. Skipped (exit 77) only when chromium,
# node or web/node_modules are missing; scripts/setup.sh installs them.
# run_planner_e2e.sh CAPS_EXE WEB_ROOT
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
caps="$1"
web_root="$2"
chromium="${CAPS_CHROMIUM:-/usr/bin/chromium}"
for need in "$chromium" "$(command -v node || true)" "$here/../../web/node_modules/playwright-core" \
            "$web_root/index.html"; do
  if [ -z "$need" ] || [ ! -e "$need" ]; then
    echo "planner_e2e: SKIPPED: ${need:-node} is missing (run scripts/setup.sh, then build)"
    exit 77
  fi
done
work="${TMPDIR:-/tmp}/caps_planner_e2e"
rm -rf "$work"
mkdir -p "$work"
"$caps" phantom -o "$work/ct.nii.gz" --voxels 96,96,90 --spacing 2.5,2.5,2.5 -q
"$caps" model from-volume "$work/ct.nii.gz" -o "$work/model" --n-theta 128 --n-z 64 -q
node "$here/planner_e2e.mjs" "$caps" "$work/model" "$web_root" "$work/screenshots"
echo "planner_e2e: screenshots in $work/screenshots"
