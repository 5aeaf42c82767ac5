#!/usr/bin/env bash
# The main job on the demo patient (Cranium.inv3, a real head CT from Debian's invesalius-examples):
# installs what is missing, builds, then writes everything into out/ (or the folder given), with
# out/index.html to open in a browser:
#   cranium/               the patient model (measured thickness map, skin and bone surfaces)
#   ellipse.json, z-plasty.json, v-y-advancement.json, *.png   three plans on the forehead
#   ellipse/, z-plasty/, v-y-advancement/   each plan meshed, its closure solved and rendered
#                          before and after, with the skin tension
#   *-compare/             measured versus constant thickness (report.html)
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
done

cat > "$out/index.html" <<'HTML'
<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>caps demo: Cranium.inv3</title>
<style>body{font-family:DejaVu Sans,Arial,sans-serif;max-width:1150px;margin:2em auto;color:#222}
img{max-width:100%;border:1px solid #ddd}.row{display:flex;gap:12px}.row div{flex:1}</style></head>
<body>
<h1>caps demo: a patient model from CT, three plans, their closure</h1>
<p>The patient: <code>Cranium.inv3</code>, a head CT from Debian's invesalius-examples. caps measured
the soft-tissue thickness between skin and bone in the CT and built a volumetric model of the
soft tissue of the whole face (tetrahedra between skin and bone, <code>cranium/tissue.vtu</code>),
planned an elliptical excision, a Z-plasty and a V-Y advancement flap on the forehead, meshed each
plan (20-node hexahedra and 15-node wedges down to the measured bone), tied that patch into the
whole-face model (no clamped rim), closed the wound with suture constraints and rendered the skin
before and after at the CT's full resolution; <code>result.json</code> says how far the closure
moves the brows, eyelid margins and alar rims. Each plan is also simulated with a constant
thickness (the 1992 CAPS assumption for surface scans) for comparison, on the 1992 clamped
patch.</p>
<h2>The patient model</h2>
<div class="row"><div><p>Soft-tissue thickness (mm)</p><img src="cranium/thickness.png" alt="thickness map"></div>
<div><p>Skin range image</p><img src="cranium/skin.png" alt="skin range image"></div></div>
<p>Files: <code>cranium/model.json</code>, the NRRD maps (3D Slicer), <code>skin.ply</code>,
<code>bone.ply</code> (3D Slicer, ParaView, Blender), <code>tissue.vtu</code> (ParaView),
<code>skin.vdb</code> and <code>bone.vdb</code> (the level sets; Blender, Houdini).</p>
HTML
for p in ellipse z-plasty v-y-advancement; do
  cat >> "$out/index.html" <<HTML
<h2>${p}</h2>
<div class="row"><div><p>The plan</p><img src="${p}.png" alt="${p} plan"></div>
<div><p>The surface mesh</p><img src="${p}/surface.png" alt="${p} surface mesh"></div></div>
<div class="row"><div><p>Before</p><img src="${p}/pre_plan.png" alt="${p} before"></div>
<div><p>After the closure</p><img src="${p}/post_plan.png" alt="${p} after"></div></div>
<div class="row"><div><p>Before, oblique</p><img src="${p}/pre_oblique.png" alt="${p} before, oblique"></div>
<div><p>After, oblique</p><img src="${p}/post_oblique.png" alt="${p} after, oblique"></div></div>
<div class="row"><div><p>Skin tension after the closure (kPa)</p><img src="${p}/tension_plan.png" alt="${p} skin tension"></div>
<div></div></div>
<p><a href="${p}-compare/report.html">Measured versus constant thickness</a> &middot;
<code>${p}/result.vtu</code> (ParaView) &middot; <code>${p}/mesh.inp</code> (CalculiX) &middot;
<code>${p}/result.json</code> (closing force, stresses, timings)</p>
HTML
done
echo "</body></html>" >> "$out/index.html"
echo "caps demo: open $out/index.html"
echo "caps demo: to plan on this patient in the browser, run"
echo "  $caps serve $out/cranium"
echo "and open http://127.0.0.1:8765/ (click on the skin to place a procedure; docs/planner.md)"
