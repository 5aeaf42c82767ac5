#!/usr/bin/env bash
# The main job on the demo patient (Cranium.inv3, a real head CT from Debian's invesalius-examples):
# installs what is missing, builds, and writes the patient model to out/cranium.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$here/scripts/build.sh"
out="${1:-$here/out}"
mkdir -p "$out"
"$here/build/tools/caps" model from-volume \
  /usr/share/doc/invesalius-examples/examples/Cranium.inv3 -o "$out/cranium" --force
echo "caps demo: model written to $out/cranium (open thickness.png and skin.png; skin.ply and"
echo "bone.ply open in 3D Slicer, ParaView and Blender; the .nrrd maps open in 3D Slicer)"
