// What is drawn over the skin: the plan's cutting lines (tubes along the skin), its points, the
// handle that moves it, and the sutures of a simulation coloured by their force.
import {
  BufferGeometry,
  CatmullRomCurve3,
  Color,
  Float32BufferAttribute,
  LineBasicMaterial,
  LineSegments,
  Mesh,
  MeshBasicMaterial,
  MeshStandardMaterial,
  SphereGeometry,
  TubeGeometry,
} from 'three';
import { lpsToScene } from './frames.js';

const kLineRadius = 0.0004;  // m: tubes 0.8 mm thick
const lineMaterial = new MeshBasicMaterial({ color: 0x1030c0 });
const refusedMaterial = new MeshBasicMaterial({ color: 0xd02020 });
const pointMaterial = new MeshBasicMaterial({ color: 0x0a0a40 });
const handleMaterial = new MeshStandardMaterial({ color: 0xffd21a, emissive: 0x554400 });
const rotateMaterial = new MeshStandardMaterial({ color: 0x20c0e0, emissive: 0x0a3a44 });
const scaleMaterial = new MeshStandardMaterial({ color: 0xe040c0, emissive: 0x44103a });

/** Meshes for a plan's lines ({lines_lps, points_lps, centre} from /api/plan/lines). */
export function planObjects(view, { refused = false } = {}) {
  const objects = [];
  for (const line of view.lines_lps) {
    if (line.length < 2) continue;
    const curve = new CatmullRomCurve3(line.map(lpsToScene), false, 'centripetal');
    const tube = new TubeGeometry(curve, Math.max(8, line.length * 2), kLineRadius, 6, false);
    objects.push(new Mesh(tube, refused ? refusedMaterial : lineMaterial));
  }
  const dot = new SphereGeometry(0.0009, 12, 8);
  for (const p of view.points_lps) {
    const m = new Mesh(dot, pointMaterial);
    m.position.copy(lpsToScene(p));
    objects.push(m);
  }
  return objects;
}

/** The relaxed skin tension lines ({lines: [{points_lps}]} from /api/skin-lines) as one set of
 * thin green line segments on the skin before the operation, named 'skin-lines'. */
export function skinLineObjects(answer) {
  const xyz = [];
  for (const line of answer.lines ?? [])
    for (let i = 1; i < line.points_lps.length; ++i)
      for (const p of [line.points_lps[i - 1], line.points_lps[i]]) {
        const v = lpsToScene(p);
        xyz.push(v.x, v.y, v.z);
      }
  if (!xyz.length) return [];
  const geometry = new BufferGeometry();
  geometry.setAttribute('position', new Float32BufferAttribute(xyz, 3));
  const lines = new LineSegments(geometry, new LineBasicMaterial({ color: 0x1f9d55 }));
  lines.name = 'skin-lines';
  return [lines];
}

const outlineMaterial = new MeshBasicMaterial({ color: 0xe07000 });

/** The lesion's outline drawn for Suggest (LPS mm, in order around it) as orange dots joined by
 * a closed line on the skin, named 'lesion-outline'. */
export function lesionOutlineObjects(points) {
  if (!points.length) return [];
  const dot = new SphereGeometry(0.0008, 12, 8);
  const objects = points.map((p) => {
    const m = new Mesh(dot, outlineMaterial);
    m.position.copy(lpsToScene(p));
    m.name = 'lesion-outline';
    return m;
  });
  if (points.length > 1) {
    const xyz = [];
    for (let i = 0; i < points.length; ++i)
      for (const p of [points[i], points[(i + 1) % points.length]]) {
        const v = lpsToScene(p);
        xyz.push(v.x, v.y, v.z);
      }
    const geometry = new BufferGeometry();
    geometry.setAttribute('position', new Float32BufferAttribute(xyz, 3));
    const line = new LineSegments(geometry, new LineBasicMaterial({ color: 0xe07000 }));
    line.name = 'lesion-outline';
    objects.push(line);
  }
  return objects;
}

/** The yellow handle at the plan's centre (dragged to move the plan). */
export function handleObject(centreLps) {
  const m = new Mesh(new SphereGeometry(0.002, 20, 14), handleMaterial);
  m.position.copy(lpsToScene(centreLps));
  m.name = 'handle';
  return m;
}

/** The handles that turn (cyan, beyond the start of the plan's axis) and scale (magenta, beyond
 * its end) a template, from /api/plan/lines' centre; named 'rotate' and 'scale'. */
export function axisHandleObjects(centre) {
  const make = (lps, material, name) => {
    const m = new Mesh(new SphereGeometry(0.0017, 18, 12), material);
    m.position.copy(lpsToScene(lps));
    m.name = name;
    return m;
  };
  return [make(centre.rotate_handle_lps, rotateMaterial, 'rotate'),
    make(centre.scale_handle_lps, scaleMaterial, 'scale')];
}

/** Handles on a free incision's points (LPS mm), dragged to move them; userData.index is the
 * point's index. */
export function pointHandles(points) {
  const ball = new SphereGeometry(0.0014, 16, 12);
  return points.map((p, i) => {
    const m = new Mesh(ball, handleMaterial);
    m.position.copy(lpsToScene(p));
    m.name = 'point';
    m.userData.index = i;
    return m;
  });
}

// The scar: dark red, as `caps render` draws the suture lines over its post-operative pictures.
const kScarColour = new Color(0x8c141a);  // sRGB (140, 20, 26) = (0.55, 0.08, 0.1)

/** Tubes along each wound's and incision's lips ({pre_lps, post_lps} of a result's view, closed
 * loops, LPS mm), named 'scar': the pre-operative lines as a morph of the post-operative scar, so
 * setScarMorph() moves them with the skin's pre-to-post slider. */
export function scarObjects(lines) {
  return lines.filter((l) => l.pre_lps.length >= 3).map(({ pre_lps, post_lps }) => {
    const segments = Math.max(16, pre_lps.length * 2);
    const tube = (points) => new TubeGeometry(
      new CatmullRomCurve3(points.map(lpsToScene), true, 'centripetal'), segments, kLineRadius, 6, true);
    const geometry = tube(pre_lps);
    const post = tube(post_lps);
    geometry.morphAttributes.position = [post.getAttribute('position')];
    geometry.morphAttributes.normal = [post.getAttribute('normal')];
    post.dispose();
    const m = new Mesh(geometry, new MeshBasicMaterial({ color: kScarColour.clone() }));
    m.name = 'scar';
    return m;
  });
}

/** Moves scarObjects() to the skin's morph `t` (0 pre, 1 post) and colours them from the plan's
 * line colour (the incision marked on the skin) to the scar's; the sutures (any other object)
 * show only on the closed skin. */
export function setScarMorph(objects, t) {
  for (const o of objects) {
    if (o.name === 'scar') {
      o.morphTargetInfluences[0] = t;
      o.material.color.copy(lineMaterial.color).lerp(kScarColour, t);
    } else {
      o.visible = t >= 1;
    }
  }
}

/** A colour from blue (0) to red (1) for a force relative to the largest. */
export function forceColour(fraction) {
  return new Color().setHSL((1 - Math.min(1, Math.max(0, fraction))) * 0.66, 0.85, 0.5);
}

/** Spheres at the sutures ({position_mm, force_n}, LPS on the closed skin), coloured by force. */
export function sutureObjects(sutures) {
  const max = Math.max(1e-12, ...sutures.map((s) => s.force_n));
  const ball = new SphereGeometry(0.0012, 14, 10);
  return sutures.map((s) => {
    const m = new Mesh(ball, new MeshBasicMaterial({ color: forceColour(s.force_n / max) }));
    m.position.copy(lpsToScene(s.position_mm));
    return m;
  });
}
