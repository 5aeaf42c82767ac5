#!/usr/bin/env bash
# ctest's planner_e2e and planner_e2e_cranium: builds the model, then runs the browser test
# (Playwright driving Debian's chromium headless) against `caps serve`:
#   phantom  the small phantom model (built each run), planner_e2e.mjs
#   cranium  the demo patient's model (Cranium.inv3, as scripts/demo.sh builds it; built once into
#            CACHE_DIR and reused while it is newer than both the caps program and Cranium.inv3),
#            planner_e2e_cranium.mjs
# Skipped (exit 77, with the reason) when chromium, node or web/node_modules are missing
# (scripts/setup.sh installs them) or, for cranium, when Cranium.inv3 is (Debian's
# invesalius-examples).
# run_planner_e2e.sh CAPS_EXE WEB_ROOT [phantom|cranium [CACHE_DIR]]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
caps="$1"
web_root="$2"
kind="${3:-phantom}"
cranium="${CAPS_CRANIUM:-/usr/share/doc/invesalius-examples/examples/Cranium.inv3}"
chromium="${CAPS_CHROMIUM:-/usr/bin/chromium}"
needs=("$chromium" "$(command -v node || true)" "$here/../../web/node_modules/playwright-core"
       "$web_root/index.html")
[ "$kind" = cranium ] && needs+=("$cranium")
for need in "${needs[@]}"; do
  if [ -z "$need" ] || [ ! -e "$need" ]; then
    if [ "$need" = "$cranium" ]; then
      echo "planner_e2e_cranium: SKIPPED: the demo patient $cranium is missing" \
           "(apt-get install invesalius-examples)"
    else
      echo "planner_e2e: SKIPPED: ${need:-node} is missing (run scripts/setup.sh, then build)"
    fi
    exit 77
  fi
done
work="${TMPDIR:-/tmp}/caps_planner_e2e_$kind"
rm -rf "$work"
mkdir -p "$work"
case "$kind" in
  phantom)
    "$caps" phantom -o "$work/ct.nii.gz" --voxels 96,96,90 --spacing 2.5,2.5,2.5 -q
    "$caps" model from-volume "$work/ct.nii.gz" -o "$work/model" --n-theta 128 --n-z 64 -q
    node "$here/planner_e2e.mjs" "$caps" "$work/model" "$web_root" "$work/screenshots"
    ;;
  cranium)
    cache="${4:-$work/cache}"
    model="$cache/cranium"
    if [ ! -f "$model/model.json" ] || [ "$caps" -nt "$model/model.json" ] ||
       [ "$cranium" -nt "$model/model.json" ]; then
      start=$(date +%s)
      rm -rf "$model" "$model.part"
      mkdir -p "$cache"
      "$caps" model from-volume "$cranium" -o "$model.part" -q
      mv "$model.part" "$model"
      echo "planner_e2e_cranium: built the Cranium model in $(( $(date +%s) - start )) s"
    else
      echo "planner_e2e_cranium: the Cranium model in $model is up to date"
    fi
    node "$here/planner_e2e_cranium.mjs" "$caps" "$model" "$web_root" "$work/screenshots"
    ;;
  *)
    echo "run_planner_e2e.sh: unknown model kind \"$kind\" (phantom or cranium)" >&2
    exit 2
    ;;
esac
echo "planner_e2e: screenshots in $work/screenshots"
