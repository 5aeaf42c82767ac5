// The plan being edited: its state (procedure, parameters, centre, orientation), laid on the
// model by the server (POST /api/plan/new, the same as `caps plan new`) whenever it changes, its
// check shown in plain words, its lines drawn on the skin; placed by clicking, moved by dragging
// the handle or with the arrow keys, rotated with R; undo and redo.
import { api } from './api.js';
import { sceneToLps } from './frames.js';
import { History } from './history.js';
import { handleObject, planObjects } from './overlays.js';

const kRotateStepDeg = 5;
const kClickSlopPx = 4;

export class Planner {
  /**
   * @param viewer    the main Viewer
   * @param templates GET /api/templates
   * @param ui        {onState(state), onCheck(plan|null, message|null), onHistory(canUndo, canRedo), onPlanChanged()}
   */
  constructor(viewer, templates, ui) {
    this.viewer = viewer;
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

  /** Chooses the procedure from the menu (keeps the centre and orientation if placed). */
  setProcedure(name) {
    this.procedure = name;
    this.parameters = this.defaults(name);
    if (this.state) this.change({ ...this.state, procedure: name, parameters: { ...this.parameters } });
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

  /** Places the current procedure with its centre at the skin point `lps` (mm). */
  placeAt(lps) {
    const at_xyz = lps.map((v) => v.toFixed(2)).join(',');
    const base = this.state ?? { orientation: 90 };
    this.change({ procedure: this.procedure, parameters: { ...this.parameters },
      orientation: base.orientation, at_xyz, at: '' });
  }

  /** A new state: recorded for undo (unless `transient`), then laid and checked. */
  change(state, { transient = false } = {}) {
    if (!transient && this.state) this.history.push(this.dragStart ?? this.state);
    if (!transient) this.dragStart = null;
    this.state = state;
    this.procedure = state.procedure;
    this.parameters = { ...state.parameters };
    this.ui.onState(state);
    this.ui.onPlanChanged();
    return this.update();
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
    this.procedure = s.procedure;
    this.parameters = { ...s.parameters };
    this.ui.onState(s);
    this.ui.onPlanChanged();
    this.update();
  }

  /** Lays the state on the model; only the latest state is sent when several come quickly. */
  update() {
    if (this.inFlight) {
      this.queued = true;
      return this.settled;
    }
    const s = this.state;
    const request = { procedure: s.procedure, orientation: s.orientation, parameters: s.parameters };
    if (s.at) request.at = s.at;
    else request.at_xyz = s.at_xyz;
    document.body.dataset.check = 'pending';
    const t0 = performance.now();
    this.inFlight = (async () => {
      try {
        const plan = await api.planNew(request);
        const lines = await api.planLines(plan);
        this.lastLatencyMs = performance.now() - t0;
        // Later moves and keys start from the plan's own (theta, z).
        if (this.state === s && !s.at)
          s.at = `${plan.frame.theta_deg.toFixed(3)},${plan.frame.z_mm.toFixed(3)}`;
        this.show(plan, lines, null);
      } catch (e) {
        this.show(null, this.lines, e.message);
      }
    })();
    this.settled = this.inFlight.then(() => {
      this.inFlight = null;
      if (this.queued) {
        this.queued = false;
        return this.update();
      }
      document.body.dataset.check = this.plan ? 'ok' : 'refused';
    });
    return this.settled;
  }

  /** Shows a plan (or a refusal, keeping the last lines drawn in red). */
  show(plan, lines, message) {
    this.plan = plan;
    this.lines = lines;
    const objects = lines ? planObjects(lines, { refused: !plan }) : [];
    if (lines) objects.push(handleObject(lines.centre.lps));
    this.handle = objects.find((o) => o.name === 'handle') ?? null;
    this.viewer.setOverlay(objects);
    this.ui.onCheck(plan, message);
  }

  /** A plan file loaded by the user: checked on the server, then edited from its centre. */
  async load(planJson) {
    const plan = await api.planCheck(planJson);
    const lines = await api.planLines(plan);
    const name = plan.procedure?.name ?? plan.procedure;
    if (this.state) this.history.push(this.state);
    if (this.templates.has(name)) {
      this.state = { procedure: name, parameters: { ...plan.procedure.parameters },
        orientation: plan.frame.orientation_deg,
        at: `${plan.frame.theta_deg},${plan.frame.z_mm}`, at_xyz: '' };
      this.procedure = name;
      this.parameters = { ...this.state.parameters };
      this.ui.onState(this.state);
    }
    this.ui.onPlanChanged();
    this.show(plan, lines, null);
    document.body.dataset.check = 'ok';
  }

  /** Moves the centre by (dtheta deg, dz mm). */
  moveBy(dtheta, dz) {
    if (!this.state?.at) return;
    const [theta, z] = this.state.at.split(',').map(Number);
    this.change({ ...this.state, at: `${(theta + dtheta).toFixed(3)},${(z + dz).toFixed(3)}` });
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
    if (k === 'ArrowUp') this.moveBy(0, step);
    else if (k === 'ArrowDown') this.moveBy(0, -step);
    else if (k === 'ArrowRight') this.moveBy(step * this.thetaDegPerMm(), 0);
    else if (k === 'ArrowLeft') this.moveBy(-step * this.thetaDegPerMm(), 0);
    else if (k === 'r' || k === 'R')
      this.setOrientation(this.state.orientation + (e.shiftKey ? -kRotateStepDeg : kRotateStepDeg));
    else return false;
    return true;
  }

  // Click on the skin: place; drag the handle: move (one undo step per drag); else orbit.
  bindPointer() {
    const el = this.viewer.renderer.domElement;
    let down = null;
    el.addEventListener('pointerdown', (e) => {
      down = { x: e.clientX, y: e.clientY, drag: false };
      if (this.handle && this.viewer.hits(e, [this.handle]).length) {
        down.drag = true;
        this.dragStart = structuredClone(this.state);
        this.viewer.controls.enabled = false;
        el.setPointerCapture(e.pointerId);
      }
    });
    el.addEventListener('pointermove', (e) => {
      if (!down?.drag) return;
      const p = this.viewer.pickSkin(e);
      if (p) {
        const at_xyz = sceneToLps(p).map((v) => v.toFixed(2)).join(',');
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
        if (p) this.placeAt(sceneToLps(p));
      }
      down = null;
    });
  }
}
