// The plan being edited, laid on the model by the server (POST /api/plan/new, the same as
// `caps plan new`) whenever it changes, its check shown in plain words, its lines drawn on the
// skin; undo and redo. Three kinds of state:
//   a template: {procedure, parameters, orientation, at | at_xyz, sutures} placed by clicking
//     (at_xyz) or at a landmark (at "glabella+15,20", the command line's --at; the arrow keys then
//     change its offsets, so the plan stays recorded at the landmark), moved by dragging the
//     yellow handle or with the arrow keys, turned by dragging the cyan
//     handle (or R), scaled by dragging the magenta one (every parameter in mm, in proportion);
//   a free incision: {procedure: 'incision', points: [[x, y, z] LPS mm], sutures}, drawn by
//     clicking along the skin (`caps plan new incision --points-xyz`), points dragged to move;
//   a loaded plan the page cannot redraw: {procedure: 'loaded', plan, sutures}.
// `sutures` (the plan file's pairs) replaces the procedure's own when not null; the plan is then
// checked again with them (POST /api/plan/check).
import { api } from './api.js';
import { sceneToLps } from './frames.js';
import { History } from './history.js';
import { landmarkAt, parseLandmarkAt } from './landmarks.js';
import { axisHandleObjects, handleObject, planObjects, pointHandles } from './overlays.js';
import { edgePair, pickEdge, remapIncisionSutures, sutureMarks } from './sutures.js';

const kRotateStepDeg = 5;
const kClickSlopPx = 4;
export const kIncision = 'incision';

export class Planner {
  /**
   * @param viewer    the main Viewer
   * @param templates GET /api/templates
   * @param ui        {onState(state), onCheck(plan|null, message|null), onHistory(canUndo, canRedo), onPlanChanged()}
   */
  constructor(viewer, templates, ui) {
    this.viewer = viewer;
    this.showSutures = true;
    this.picking = null;     // choosing a suture pair: {replace: index | -1, first: edge | -1}
    this.skinClick = null;   // (lps) => ..., set while a click on the skin draws something else
    this.templates = new Map(templates.map((t) => [t.name, t]));
    this.ui = ui;
    this.state = null;       // null until placed
    this.plan = null;        // the checked plan (plan file JSON with its check), null if refused
    this.lines = null;       // /api/plan/lines of this.plan
    this.procedure = templates[0].name;
    this.parameters = this.defaults(this.procedure);
    this.history = new History(() => ui.onHistory(this.history.canUndo, this.history.canRedo));
    this.inFlight = null;    // the request under way
    this.queued = false;     // a newer state waits for it
    this.settled = Promise.resolve();
    this.bindPointer();
  }

  // The parameters sent for a new plan: each default, except those that are an alternative to
  // another (the ellipse's apex_angle sets its width: one of the two is given).
  defaults(name) {
    const t = this.templates.get(name);
    return Object.fromEntries(t.parameters.filter((p) => !p.alternative_to)
      .map((p) => [p.name, p.default]));
  }

  /** Chooses the procedure from the menu: a template keeps the plan's centre and orientation
   * if one is placed; a free incision starts with no point. The sutures go back to the
   * procedure's own. */
  setProcedure(name) {
    this.procedure = name;
    this.cancelPick();
    if (name === kIncision) {
      this.parameters = {};
      this.change({ procedure: kIncision, points: [], sutures: null });
      return;
    }
    this.parameters = this.defaults(name);
    if (!this.state) return;
    if (this.state.procedure === kIncision || this.state.procedure === 'loaded') {
      const centre = this.lines?.centre;
      if (!centre) {
        this.change(null);
        return;
      }
      this.change({ procedure: name, parameters: { ...this.parameters },
        orientation: centre.orientation_deg, at: `${centre.theta_deg},${centre.z_mm}`, at_xyz: '',
        sutures: null });
      return;
    }
    this.change({ ...this.state, procedure: name, parameters: { ...this.parameters }, sutures: null });
  }

  get isIncision() {
    return this.state?.procedure === kIncision;
  }

  /** A free incision: a new one with no point. */
  newIncision() {
    this.change({ procedure: kIncision, points: [], sutures: null });
  }

  /** A free incision's points changed: its sutures follow their segments (remapIncisionSutures). */
  withPoints(points) {
    const from = this.state.points.length;
    let sutures = this.state.sutures;
    if (sutures) {
      const r = remapIncisionSutures(sutures, from, points.length);
      sutures = r.sutures;
      if (r.dropped) this.ui.onNotice?.(`${r.dropped} suture pair(s) on the removed segment dropped.`);
    }
    return { ...this.state, points, sutures };
  }

  /** Removes the last point of a free incision. */
  removeLastPoint() {
    if (!this.isIncision || !this.state.points.length) return;
    this.change(this.withPoints(this.state.points.slice(0, -1)));
  }

  // ---- sutures -------------------------------------------------------------------------------

  /** The plan's suture pairs as the plan file writes them. */
  get sutures() {
    return this.state?.sutures ?? this.plan?.sutures ?? [];
  }

  setSutures(sutures) {
    if (this.state) this.change({ ...this.state, sutures });
  }

  removeSuture(k) {
    this.setSutures(this.sutures.filter((_, i) => i !== k));
  }

  /** Back to the procedure's own sutures (a free incision: none). */
  resetSutures() {
    this.setSutures(null);
  }

  /** Starts choosing a pair by clicking its two sides; `replace`: the pair it replaces, or -1. */
  startPick(replace = -1) {
    if (!this.lines?.loop) return;
    this.picking = { replace, first: -1 };
    this.ui.onPick?.(this.picking);
    this.drawOverlay();
  }

  cancelPick() {
    if (!this.picking) return;
    this.picking = null;
    this.ui.onPick?.(null);
    this.drawOverlay();
  }

  // A click at `lps` while choosing a pair.
  pickAt(lps) {
    const loop = this.lines.loop;
    const edge = pickEdge(loop, lps);
    if (edge < 0) {
      this.ui.onNotice?.('Click on the skin just beside the cut, on the side to sew.');
      return;
    }
    if (this.picking.first < 0) {
      this.picking.first = edge;
      this.ui.onPick?.(this.picking);
      this.drawOverlay();
      return;
    }
    if (edge === this.picking.first) {
      this.ui.onNotice?.('That is the same side; click the side it is sewn to.');
      return;
    }
    const pair = edgePair(this.picking.first, edge, loop.nodes.length);
    const sutures = [...this.sutures];
    if (this.picking.replace >= 0) sutures[this.picking.replace] = pair;
    else sutures.push(pair);
    this.picking = null;
    this.ui.onPick?.(null);
    this.setSutures(sutures);
  }

  setParameter(name, value) {
    // Setting one of two alternatives drops the other.
    for (const p of this.templates.get(this.procedure).parameters) {
      if (p.name === name && p.alternative_to) delete this.parameters[p.alternative_to];
      if (p.alternative_to === name) delete this.parameters[p.name];
    }
    this.parameters[name] = value;
    if (this.state) this.change({ ...this.state, parameters: { ...this.parameters } });
  }

  setOrientation(deg) {
    if (this.state) this.change({ ...this.state, orientation: deg });
  }

  /** A click on the skin at `lps` (mm): a free incision gains a point there; a template is
   * placed with its centre there. */
  placeAt(lps) {
    if (this.procedure === kIncision) {
      this.change(this.isIncision ? this.withPoints([...this.state.points, lps])
        : { procedure: kIncision, points: [lps], sutures: null });
      return;
    }
    const at_xyz = lps.map((v) => v.toFixed(2)).join(',');
    const base = this.state?.procedure === this.procedure ? this.state : { orientation: 90 };
    // A refusal keeps the last lines drawn in red, which shows a drag or a key that went too far;
    // after a click elsewhere they would be another place's plan.
    this.lines = null;
    this.change({ procedure: this.procedure, parameters: { ...this.parameters },
      orientation: base.orientation ?? 90, at_xyz, at: '', sutures: base.sutures ?? null });
  }

  /** A new state: recorded for undo (unless `transient`), then laid and checked. */
  change(state, { transient = false } = {}) {
    if (!transient && this.state) this.history.push(this.dragStart ?? this.state);
    if (!transient) this.dragStart = null;
    return this.restore(state);
  }

  undo() {
    const s = this.history.undo(this.state);
    if (s) this.restore(s);
  }

  redo() {
    const s = this.history.redo(this.state);
    if (s) this.restore(s);
  }

  restore(s) {
    this.state = s;
    if (s && s.procedure !== 'loaded') this.procedure = s.procedure;
    this.parameters = { ...(s?.parameters ?? {}) };
    this.ui.onState(s);
    this.ui.onPlanChanged();
    return this.update();
  }

  /** Lays the state on the model; only the latest state is sent when several come quickly. */
  update() {
    if (this.inFlight) {
      this.queued = true;
      return this.settled;
    }
    const s = this.state;
    if (!s || (s.procedure === kIncision && s.points.length < 2)) {
      // Nothing to lay yet: a free incision's first point is drawn by the page alone.
      this.show(null, null, null);
      document.body.dataset.check = 'none';
      return this.settled;
    }
    document.body.dataset.check = 'pending';
    const t0 = performance.now();
    this.inFlight = (async () => {
      try {
        let plan;
        if (s.procedure === 'loaded') plan = s.plan;
        else if (s.procedure === kIncision)
          plan = await api.planNew({ procedure: kIncision,
            points_xyz: s.points.map((p) => p.map((v) => v.toFixed(2)).join(',')).join(';') });
        else {
          const request = { procedure: s.procedure, orientation: s.orientation, parameters: s.parameters };
          if (s.at) request.at = s.at;
          else request.at_xyz = s.at_xyz;
          plan = await api.planNew(request);
        }
        // The user's sutures (or a loaded plan's) are checked with the plan they belong to.
        if (s.sutures || s.procedure === 'loaded')
          plan = await api.planCheck({ ...plan, sutures: s.sutures ?? plan.sutures });
        const lines = await api.planLines(plan);
        this.lastLatencyMs = performance.now() - t0;
        // A state changed (or a plan loaded) while this one was on its way: its answer is stale,
        // and the newer state shows its own (a queued update, or the load itself).
        if (this.state !== s) return;
        // Later moves and keys start from the plan's own (theta, z).
        if (s.at === '')
          s.at = `${plan.frame.theta_deg.toFixed(3)},${plan.frame.z_mm.toFixed(3)}`;
        this.show(plan, lines, null);
      } catch (e) {
        if (this.state === s) this.show(null, this.lines, e.message);
      }
    })();
    const settled = this.inFlight.then(() => {
      this.inFlight = null;
      if (this.queued) {
        this.queued = false;
        // With nothing to lay (a free incision back to one point) update() returns this very
        // promise: resolving a promise with itself is a chaining cycle, an error on the page.
        const next = this.update();
        return next === settled ? undefined : next;
      }
      document.body.dataset.check = this.plan ? 'ok' : 'refused';
    });
    this.settled = settled;
    return settled;
  }

  /** Shows a plan (or a refusal, keeping the last lines drawn in red). */
  show(plan, lines, message) {
    this.plan = plan;
    this.lines = lines;
    this.drawOverlay();
    this.ui.onCheck(plan, message, this.state);
  }

  // The plan's lines, its handles (the centre's, or a free incision's points) and its sutures.
  drawOverlay() {
    const lines = this.lines, s = this.state;
    const objects = lines ? planObjects(lines, { refused: !this.plan }) : [];
    if (s?.procedure === kIncision) {
      objects.length = 0;
      if (lines && s.points.length >= 2) objects.push(...planObjects({ ...lines, points_lps: [] },
        { refused: !this.plan }));
      objects.push(...pointHandles(s.points));
    } else if (lines && s && s.procedure !== 'loaded') {
      objects.push(handleObject(lines.centre.lps));
      if (lines.centre.rotate_handle_lps) objects.push(...axisHandleObjects(lines.centre));
    }
    if (lines?.loop && this.plan && (this.showSutures || this.picking))
      objects.push(...sutureMarks(lines.loop, this.plan.suture_quadruples ?? [],
        { highlight: this.picking?.first ?? -1 }));
    this.handle = objects.find((o) => o.name === 'handle') ?? null;
    this.axisHandles = objects.filter((o) => o.name === 'rotate' || o.name === 'scale');
    this.pointHandles = objects.filter((o) => o.name === 'point');
    this.viewer.setOverlay(objects);
  }

  setShowSutures(on) {
    this.showSutures = on;
    this.drawOverlay();
  }

  /** A plan file loaded by the user: checked on the server, then edited from its centre. */
  async load(planJson, fileName) {
    const plan = await api.planCheck(planJson, undefined, fileName);
    const lines = await api.planLines(plan);
    const name = plan.procedure?.name ?? plan.procedure;
    if (this.state) this.history.push(this.state);
    const path = plan.paths?.[0] ?? [];
    const oneCut = plan.paths?.length === 1 && path.every((p, i) => p === i) &&
      path.length === plan.points.length && !plan.excisions?.length && !plan.flaps?.length;
    if (this.templates.has(name)) {
      // The template's own sutures are kept as the state's only when they were changed.
      // A plan placed at a landmark stays placed there (its file records the landmark).
      const a = plan.at;
      const at = a?.landmark ? landmarkAt(a.landmark, a.left_mm ?? 0, a.up_mm ?? 0)
        : `${plan.frame.theta_deg},${plan.frame.z_mm}`;
      // A plan file records every parameter, also one set by another (an ellipse's apex_angle
      // by its width): plan new takes the one it is set by.
      const parameters = { ...plan.procedure.parameters };
      for (const p of this.templates.get(name).parameters)
        if (p.alternative_to && parameters[p.alternative_to] !== undefined) delete parameters[p.name];
      const own = await api.planNew({ procedure: name, parameters,
        orientation: plan.frame.orientation_deg, at });
      const changed = JSON.stringify(own.sutures) !== JSON.stringify(plan.sutures);
      this.state = { procedure: name, parameters,
        orientation: plan.frame.orientation_deg, at, at_xyz: '',
        sutures: changed ? plan.sutures : null };
      this.procedure = name;
    } else if (oneCut) {
      this.state = { procedure: kIncision, points: lines.points_lps, sutures: plan.sutures ?? [] };
      this.procedure = kIncision;
    } else {
      this.state = { procedure: 'loaded', plan, sutures: null };
    }
    this.parameters = { ...(this.state.parameters ?? {}) };
    this.ui.onState(this.state);
    this.ui.onPlanChanged();
    this.show(plan, lines, null);
    document.body.dataset.check = 'ok';
  }

  /** Moves the centre by `leftMm` to the patient's left and `upMm` up: a landmark placement's
   * offsets change by as much; a (theta, z) centre moves by (leftMm in degrees here, upMm). */
  moveBy(leftMm, upMm) {
    if (!this.state?.at) return;
    const mark = parseLandmarkAt(this.state.at);
    const round = (v) => +v.toFixed(3);
    if (mark) {
      this.change({ ...this.state,
        at: landmarkAt(mark.name, round(mark.leftMm + leftMm), round(mark.upMm + upMm)) });
      return;
    }
    const [theta, z] = this.state.at.split(',').map(Number);
    const dtheta = leftMm * this.thetaDegPerMm();
    this.change({ ...this.state, at: `${(theta + dtheta).toFixed(3)},${(z + upMm).toFixed(3)}` });
  }

  /** Degrees of theta for `mm` of arc along theta at the plan's centre (from its frame). */
  thetaDegPerMm() {
    const m = this.plan?.frame?.local_to_theta_z;
    if (!m) return 0.5;
    // local (x, y) mm -> (dtheta, dz): the local vector with dz = 0 and its length in mm.
    const [[a, b], [c, d]] = m;
    const det = a * d - b * c;
    const x = d / det, y = -c / det;  // inverse applied to (1, 0)
    return 1 / Math.hypot(x, y);
  }

  onKey(e) {
    if (!this.state || e.target.closest?.('input, select, textarea')) return false;
    const step = e.shiftKey ? 5 : 1;
    const k = e.key;
    if (k === 'Escape' && this.picking) this.cancelPick();
    else if (this.isIncision) {
      if (k === 'Backspace' || k === 'Delete') this.removeLastPoint();
      else return false;
    } else if (this.state.procedure === 'loaded') return false;
    else if (k === 'ArrowUp') this.moveBy(0, step);
    else if (k === 'ArrowDown') this.moveBy(0, -step);
    else if (k === 'ArrowRight') this.moveBy(step, 0);
    else if (k === 'ArrowLeft') this.moveBy(-step, 0);
    else if (k === 'r' || k === 'R')
      this.setOrientation(this.state.orientation + (e.shiftKey ? -kRotateStepDeg : kRotateStepDeg));
    else return false;
    return true;
  }

  // The state while the cyan (rotate) or magenta (scale) handle is dragged to the skin point
  // `lps` (mm), from the plan as it was when the drag began (`start`: its state and centre). The
  // page works in the skin's tangent plane at the centre (a the plan's axis, n the skin normal;
  // the orientation turns from superior towards the patient's left, i.e. towards a x n):
  // turning points the axis's start at the pointer, scaling puts the axis's end under it.
  axisDragState(kind, start, lps) {
    const { state, centre } = start;
    const c = centre.lps, n = centre.normal_lps, a = centre.axis_lps;
    const dot = (u, v) => u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let d = [0, 1, 2].map((i) => lps[i] - c[i]);
    const dn = dot(d, n);
    d = d.map((v, i) => v - dn * n[i]);  // into the tangent plane
    if (Math.hypot(...d) < 1e-6) return null;
    if (kind === 'rotate') {
      const b = [a[1] * n[2] - a[2] * n[1], a[2] * n[0] - a[0] * n[2], a[0] * n[1] - a[1] * n[0]];
      // the handle sits at the axis's start: the axis points away from it
      const turn = Math.atan2(-dot(d, b), -dot(d, a)) * 180 / Math.PI;
      let orientation = state.orientation + turn;
      orientation = Math.round((((orientation + 180) % 360 + 360) % 360 - 180) * 10) / 10;
      return { ...state, orientation };
    }
    const half = centre.half_extent_mm;
    if (!(half > 0)) return null;
    const factor = Math.max(0.05, (dot(d, a) - centre.handle_gap_mm) / half);
    const parameters = { ...state.parameters };
    for (const p of this.templates.get(state.procedure).parameters)
      if (p.unit === 'mm' && parameters[p.name] !== undefined)
        // to the sliders' half millimetres
        parameters[p.name] = Math.min(p.max, Math.max(p.min,
          Math.round(parameters[p.name] * factor * 2) / 2));
    return { ...state, parameters };
  }

  // Click on the skin: place (or add a point, or pick a suture's side); drag the handle or an
  // incision's point: move it; drag the cyan or magenta handle: turn or scale the template (one
  // undo step per drag); else orbit.
  bindPointer() {
    const el = this.viewer.renderer.domElement;
    let down = null;
    el.addEventListener('pointerdown', (e) => {
      down = { x: e.clientX, y: e.clientY, drag: false };
      if (this.picking) return;
      const point = this.pointHandles?.length ? this.viewer.hits(e, this.pointHandles)[0] : null;
      const axis = this.axisHandles?.length ? this.viewer.hits(e, this.axisHandles)[0] : null;
      if (point || axis || (this.handle && this.viewer.hits(e, [this.handle]).length)) {
        down.drag = true;
        down.point = point ? point.object.userData.index : -1;
        down.axis = axis && !point ? { kind: axis.object.name,
          start: { state: structuredClone(this.state), centre: this.lines.centre } } : null;
        this.dragStart = structuredClone(this.state);
        this.viewer.controls.enabled = false;
        el.setPointerCapture(e.pointerId);
      }
    });
    el.addEventListener('pointermove', (e) => {
      if (!down?.drag) return;
      const p = this.viewer.pickSkin(e);
      if (!p) return;
      const lps = sceneToLps(p);
      if (down.axis) {
        const next = this.axisDragState(down.axis.kind, down.axis.start, lps);
        if (next) this.change(next, { transient: true });
      } else if (down.point >= 0) {
        const points = this.state.points.map((q, i) => (i === down.point ? lps : q));
        this.change({ ...this.state, points }, { transient: true });
      } else {
        const at_xyz = lps.map((v) => v.toFixed(2)).join(',');
        this.change({ ...this.state, at_xyz, at: '' }, { transient: true });
      }
    });
    el.addEventListener('pointerup', (e) => {
      if (!down) return;
      const moved = Math.hypot(e.clientX - down.x, e.clientY - down.y);
      if (down.drag) {
        this.viewer.controls.enabled = true;
        if (moved > 0 && this.dragStart) this.change(this.state);  // one undo step
        this.dragStart = null;
      } else if (moved <= kClickSlopPx) {
        const p = this.viewer.pickSkin(e);
        if (p && this.picking) this.pickAt(sceneToLps(p));
        else if (p && this.skinClick) this.skinClick(sceneToLps(p));
        else if (p) this.placeAt(sceneToLps(p));
      }
      down = null;
    });
  }
}
