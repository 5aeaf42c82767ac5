// Suggest (POST /api/suggest, `caps plan suggest`): for a lesion at the placed plan's centre,
// the closures that fit it around the lesion and its margin at every orientation, each closed in
// the whole face and ranked; the polar plot and a table of the designs, each of which opens in
// the planner as its plan (then Simulate adds it to the alternatives). docs/planner.md.
import { api, apiFetch } from './api.js';
import { escapeHtml } from './results.js';

const kPollMs = 500;

const fmt = (v, digits) => (typeof v === 'number' ? v.toFixed(digits) : '–');

/** The design's figures: the full closure's where it was closed again, else the sweep's. */
function figures(d) {
  return d.ranked_by === 'full' && d.full ? d.full : d.sweep ?? {};
}

export class Suggestions {
  /**
   * @param e   the page's elements: {progress, progressText, plot, table, summary, lines}
   * @param open  async (planJson, name) => opens a design's plan in the planner
   */
  constructor(e, open) {
    this.e = e;
    this.open = open;
    this.last = null;
  }

  /** Runs a suggestion for a lesion centred at `centre` ({at: "THETA,Z" or a landmark's
   * placement, or at_xyz: "X,Y,Z" LPS on the served model; {} for a drawn outline); shows it. */
  async run(centre, lesion, options) {
    const e = this.e;
    e.progress.hidden = false;
    e.progressText.textContent = 'starting…';
    document.body.dataset.suggestion = 'running';
    const poll = setInterval(async () => {
      try {
        const p = await api.progress();
        if (p.running)
          e.progressText.textContent = `${p.step} ${Math.round(p.fraction * 100)} % (${p.elapsed_s.toFixed(1)} s)`;
      } catch { /* the next poll tries again */ }
    }, kPollMs);
    try {
      const s = await api.suggest({ ...centre, ...lesion, ...options });
      this.last = s;
      this.show(s);
      document.body.dataset.suggestion = 'shown';
      return s;
    } catch (err) {
      document.body.dataset.suggestion = 'failed';
      throw err;
    } finally {
      clearInterval(poll);
      e.progress.hidden = true;
    }
  }

  show(s) {
    const e = this.e;
    e.plot.src = `${s.result_url}suggestions.png`;
    e.plot.parentElement.href = e.plot.src;
    e.plot.hidden = false;
    const ranked = s.designs.filter((d) => d.rank > 0);
    const refused = s.designs.filter((d) => !(d.rank > 0));
    const objective = s.objective?.meaning ?? 'the objective';
    const full = ranked.filter((d) => d.ranked_by === 'full').length;
    e.summary.textContent = ranked.length
      ? `Ranked by ${objective}, least first. ★: within 5 % of the best, closer than the model can tell apart. ` +
        (full ? `The first ${full} were closed again with the full mesh and ${s.material}; the others carry ` +
          `the sweep's coarser figures (${s.sweep?.material ?? ''}, ${s.sweep?.mesh_size_mm ?? ''} mm).`
          : `None was closed again with the full mesh within its time limit: the figures are the sweep's ` +
          `(${s.sweep?.material ?? ''}, ${s.sweep?.mesh_size_mm ?? ''} mm mesh).`) +
        (refused.length ? ` ${refused.length} design(s) could not be laid or closed here: see below the table.` : '')
      : 'No design could be laid or closed here: see why below the table.';
    // Borges's relaxed skin tension lines at the lesion, and how the least force lies to them.
    e.lines.textContent = s.skin_lines?.found ? `${s.skin_lines.sentence}.`
      : `Relaxed skin tension lines: not known here (${s.skin_lines?.note ?? 'no map'}).`;
    // A flap tried to both sides says which (suggestions.json's `side`: "lobes left", ...).
    const label = (d) => `${escapeHtml(d.procedure)} ${Math.round(d.orientation_deg)}°` +
      (d.side ? ` (${escapeHtml(d.side)})` : '');
    const rows = ranked.map((d) => {
      const f = figures(d);
      const feature = f.feature_words ? `${fmt(f.max_feature_mm, 2)} (${escapeHtml(f.feature_words)})` : '–';
      return `<tr data-design="${escapeHtml(d.name)}"><td>${d.rank}${d.near_best ? ' ★' : ''}</td>` +
        `<td>${label(d)}</td>` +
        `<td>${fmt(f.max_force_per_suture_n, 2)}</td><td>${feature}</td>` +
        `<td>${fmt(d.angle_to_skin_lines_deg, 0)}</td>` +
        `<td>${fmt(d.scar_length_mm, 1)}</td><td>${fmt(d.healthy_excised_mm2, 0)}</td>` +
        `<td>${d.ranked_by === 'full' ? 'full' : 'sweep'}</td>` +
        `<td><button data-open="${escapeHtml(d.name)}" title="Open this design in the planner; Simulate adds it to the alternatives">Open</button></td></tr>`;
    });
    if (refused.length)
      rows.push(`<tr><td colspan="9"><details><summary class="muted">${refused.length} design(s) not ` +
        `possible here</summary><ul>${refused.map((d) => `<li><b>${label(d)}</b>: ` +
        `${escapeHtml(d.refused ?? '')}</li>`).join('')}</ul>` +
        `</details></td></tr>`);
    e.table.querySelector('tbody').innerHTML = rows.join('');
    e.table.hidden = false;
    for (const b of e.table.querySelectorAll('[data-open]'))
      b.addEventListener('click', () => this.openDesign(b.dataset.open).catch((err) => {
        e.summary.textContent = `The design could not be opened: ${err.message}`;
      }));
  }

  /** Opens the design `name` of the last suggestion in the planner. */
  async openDesign(name) {
    const d = this.last?.designs.find((x) => x.name === name);
    if (!d?.plan) return;
    const response = await apiFetch(`${this.last.result_url}${d.plan}`);
    if (!response.ok) throw new Error(`the design's plan could not be read (HTTP ${response.status})`);
    await this.open(await response.json(), `${name}.json`);
  }
}
