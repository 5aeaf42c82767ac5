#!/usr/bin/env bash
# The main job on the demo patient (Cranium.inv3, a real head CT from Debian's invesalius-examples):
# installs what is missing, builds, then writes into out/ (or the folder given):
#   cranium/            the patient model (measured thickness map, skin and bone surfaces)
#   ellipse.json, z-plasty.json        two plans on the forehead, with ellipse.png, z-plasty.png
#   ellipse/, z-plasty/                each plan meshed and its closure solved (caps simulate)
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
"$caps" plan new z-plasty --model "$out/cranium" --at 30,110 --length 15 -o "$out/z-plasty.json" --force
for p in ellipse z-plasty; do
  "$caps" plan show "$out/$p.json" -o "$out/$p.png" --force
  "$caps" simulate --model "$out/cranium" --plan "$out/$p.json" -o "$out/$p" --force
done
echo "caps demo: results in $out"
echo "  cranium/thickness.png, cranium/skin.png: the patient model (skin.ply, bone.ply open in"
echo "    3D Slicer, ParaView and Blender; the .nrrd maps in 3D Slicer)"
echo "  ellipse.png, z-plasty.png: the plans; ellipse/, z-plasty/: mesh.vtu and result.vtu for"
echo "    ParaView, mesh.inp for CalculiX, result.json with the closing force"
