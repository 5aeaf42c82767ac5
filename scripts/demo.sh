#!/usr/bin/env bash
# The main job on the demo patient (Cranium.inv3, a real head CT from Debian's invesalius-examples):
# installs what is missing, builds, then writes everything into out/ (or the folder given), with
# out/index.html to open in a browser:
#   cranium/               the patient model (measured thickness map, skin and bone surfaces)
#   ellipse.json, z-plasty.json, v-y-advancement.json, *.png   three plans on the forehead
#   ellipse/, z-plasty/, v-y-advancement/   each plan meshed, its closure solved and rendered
#                          before and after, with the skin tension
#   *-compare/             measured versus constant thickness (report.html)
#   *-sheet.pdf, *-sheet.png   each plan's operating-room sheet (caps plan sheet: the incision 1:1,
#                          its points from palpable landmarks, the predicted forces)
#   slicer/                for 3D Slicer: the CT, the segmentation, surfaces, landmarks and the
#                          Z-plasty as markups, its post-operative skin (caps model export-slicer)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$here/scripts/build.sh"
out="${1:-$here/out}"
caps="$here/build/tools/caps"
mkdir -p "$out"
"$caps" model from-volume /usr/share/doc/invesalius-examples/examples/Cranium.inv3 \
  -o "$out/cranium" --force
# The forehead, to the patient's left of a region without bone under it (see thickness.png).
"$caps" plan new ellipse --model "$out/cranium" --at 25,105 -o "$out/ellipse.json" --force
"$caps" plan new z-plasty --model "$out/cranium" --at 30,105 --length 15 -o "$out/z-plasty.json" --force
"$caps" plan new v-y-advancement --model "$out/cranium" --at 0,95 --length 15 --advance 4 \
  -o "$out/v-y-advancement.json" --force
for p in ellipse z-plasty v-y-advancement; do
  "$caps" plan show "$out/$p.json" -o "$out/$p.png" --force
  "$caps" simulate --model "$out/cranium" --plan "$out/$p.json" -o "$out/$p" --render --tension-map --force
  "$caps" compare --model "$out/cranium" --plan "$out/$p.json" -o "$out/$p-compare" --force
  # The operating-room sheet beside its result, and the PDF as poppler draws it (the preview in
  # index.html: the PDF opens and shows what the PNG shows).
  "$caps" plan sheet "$out/$p.json" --model "$out/cranium" --result "$out/$p" \
    -o "$out/$p-sheet.pdf" --png --force
  pdftoppm -r 60 -png -singlefile "$out/$p-sheet.pdf" "$out/$p-sheet-preview"
done

# For 3D Slicer: the CT in patient space, the segmentation, the surfaces with their thickness,
# the landmarks and the Z-plasty's lines as markups, its post-operative skin (docs/slicer.md).
"$caps" model export-slicer "$out/cranium" --plan "$out/z-plasty.json" --result "$out/z-plasty" \
  -o "$out/slicer" --force

# The index: each plan's forces and feature distortions (result.json, summary.json), its sheet
# and the Slicer folder.
python3 "$here/scripts/demo_index.py" "$out" ellipse z-plasty v-y-advancement
echo "caps demo: open $out/index.html"
echo "caps demo: to plan on this patient in the browser, run"
echo "  $caps serve $out/cranium"
echo "and open http://127.0.0.1:8765/ (click on the skin to place a procedure; docs/planner.md)"
