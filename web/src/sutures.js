// The plan's sutures on the page: which side of the cut a click is on (a border edge of the
// plan's loop), the pairs as the plan file writes them, their remapping when a free incision gains
// or loses a point, and the coloured marks that show which side is sewn to which.
//
// The border loop (docs/plan.md, "The paper's rules"): a cut 0..n-1 becomes the loop 0..n-1,
// n-2..1; loop edge i joins loop nodes i and i+1 (mod the loop's size) and keeps the tissue on its
// left as seen from outside, so the side of the cut an edge stands for is the left of its
// direction: n x (b - a) with n the skin's outward normal (LPS is right-handed).
import { Color, CatmullRomCurve3, Mesh, MeshBasicMaterial, TubeGeometry } from 'three';
import { lpsToScene } from './frames.js';

const kPickMm = 8;          // a click farther than this from every edge picks none
const kSideOffsetMm = 1.1;  // each sewn side is drawn this far into its own tissue
const kTubeRadius = 0.00035;

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const unit = (a) => scale(a, 1 / Math.max(1e-12, Math.hypot(...a)));

/** The direction (LPS, unit) into the tissue an edge of the loop stands for. */
function edgeSide(loop, i) {
  const n = loop.nodes.length;
  const e = loop.edges_lps[i];
  const normal = unit(add(loop.nodes[i].normal_lps, loop.nodes[(i + 1) % n].normal_lps));
  return unit(cross(normal, sub(e[e.length - 1], e[0])));
}

/**
 * The border edge a click at `lps` (mm) stands for: the nearest edge on whose side of the cut the
 * click is (twin edges lie on each other; the click's side tells them apart), or -1.
 * @param loop /api/plan/lines' "loop": {nodes: [{lps, normal_lps}], edges_lps}
 */
export function pickEdge(loop, lps) {
  let best = -1, bestDistance = kPickMm;
  loop.edges_lps.forEach((pts, i) => {
    const side = edgeSide(loop, i);
    for (let k = 0; k + 1 < pts.length; ++k) {
      const a = pts[k], d = sub(pts[k + 1], a);
      const t = Math.min(1, Math.max(0, dot(sub(lps, a), d) / Math.max(1e-12, dot(d, d))));
      const closest = add(a, scale(d, t));
      const off = sub(lps, closest);
      const distance = Math.hypot(...off);
      if (distance < bestDistance && dot(off, side) > 0) {
        best = i;
        bestDistance = distance;
      }
    }
  });
  return best;
}

/** A suture pair sewing loop edges i and j, as the plan file writes it. */
export function edgePair(i, j, loopSize) {
  return [[i, (i + 1) % loopSize], [j, (j + 1) % loopSize]];
}

/** "0–1" for a side of a pair (an edge or a run of loop nodes). */
export function sideText(side) {
  return side.join('–');
}

// A free incision of n points (one path 0..n-1): loop edge i as (segment s, side), segment s
// joining points s and s+1, side 'L' (loop nodes 0..n-1) or 'R' (the twins).
function edgeToSegment(i, n) {
  if (i < n - 1) return { s: i, side: 'L' };
  return { s: 2 * n - 3 - i, side: 'R' };
}

function segmentToEdge({ s, side }, n) {
  if (s < 0 || s > n - 2) return null;
  return side === 'L' ? s : 2 * n - 3 - s;
}

/**
 * The sutures of a free incision of `from` points rewritten for the same cut with `to` points
 * (points added or removed at its end): each sewn edge keeps its segment and side; pairs that name
 * a removed segment, or that are runs, are dropped. @return {sutures, dropped}
 */
export function remapIncisionSutures(sutures, from, to) {
  const loopTo = 2 * to - 2;
  const out = [];
  let dropped = 0;
  for (const pair of sutures ?? []) {
    const edges = pair.map((side) => {
      if (side.length !== 2) return null;
      const loopFrom = 2 * from - 2;
      const i = (side[1] - side[0] + loopFrom) % loopFrom === 1 ? side[0] : side[1];
      return segmentToEdge(edgeToSegment(i, from), to);
    });
    if (edges.some((e) => e === null) || to < 2) ++dropped;
    else out.push(edgePair(edges[0], edges[1], loopTo));
  }
  return { sutures: out, dropped };
}

/** The edges of an oriented pair (a, b, c, d) (plan.suture_quadruples): a..b-1 and d..c-1. */
export function quadrupleEdges([a, b, c, d], loopSize) {
  const run = (from, to) => {
    const edges = [];
    for (let i = from; i !== to; i = (i + 1) % loopSize) edges.push(i);
    return edges.length ? edges : [from];
  };
  return [run(a, b), run(d, c)];
}

/** A colour for suture pair k (distinct for the first dozen). */
export function pairColour(k) {
  return new Color().setHSL(((k * 0.61803) % 1 + 1) % 1, 0.8, 0.45);
}

function offsetLine(loop, i) {
  const side = edgeSide(loop, i);
  return loop.edges_lps[i].map((p) => add(p, scale(side, kSideOffsetMm)));
}

function tube(points, colour, radius = kTubeRadius) {
  const curve = new CatmullRomCurve3(points.map(lpsToScene), false, 'centripetal');
  return new Mesh(new TubeGeometry(curve, Math.max(6, points.length * 2), radius, 5, false),
    new MeshBasicMaterial({ color: colour }));
}

/**
 * Marks for the plan's suture pairs: each side drawn along its edges, just inside its own tissue,
 * in the pair's colour, and a thin link between the middles of the two sides. `highlight`: a loop
 * edge being picked (drawn white).
 */
export function sutureMarks(loop, quadruples, { highlight = -1 } = {}) {
  const n = loop.nodes.length;
  const objects = [];
  quadruples.forEach((q, k) => {
    const colour = pairColour(k);
    const middles = quadrupleEdges(q, n).map((edges) => {
      const lines = edges.map((i) => offsetLine(loop, i));
      for (const l of lines) objects.push(tube(l, colour));
      const mid = lines[Math.floor(lines.length / 2)];
      return lines.length % 2 ? mid[Math.floor(mid.length / 2)] : mid[0];
    });
    if (Math.hypot(...sub(middles[0], middles[1])) > 0.5)
      objects.push(tube([middles[0], middles[1]], colour, kTubeRadius * 0.5));
  });
  if (highlight >= 0) objects.push(tube(offsetLine(loop, highlight), 0xffffff, kTubeRadius * 1.4));
  for (const o of objects) o.name = 'suture-mark';
  return objects;
}
