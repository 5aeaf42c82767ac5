// Patient LPS millimetres <-> the glTF frame the skin files use (render/gltf_export.hpp):
//   gltf = 0.001 * R * lps,  R = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
// x = L (the patient's left), y = S (superior, up), z = A (the face looks along +z), metres.
import { Vector3 } from 'three';

/** An LPS point [x, y, z] in mm to a three.js Vector3 in the glTF frame (m). */
export function lpsToScene([x, y, z]) {
  return new Vector3(x / 1000, z / 1000, -y / 1000);
}

/** A three.js point in the glTF frame (m) to LPS mm [x, y, z]. */
export function sceneToLps(p) {
  return [p.x * 1000, -p.z * 1000, p.y * 1000];
}
