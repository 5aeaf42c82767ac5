// Simulations and the alternatives: Simulate sends the checked plan to POST /api/simulate (the
// result `caps simulate --json` prints), shows progress while it runs, then the post-operative
// skin as a morph (pre -> post slider, Play), the tension map and the force of each suture. Every
// simulated plan is kept as a row of the alternatives table; two of them can be shown side by
// side in two views that move together.
import { api, apiFetch } from './api.js';
import { scarObjects, setScarMorph, sutureObjects } from './overlays.js';
import { loadResultSkin } from './skin.js';

const kPollMs = 100;
const kPlaySeconds = 2;

const fmt = (v, digits = 2) => (Number.isFinite(v) ? v.toFixed(digits) : '–');

/** A short name for a plan: the procedure and its parameters (a drawn cut: its points);
 * `ownSutures`: a template sewn with the user's pairs rather than its own. */
export function planLabel(plan, ownSutures = false) {
  const p = plan.procedure ?? {};
  const pairs = plan.sutures?.length ?? 0;
  if ((p.name ?? 'custom') === 'custom')
    return `drawn cut (${plan.points?.length ?? 0} points, ${pairs} suture pair${pairs === 1 ? '' : 's'})`;
  const params = Object.entries(p.parameters ?? {}).map(([k, v]) => `${k} ${+v.toFixed(1)}`);
  return `${p.name} (${params.join(', ')}; ${+plan.frame.orientation_deg.toFixed(0)}°` +
    `${ownSutures ? `; your ${pairs} suture pair${pairs === 1 ? '' : 's'}` : ''})`;
}

/** The settings a row was simulated with, so that alternatives of one plan can be told apart:
 * the material, the tissue, the mesh size. */
export function settingsLabel(result, options = {}) {
  const tissue = options.tissue === 'auto' || options.tissue === 'measured' ? 'measured layers' : 'one tissue';
  const mesh = options.mesh_size ? `${options.mesh_size} mm mesh` : 'default mesh';
  return `${result.material ?? options.material ?? ''}, ${tissue}, ${mesh}`;
}

export class Results {
  constructor(viewA, viewB, el) {
    this.views = [viewA, viewB];
    this.el = el;
    this.rows = [];          // {n, plan, result, view, sutures, skins: [skin in A, skin in B]}
    this.shown = [null, null];
    this.modelSkin = null;   // the model's ColouredSkin, shown while no result is
    this.colouring = 'skin';
    this.morph = 1;
    this.lastResultId = 0;   // the newest result id taken from the server (ids only grow)
  }

  /** Runs the simulation of `plan` with `options`; adds its row and shows it in view A. A
   * finite-strain closure asks the server for a first answer (the linear closure of the same
   * plan, docs/planner.md "First answer"): it is shown, labelled, as soon as it is there, and
   * replaced by the finite-strain result; if that one fails, runs out of its time limit or is
   * cancelled, the first answer stays, labelled with why. */
  async simulate(plan, options, { ownSutures = false } = {}) {
    const e = this.el;
    e.progress.hidden = false;
    e.progressText.textContent = 'starting…';
    e.progressBar.removeAttribute('value');
    document.body.dataset.simulation = 'running';
    const t0 = performance.now();
    const firstAnswer = (options.material ?? 'neo-hookean') !== 'linear';
    let first = null;         // the first answer's row, once shown
    let firstLoading = null;  // its loading
    // The progress board's first answer is this request's only if it is newer than every result
    // taken so far (until the server starts this request, the board holds the last one's).
    const ours = (answer) => answer && answer.result_id > this.lastResultId;
    const showFirst = (result) => {
      this.lastResultId = Math.max(this.lastResultId, result.result_id);
      firstLoading ??= (async () => {
        const row = await this.resultRow(plan, result, ownSutures, options);
        row.provisional = 'first answer: the linear (small-strain) closure of the patch around the wound, ' +
          'clamped at its rim; the finite-strain closure in the whole face is running';
        row.seconds = (performance.now() - t0) / 1000;
        this.rows.push(row);
        await this.showRow(row, 0);
        await this.views[0].nextFrame();
        row.timing = { first_answer_s: (performance.now() - t0) / 1000 };
        first = row;
        document.body.dataset.firstAnswer = 'shown';
      })();
      return firstLoading;
    };
    const poll = setInterval(async () => {
      try {
        const p = await api.progress();
        if (firstAnswer && ours(p.first_answer) && !firstLoading) showFirst(p.first_answer).catch(() => {});
        if (!p.running) return;
        e.progressBar.value = p.fraction;
        e.progressText.textContent = `${first ? 'finite strain: ' : ''}${p.step} ` +
          `${Math.round(p.fraction * 100)} % (${p.elapsed_s.toFixed(1)} s)`;
      } catch { /* the next poll tries again */ }
    }, kPollMs);
    try {
      const result = await api.simulate(plan, options, firstAnswer);
      this.lastResultId = Math.max(this.lastResultId, result.result_id);
      const t1 = performance.now();
      e.progressText.textContent = 'loading the post-operative skin…';
      const row = await this.resultRow(plan, result, ownSutures, options);
      const t2 = performance.now();
      await firstLoading?.catch(() => {});
      if (first) {  // the final answer takes the first one's place
        row.n = first.n;
        this.rows[this.rows.indexOf(first)] = row;
        this.shown = this.shown.map((r) => (r === first ? null : r));
      } else {
        this.rows.push(row);
      }
      await this.showRow(row, 0);
      await this.views[0].nextFrame();  // on screen once the frame with it is drawn
      const t3 = performance.now();
      row.seconds = (t3 - t0) / 1000;
      // Where the time went, for the latency benchmark (docs/benchmarks.md).
      row.timing = { simulate_s: (t1 - t0) / 1000, view_s: (t2 - t1) / 1000, draw_s: (t3 - t2) / 1000,
        first_answer_s: first?.timing?.first_answer_s };
      this.showSummary(row);
      this.renderTable();
      document.body.dataset.simulation = 'done';
      return row;
    } catch (err) {
      // The finite-strain closure did not finish (422) or was cancelled (409): the first answer,
      // if there is one, stays. (A refused request, 400, never started.)
      if (firstAnswer && !firstLoading && (err.status === 422 || err.status === 409)) {
        const p = await api.progress().catch(() => null);
        if (ours(p?.first_answer)) showFirst(p.first_answer);
      }
      await firstLoading?.catch(() => {});
      if (first) {
        first.provisional = `the linear (small-strain) closure of the patch around the wound, clamped at ` +
          `its rim: the finite-strain one ${whyNotFinished(err)} (Material: linear closes the whole face)`;
        this.showSummary(first);
        this.renderTable();
        err.linearShown = true;
        document.body.dataset.simulation = 'linear';
      } else {
        document.body.dataset.simulation = 'failed';
      }
      throw err;
    } finally {
      clearInterval(poll);
      e.progress.hidden = true;
    }
  }

  // A row of the alternatives for a simulate result: its view and its result.json.
  async resultRow(plan, result, ownSutures, options = {}) {
    const [view, file] = await Promise.all([api.resultView(result.result_id),
      api.resultFile(result.result_id, 'result.json')]);
    return {
      n: this.rows.length + 1, plan, result, view, ownSutures, options,
      sutures: file.sutures_at_spacing?.sutures ?? [],
      skins: [null, null],
    };
  }

  /** Shows a row's result in view `which` (0: A, 1: B). */
  async showRow(row, which) {
    const viewer = this.views[which];
    if (which === 1) this.onShowB?.();
    if (!row.skins[which]) row.skins[which] = await loadResultSkin(row.view, this.modelSkin);
    const skin = row.skins[which];
    skin.setMorph(this.morph);
    this.showColouring(skin, viewer);
    viewer.setSkin(skin.mesh);
    // View B's first skin frames B alone; the views move together, so B takes A's camera.
    if (which === 1) viewer.copyCamera(this.views[0]);
    // The scar line on the closed skin (the incision's lines on the open one) and the sutures.
    const overlay = [...scarObjects(row.view.scar_lines ?? []), ...sutureObjects(row.sutures)];
    setScarMorph(overlay, this.morph);
    viewer.setOverlay(overlay);
    this.shown[which] = row;
    document.getElementById(which ? 'label-b' : 'label-a').textContent =
      `${which ? 'B' : 'A'}: #${row.n} ${planLabel(row.plan, row.ownSutures)}${row.provisional ? ' (linear)' : ''}`;
    if (which === 0) {
      this.showSummary(row);
      this.onShown?.(row);
    }
    this.el.result.hidden = false;
    this.applyTensionScale();
    this.renderTable();
  }

  // Both views' tension on the one scale (tensionScaleKpa), and its colour bar.
  applyTensionScale() {
    const top = this.tensionScaleKpa;
    this.shown.forEach((row, i) => {
      if (!row?.skins[i]) return;
      row.skins[i].setTensionScale(top);
      this.views[i].requestRender();
    });
    this.showLegend();
  }

  /** Back to the model's skin in view A (the plan changed: the result no longer matches it). */
  showPlanning() {
    if (!this.shown[0] || !this.modelSkin) return;
    this.shown[0] = null;
    this.views[0].setSkin(this.modelSkin.mesh, { pickable: true });
    document.getElementById('label-a').textContent = '';
    this.el.result.hidden = true;
    this.onShown?.(null);
    this.renderTable();
  }

  /** The files of `caps render` for a row's result (rendered once on the server), with the plan
   * and result.json: [{name, url}]. */
  async exportFiles(row) {
    row.exported ??= api.resultExport(row.result.result_id);
    try {
      return (await row.exported).files;
    } catch (e) {
      row.exported = null;
      throw e;
    }
  }

  /** A self-contained HTML page on a row: the plan, the forces, the warnings and the pictures
   * before and after (from exportFiles()). */
  async report(row) {
    const files = await this.exportFiles(row);
    const pictures = {};
    await Promise.all(files.filter((f) => f.name.endsWith('.png')).map(async (f) => {
      const blob = await (await apiFetch(f.url)).blob();
      pictures[f.name] = await new Promise((resolve) => {
        const reader = new FileReader();
        reader.onload = () => resolve(reader.result);
        reader.readAsDataURL(blob);
      });
    }));
    const r = row.result, s = r.sutures_at_spacing ?? {}, p = row.plan;
    const figure = (name, caption) => (pictures[name]
      ? `<figure><img src="${pictures[name]}" alt="${escapeHtml(caption)}"><figcaption>${escapeHtml(caption)}</figcaption></figure>` : '');
    const rows = [
      ['Closing force', `${fmt(r.closing_force_n)} N`],
      ['Largest suture force', `${fmt(s.max_force_per_suture_n)} N (${s.sutures ?? 0} sutures every ${fmt(s.spacing_mm, 1)} mm)`],
      ['Force per mm of wound', `${fmt(s.force_per_mm_n, 3)} N/mm over ${fmt(s.wound_length_mm, 1)} mm`],
      ['Skin tension (99th percentile)', `${fmt(row.view.tension_scale_max_kpa, 1)} kPa`],
      ['Largest displacement', `${fmt(r.max_displacement_mm)} mm`],
      ['Lengthening (corner to corner)', `${fmt(r.lengthening?.mm, 1)} mm (${fmt(r.lengthening?.percent, 0)} %: ${fmt(r.lengthening?.before_mm, 1)} → ${fmt(r.lengthening?.after_mm, 1)} mm between the ${escapeHtml(r.lengthening?.between ?? '')})`],
      ['Excised area', `${fmt(row.view.wound_area_mm2?.pre, 1)} mm²`],
      ['Model', `${r.elements} elements, ${escapeHtml(r.material)}`],
    ].map(([k, v]) => `<tr><th>${k}</th><td>${v}</td></tr>`).join('');
    const sutures = row.sutures.map((x, i) => `<tr><td>${i + 1}</td><td>${fmt(x.force_n, 3)} N</td></tr>`).join('');
    const warnings = [...(p.check?.warnings ?? []), ...(r.warnings ?? [])]
      .map((w) => `<li>${escapeHtml(w)}</li>`).join('');
    return `<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>caps: ${escapeHtml(planLabel(p, row.ownSutures))}</title>
<style>body{font-family:"DejaVu Sans",Arial,sans-serif;max-width:1000px;margin:2em auto;color:#222}
table{border-collapse:collapse}th,td{border:1px solid #ccd;padding:3px 8px;text-align:left}
.row{display:flex;gap:10px;flex-wrap:wrap}figure{margin:0;flex:1 1 30%}img{width:100%;border:1px solid #ddd}</style></head>
<body><h1>${escapeHtml(planLabel(p, row.ownSutures))}</h1>
<p>Planned on ${escapeHtml(p.model ?? '')}${p.check?.near?.words ? `; centre ${escapeHtml(p.check.near.words)}` : ''};
cut ${fmt(p.check?.cut_length_mm, 1)} mm on the skin; ${p.sutures?.length ?? 0} suture pairs. Simulated with caps
(${new Date().toISOString().slice(0, 10)}).</p>
<table>${rows}</table>
${warnings ? `<h2>Warnings</h2><ul>${warnings}</ul>` : ''}
<h2>Before and after</h2>
<div class="row">${figure('pre_plan.png', 'before, looking down on the plan')}${figure('post_plan.png', 'after the closure')}${figure('tension_plan.png', 'skin tension after the closure')}</div>
<div class="row">${figure('pre_oblique.png', 'before, oblique')}${figure('post_oblique.png', 'after, oblique')}${figure('tension_oblique.png', 'skin tension, oblique')}</div>
<h2>Forces per suture</h2><table><tr><th>suture</th><th>force</th></tr>${sutures}</table>
<p>Files: the plan (${escapeHtml(`${p.procedure?.name ?? 'plan'}-plan.json`)}) is read by <code>caps plan check</code> and
<code>caps simulate</code>; result.json is what <code>caps simulate</code> writes.</p>
</body></html>
`;
  }

  /** Pre (0) to post (1) on every result shown. */
  setMorph(t) {
    this.morph = t;
    this.el.morph.value = t;
    this.shown.forEach((row, i) => {
      if (!row) return;
      row.skins[i].setMorph(t);
      setScarMorph(this.views[i].overlay.children, t);
      this.views[i].requestRender();
    });
  }

  /** Animates the morph from pre to post over kPlaySeconds. */
  play() {
    const start = performance.now();
    const step = (now) => {
      const t = Math.min(1, (now - start) / (kPlaySeconds * 1000));
      this.setMorph(t);
      if (t < 1) requestAnimationFrame(step);
    };
    requestAnimationFrame(step);
  }

  /** The top of the tension scale (kPa) both views share: the larger of their 99th
   * percentiles, so one colour is one tension in A and in B. */
  get tensionScaleKpa() {
    return Math.max(0, ...this.shown.filter((r) => r).map((r) => r.view.tension_scale_max_kpa));
  }

  // The skin's colours as chosen (the tension is read when first shown).
  async showColouring(skin, viewer) {
    const name = this.colouring;
    if (name === 'tension') document.body.dataset.tension = 'loading';
    await skin.show(name);
    viewer.requestRender();
    if (name === 'tension' && this.colouring === 'tension') document.body.dataset.tension = 'shown';
  }

  setTension(on) {
    this.colouring = on ? 'tension' : 'skin';
    this.shown.forEach((row, i) => {
      if (row) this.showColouring(row.skins[i], this.views[i]);
    });
    this.applyTensionScale();
  }

  // The colour bar of the tension scale, shared by the views shown.
  showLegend() {
    const on = this.colouring === 'tension' && this.shown.some((r) => r);
    this.el.tensionLegend.hidden = !on;
    if (!on) return;
    const top = this.tensionScaleKpa, both = this.shown[0] && this.shown[1];
    this.el.tensionLegend.dataset.maxKpa = top;
    this.el.tensionLegend.innerHTML = `skin tension, kPa${both ? ' (A and B on one scale)' : ''}` +
      `<span class="scale"><span class="bar"></span><span class="ticks"><span>0</span>` +
      `<span>${fmt(top / 2, 1)}</span><span>${fmt(top, 1)}</span></span></span>`;
  }

  showSummary(row) {
    const r = row.result, s = r.sutures_at_spacing ?? {};
    const warnings = (r.warnings ?? []).map((w) => `<li>${escapeHtml(w)}</li>`).join('');
    this.el.summary.innerHTML = `
      <p>Closing force <b id="closing-force">${fmt(r.closing_force_n)} N</b>; ${s.sutures ?? 0}
        sutures every ${fmt(s.spacing_mm, 1)} mm, the largest <b>${fmt(s.max_force_per_suture_n)} N</b>
        (${fmt(s.force_per_mm_n, 3)} N per mm of wound; the dark red line on the skin is the
        scar, the dots are the sutures, blue the smallest force, red the largest).</p>
      <p>Skin tension ${fmt(row.view.tension_scale_max_kpa, 1)} kPa (99th percentile; peak
        ${fmt(row.view.max_skin_tension_kpa, 1)} kPa at a sutured corner); largest displacement
        ${fmt(r.max_displacement_mm)} mm; ${r.elements} elements, ${r.material}; ${fmt(row.seconds, 1)} s.</p>
      ${warnings ? `<ul class="warnings">${warnings}</ul>` : ''}`;
    if (row.provisional)
      this.el.summary.insertAdjacentHTML('afterbegin',
        `<p class="provisional" id="provisional">Shown: ${escapeHtml(row.provisional)}.</p>`);
    const rows = row.sutures.map((x, i) =>
      `<tr><td>${i + 1}</td><td>${fmt(x.force_n, 3)} N</td></tr>`).join('');
    this.el.sutures.innerHTML = `<tr><th>suture</th><th>force</th></tr>${rows}`;
    this.setTension(this.colouring === 'tension');
  }

  renderTable() {
    const body = this.el.table.querySelector('tbody');
    body.innerHTML = '';
    for (const row of this.rows) {
      const r = row.result;
      const tr = document.createElement('tr');
      tr.dataset.row = row.n;
      if (this.shown[0] === row) tr.classList.add('shown-a');
      if (this.shown[1] === row) tr.classList.add('shown-b');
      if (row.provisional) tr.classList.add('provisional');
      tr.innerHTML = `<td>${row.n}</td><td>${escapeHtml(planLabel(row.plan, row.ownSutures))}${
        row.provisional ? ' <i title="the finite-strain closure did not answer (yet)">linear</i>' : ''}<br>
        <small class="settings">${escapeHtml(settingsLabel(r, row.options))}</small></td>
        <td class="closing">${fmt(r.closing_force_n)}</td>
        <td class="largest">${fmt(r.sutures_at_spacing?.max_force_per_suture_n)}</td>
        <td>${fmt(row.view.tension_scale_max_kpa, 1)}</td>
        <td class="lengthening" title="between the ${escapeHtml(r.lengthening?.between ?? '')}: ${fmt(r.lengthening?.before_mm, 1)} → ${fmt(r.lengthening?.after_mm, 1)} mm">${fmt(r.lengthening?.mm, 1)}<br>${fmt(r.lengthening?.percent, 0)} %</td>
        <td>${fmt(row.view.wound_area_mm2?.pre, 1)}</td>
        <td><button data-show="0" title="Show in view A">A</button><button data-show="1" title="Show in view B">B</button></td>`;
      tr.querySelectorAll('button').forEach((b) =>
        b.addEventListener('click', () => this.showRow(row, Number(b.dataset.show))));
      body.appendChild(tr);
    }
  }
}

/** Why a finite-strain simulation gave no answer, in a few words: cancelled, its time limit
 * (with how far it had come) or the solver's message. */
export function whyNotFinished(err) {
  if (err.status === 409) return 'was cancelled';
  const limit = /time limit of ([0-9.e+-]+) s.*?it had come ([0-9.]+) % of the way/s.exec(err.message);
  if (err.status === 422 && limit)
    return `did not finish within the time limit of ${+Number(limit[1]).toPrecision(3)} s (it had come ${limit[2]} % of the way)`;
  return `did not finish (${err.message})`;
}

export function escapeHtml(s) {
  return String(s).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
}
