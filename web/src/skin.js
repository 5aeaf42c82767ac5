// The skin meshes: the model's skin (coloured by the model or by the soft-tissue thickness) and a
// simulation's skin (pre-operative positions with the post-operative skin as a morph target, and
// the tension map as a second set of colours), all read from the server's .glb files.
import { BufferAttribute, BufferGeometry, DoubleSide, Group, Mesh } from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { getBinary } from './api.js';

const loader = new GLTFLoader();
const buffers = new Map();  // url -> ArrayBuffer: each file is fetched once

function fetchOnce(url) {
  if (!buffers.has(url)) buffers.set(url, getBinary(url));
  return buffers.get(url);
}

async function loadMesh(url) {
  fetchOnce(url);
  const gltf = await loader.parseAsync(await buffers.get(url), '');
  let mesh = null;
  gltf.scene.traverse((o) => {
    if (!mesh && o.isMesh) mesh = o;
  });
  if (!mesh) throw new Error(`${url}: no mesh in the file`);
  mesh.removeFromParent();
  mesh.updateMatrixWorld(true);
  mesh.material.side = DoubleSide;
  mesh.material.roughness = 0.7;
  return mesh;
}

/** A mesh whose colours switch between named colour sets of the same vertices. */
class ColouredSkin {
  constructor(mesh) {
    this.mesh = mesh;
    this.colours = { skin: mesh.geometry.getAttribute('color') };
    // The triangles in the file's order (range_mesh(): cell q is faces 2q and 2q + 1), kept
    // before three-mesh-bvh sorts the index in place for picking.
    this.fileIndex = mesh.geometry.index.array.slice();
  }

  async addColours(name, url) {
    const other = await loadMesh(url);
    const colour = other.geometry.getAttribute('color');
    if (colour.count !== this.colours.skin.count)
      throw new Error(`${url}: another skin (${colour.count} vertices, not ${this.colours.skin.count})`);
    this.colours[name] = colour;
  }

  show(name) {
    this.mesh.geometry.setAttribute('color', this.colours[name] ?? this.colours.skin);
  }
}

/** The model's skin (GET /api/skin): {skin: ColouredSkin with 'thickness', thicknessMax (mm)}. */
export async function loadModelSkin(info) {
  fetchOnce(info.thickness.url);  // both files download at once
  const skin = new ColouredSkin(await loadMesh(info.skin.url));
  await skin.addColours('thickness', info.thickness.url);
  return { skin, thicknessMax: info.thickness.scale_max_mm };
}

// viridis (image/src/colormap.cpp: 11 stops, sRGB 0..255), as the server colours tension.glb.
const kViridis = [[68, 1, 84], [72, 36, 117], [65, 68, 135], [53, 95, 141], [42, 120, 142],
  [33, 145, 140], [34, 168, 132], [68, 191, 112], [122, 209, 81], [189, 223, 38], [253, 231, 37]];
const srgbToLinear = (c) => (c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4);

/** viridis(t), t clamped to [0, 1], as sRGB in [0, 1]. */
export function viridis(t) {
  const x = Math.min(1, Math.max(0, t)) * 10;
  const i = Math.min(9, Math.floor(x)), f = x - i;
  return kViridis[i].map((a, k) => (a * (1 - f) + kViridis[i + 1][k] * f) / 255);
}

/** A simulation's skin (GET /api/results/ID/view) over the model's (`modelSkin`, a ColouredSkin):
 * the part the simulation meshed (morph 0 = pre-operative, 1 = post-operative) and the model's
 * skin without the cells that part replaces, moved around it as the whole face moves. Its skin
 * coloured by the tension (the mesh's faces, and the skin around them a closure in the whole
 * face reaches) is read when first shown (show('tension'), which resolves once it is drawn). */
export async function loadResultSkin(view, modelSkin) {
  const patch = await loadMesh(view.skin);
  const base = modelSkin.mesh.geometry;
  const index = modelSkin.fileIndex.slice();
  for (const q of view.replaced_cells) index.fill(0, 6 * q, 6 * q + 6);  // empty triangles
  const rest = new BufferGeometry();
  rest.setAttribute('position', base.getAttribute('position'));
  rest.setAttribute('normal', base.getAttribute('normal'));
  rest.setAttribute('color', modelSkin.colours.skin);
  rest.setIndex(new BufferAttribute(index, 1));
  // A closure in the whole face moves the skin around the patch too: the model's vertices it
  // moves (skin_moved.bin: uint32 vertex, float32 x y z move in glTF metres) are the rest's
  // morph target, so the face moves with the patch and the seam between them stays closed.
  if (view.moved_skin) {
    const bytes = new DataView(await getBinary(view.moved_skin));
    const position = base.getAttribute('position');
    const moved = new Float32Array(position.array);
    for (let at = 0; at + 16 <= bytes.byteLength; at += 16) {
      const v = bytes.getUint32(at, true);
      if (v >= position.count) throw new Error(`${view.moved_skin}: vertex ${v} of ${position.count}`);
      for (let c = 0; c < 3; ++c) moved[3 * v + c] += bytes.getFloat32(at + 4 + 4 * c, true);
    }
    rest.morphAttributes.position = [new BufferAttribute(moved, 3)];
  }
  const restMesh = new Mesh(rest, modelSkin.mesh.material);
  const mesh = new Group();
  mesh.add(restMesh, patch);
  let tension = null, morph = 1, wanted = 'skin';
  if (restMesh.morphTargetInfluences) restMesh.morphTargetInfluences[0] = morph;
  let scaleMaxKpa = view.tension_scale_max_kpa, values = null;
  // The tension mesh's colours on the scale 0..scaleMaxKpa (viridis; glTF colours are linear).
  const recolour = (t) => {
    if (!values) return;
    const colour = t.geometry.getAttribute('color');
    for (let v = 0; v < values.length; ++v) {
      const c = viridis(values[v] / scaleMaxKpa);
      colour.setXYZ(v, srgbToLinear(c[0]), srgbToLinear(c[1]), srgbToLinear(c[2]));
    }
    colour.needsUpdate = true;
  };
  // A closure in the whole face: the tension of the skin around the patch too (records of a
  // uint32 vertex of the model's skin and its float32 kPa), so the map goes on across the patch's
  // rim; the rest of the head is at 0 (nothing moved there).
  let restTension = null;
  const restColours = () => {
    const colour = restTension.colour, zero = viridis(0).map(srgbToLinear);
    for (let v = 0; v < colour.count; ++v) colour.setXYZ(v, zero[0], zero[1], zero[2]);
    for (let i = 0; i < restTension.vertex.length; ++i) {
      const c = viridis(restTension.kpa[i] / scaleMaxKpa);
      colour.setXYZ(restTension.vertex[i], srgbToLinear(c[0]), srgbToLinear(c[1]), srgbToLinear(c[2]));
    }
    colour.needsUpdate = true;
  };
  const loadRestTension = async () => {
    const bytes = new DataView(await getBinary(view.moved_skin_tension));
    const count = base.getAttribute('position').count, n = Math.floor(bytes.byteLength / 8);
    const vertex = new Uint32Array(n), kpa = new Float32Array(n);
    for (let i = 0; i < n; ++i) {
      vertex[i] = bytes.getUint32(8 * i, true);
      kpa[i] = bytes.getFloat32(8 * i + 4, true);
      if (vertex[i] >= count) throw new Error(`${view.moved_skin_tension}: vertex ${vertex[i]} of ${count}`);
    }
    restTension = { vertex, kpa, colour: new BufferAttribute(new Float32Array(3 * count), 3) };
    restColours();
  };
  const showRest = () => {
    if (restTension) rest.setAttribute('color', wanted === 'tension' ? restTension.colour : modelSkin.colours.skin);
  };
  const loadTension = async () => {
    const [t, kpa] = await Promise.all([loadMesh(view.tension),
      view.tension_values ? getBinary(view.tension_values) : null,
      view.moved_skin_tension ? loadRestTension() : null]);
    if (kpa) {
      values = new Float32Array(kpa);
      if (values.length !== t.geometry.getAttribute('position').count)
        throw new Error(`${view.tension_values}: ${values.length} values for ` +
          `${t.geometry.getAttribute('position').count} vertices`);
    }
    if (scaleMaxKpa !== view.tension_scale_max_kpa) recolour(t);
    // Drawn in front of the patch's faces at the same place (they coincide before and after).
    t.material.polygonOffset = true;
    t.material.polygonOffsetFactor = -2;
    t.material.polygonOffsetUnits = -2;
    t.morphTargetInfluences[0] = morph;
    patch.add(t);
    return t;
  };
  let loading = null;
  return {
    mesh,
    async show(name) {
      wanted = name;
      if (name === 'tension' && !tension) {
        loading ??= loadTension();
        tension = await loading;
      }
      if (tension) tension.visible = wanted === 'tension';
      showRest();
    },
    /** Colours the tension from 0 to `kpa` (several results on one scale). */
    setTensionScale(kpa) {
      if (!(kpa > 0) || kpa === scaleMaxKpa) return;
      scaleMaxKpa = kpa;
      if (tension) recolour(tension);
      if (restTension) restColours();
    },
    setMorph(t) {
      morph = t;
      patch.morphTargetInfluences[0] = t;
      if (restMesh.morphTargetInfluences) restMesh.morphTargetInfluences[0] = t;
      if (tension) tension.morphTargetInfluences[0] = t;
    },
  };
}
