// The planner page: loads the model's skin and the procedure library, then wires the procedure
// menu, the parameter sliders, the plan check, Simulate, the alternatives and save/load.
import { api, apiFetch } from './api.js';
import { lpsToScene } from './frames.js';
import { lesionOutlineObjects, skinLineObjects } from './overlays.js';
import { kIncision, Planner } from './planner.js';
import { showLandmarks } from './landmarks.js';
import { Results, escapeHtml, whyNotFinished } from './results.js';
import { Suggestions } from './suggest.js';
import { pairColour, sideText } from './sutures.js';
import { loadModelSkin } from './skin.js';
import { Viewer } from './viewer.js';

const $ = (id) => document.getElementById(id);
const kPlaceHint = 'Click on the skin to place the procedure.';

function status(text) {
  $('status').textContent = text;
  $('status').hidden = !text;
}

// Slider steps by unit: whole counts and signs, half millimetres, whole degrees.
function stepOf(p) {
  if (p.unit === 'count') return 1;
  if (p.unit === 'sign') return 2;
  if (p.unit === 'mm') return 0.5;
  return 1;
}

function buildParameters(template, values, onInput) {
  const box = $('parameters');
  box.innerHTML = '';
  const rows = [...template.parameters, { name: 'orientation', unit: 'deg', min: -180, max: 180,
    meaning: 'from superior towards the patient\'s left' }];
  for (const p of rows) {
    const row = document.createElement('div');
    row.className = 'param';
    row.title = p.meaning ?? '';
    const unit = p.unit === 'count' || p.unit === 'sign' ? '' : ` ${p.unit}`;
    row.innerHTML = `<label for="param-${p.name}">${p.name.replace(/_/g, ' ')}</label>
      <input type="range" id="param-${p.name}" min="${p.min}" max="${p.max}" step="${stepOf(p)}">
      <output></output>`;
    const input = row.querySelector('input'), out = row.querySelector('output');
    const value = values[p.name] ?? p.default;  // an alternative not given shows its default
    input.value = value;
    out.textContent = `${+Number(value).toFixed(1)}${unit}`;
    input.addEventListener('input', () => {
      out.textContent = `${+Number(input.value).toFixed(1)}${unit}`;
    });
    input.addEventListener('change', () => onInput(p.name, Number(input.value)));
    box.appendChild(row);
  }
}

// ", 15 mm left and 20 mm up from the glabella" for a plan placed at a landmark ('' if not).
function atLandmark(at) {
  if (!at?.landmark) return '';
  const mm = (v, pos, neg) => `${+Math.abs(v).toFixed(1)} mm ${v < 0 ? neg : pos}`;
  return `, ${mm(at.left_mm, 'left', 'right')} and ${mm(at.up_mm, 'up', 'down')} from the ` +
    escapeHtml(at.landmark.replace('_', ' '));
}

function showCheck(plan, message, state) {
  const el = $('check');
  if (!plan && !message) {
    el.className = 'check muted';
    el.textContent = state?.procedure === kIncision
      ? `Click on the skin to draw the cut: ${state.points.length ? 'one more point' : 'at least two points'}.`
      : 'No plan yet.';
    return;
  }
  if (!plan) {
    el.className = 'check refused';
    const text = message ?? '';
    el.innerHTML = `<b>Cannot be operated here.</b> ${escapeHtml(text.charAt(0).toUpperCase() + text.slice(1))}`;
    return;
  }
  const c = plan.check ?? {};
  const warnings = c.warnings ?? [];
  const pairs = plan.suture_quadruples?.length ?? plan.sutures?.length ?? 0;
  el.className = warnings.length ? 'check warn' : 'check ok';
  // Where it is as the surgeon finds it: from the landmark it was placed from, else from the
  // nearest one the model has (the check's "near"); a model without landmarks says nothing.
  const where = plan.at?.landmark ? `, centre${atLandmark(plan.at).replace(/^,/, '')}`
    : c.near?.words ? `, centre ${escapeHtml(c.near.words)}` : '';
  el.innerHTML = `<b>Can be operated.</b> Cut ${(c.cut_length_mm ?? 0).toFixed(1)} mm on the skin,
    ${pairs} suture pair${pairs === 1 ? '' : 's'}${where}.` +
    (pairs ? '' : ' <b>No sutures yet</b>: nothing closes this cut; add pairs below.') +
    (warnings.length ? `<ul>${warnings.map((w) => `<li>${escapeHtml(w)}</li>`).join('')}</ul>` : '');
}

// The plan's suture pairs, each with its colour on the skin (where its two sides are drawn), the
// lengths of its two sides on the skin (the loop nodes only in the tooltip), and buttons to move
// (choose its two sides again) or remove it.
function showSutures(planner) {
  const plan = planner.plan;
  const table = $('suture-pairs');
  const lengths = plan?.check?.suture_lengths_mm ?? [];
  const own = planner.state?.sutures == null;
  $('sutures-origin').textContent = !plan ? '' : own
    ? (planner.isIncision ? '' : '(the procedure\'s)') : '(yours)';
  table.innerHTML = (plan?.sutures ?? []).map((pair, k) => {
    const len = lengths[k] ? ` ${lengths[k].map((v) => v.toFixed(1)).join(' / ')} mm` : '';
    return `<tr><td><span class="swatch" style="background:#${pairColour(k).getHexString()}"></span></td>
      <td title="loop edges ${sideText(pair[0])} and ${sideText(pair[1])}, as the plan file writes them">pair ${k + 1}</td><td>${len}</td>
      <td><button data-move="${k}" title="Click its two sides again">Move</button>
      <button data-remove="${k}" title="Remove this pair">✕</button></td></tr>`;
  }).join('');
  table.querySelectorAll('[data-move]').forEach((b) =>
    b.addEventListener('click', () => planner.startPick(Number(b.dataset.move))));
  table.querySelectorAll('[data-remove]').forEach((b) =>
    b.addEventListener('click', () => planner.removeSuture(Number(b.dataset.remove))));
  $('add-suture').disabled = !plan || !planner.lines?.loop;
  $('reset-sutures').disabled = !plan || own;
}

function download(name, text, type = 'application/json') {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(new Blob([text], { type }));
  a.download = name;
  document.body.appendChild(a);
  a.click();
  a.remove();
}

async function main() {
  const viewA = new Viewer($('view-a'));
  const viewB = new Viewer($('view-b'));
  // The two views move together.
  let syncing = false;
  for (const [from, to] of [[viewA, viewB], [viewB, viewA]])
    from.controls.addEventListener('change', () => {
      if (syncing || $('view-b').hidden) return;
      syncing = true;
      to.copyCamera(from);
      syncing = false;
    });

  const [model, templates, skinInfo] = await Promise.all([api.model(), api.templates(), api.skin()]);
  // A local chart (caps model chart) says where it faces: plans on it are at its --at 0,0.
  const chart = model.source?.chart ? ` · local chart at ${model.source.chart.at}` : '';
  $('model-name').textContent = `${model.source?.path?.split('/').pop() ?? 'model'} · ` +
    `${model.source?.modality ?? model.source?.kind ?? ''}${chart}`;
  // On a chart the server made (POST /api/chart), the way back to the whole head.
  $('chart-back').hidden = !model.made_here;
  $('chart-back').addEventListener('click', async () => {
    await api.chart({ head: true });
    location.reload();
  });
  const { skin, thicknessMax } = await loadModelSkin(skinInfo);
  viewA.setSkin(skin.mesh, { pickable: true });

  const results = new Results(viewA, viewB, {
    progress: $('progress'), progressBar: $('progress-bar'), progressText: $('progress-text'),
    result: $('result'), morph: $('morph'), summary: $('result-summary'), sutures: $('sutures'),
    table: $('alternatives'), tensionLegend: $('tension-legend'),
  });
  results.modelSkin = skin;
  results.onShowB = () => {
    $('compare').checked = true;
    setCompare(true);
  };

  const menu = $('procedure');
  for (const t of templates) menu.add(new Option(`${t.name} — ${t.summary}`, t.name));
  menu.add(new Option('free incision — your own cut and sutures', kIncision));

  let noticeTimer = 0;
  const notice = (text) => {
    status(text);
    clearTimeout(noticeTimer);
    noticeTimer = setTimeout(() => status(''), 4000);
  };
  // The lesion's outline drawn for Suggest (LPS mm, in the order clicked): Suggest needs it (three
  // points or more) or a lesion's centre, and no suggestion running.
  const lesionOutline = [];
  // A round lesion's centre: the placed plan's; or, where the plan laid at the click cannot be
  // operated (the page's default Z-plasty below the eye reaches the eye), the place clicked: the
  // lesion is there whatever the template, and Suggest lays designs that fit.
  const lesionCentre = () => {
    const c = planner.plan ? planner.lines?.centre : null;
    if (c) return { at: `${c.theta_deg},${c.z_mm}` };
    const s = planner.state;
    if (s?.at) return { at: s.at };
    if (s?.at_xyz) return { at_xyz: s.at_xyz };
    return null;
  };
  const suggestReady = () => (lesionCentre() !== null || lesionOutline.length >= 3) &&
    document.body.dataset.suggestion !== 'running';
  const planner = new Planner(viewA, templates, {
    onState: (s) => {
      if (!s) return;
      if ($('status').textContent === kPlaceHint) status('');  // placed: the hint has done its job
      if (s.procedure === 'loaded') {
        showTemplate(null);
        return;
      }
      menu.value = s.procedure;
      showTemplate(s.procedure, s);
    },
    onCheck: (plan, message, state) => {
      showCheck(plan, message, state);
      // Refused where the head's model cannot represent the skin: offer a local chart there.
      $('chart-offer').hidden = plan !== null || !/cannot represent/.test(message ?? '') ||
        Boolean(model.source?.chart);
      showSutures(planner);
      $('simulate').disabled = !plan;
      $('suggest').disabled = !suggestReady();
      $('save').disabled = !plan;
    },
    onNotice: notice,
    onPick: (pick) => {
      clearTimeout(noticeTimer);
      // The cut seen from straight above, close enough to click beside either side of it.
      if (pick && pick.first < 0) lookAtPlan();
      if (!pick) status('');
      else status(pick.first < 0
        ? 'Suture pair: click on the skin just beside the cut, on the first side to sew (Esc cancels).'
        : 'Now click beside the side it is sewn to.');
    },
    onHistory: (u, r) => {
      $('undo').disabled = !u;
      $('redo').disabled = !r;
    },
    onPlanChanged: () => results.showPlanning(),
  });
  showLandmarks(planner);
  $('chart-here').addEventListener('click', async () => {
    const s = planner.state;
    const request = s?.at ? { at: s.at } : { at_xyz: s?.at_xyz };
    $('chart-here').disabled = true;
    document.body.dataset.chart = 'making';
    status('Measuring the CT again on a local chart that faces the skin here...');
    try {
      await api.chart(request);
      location.reload();
    } catch (e) {
      $('chart-here').disabled = false;
      document.body.dataset.chart = 'failed';
      status(e.message);
    }
  });
  const onParameter = (name, value) =>
    name === 'orientation' ? planner.setOrientation(value) : planner.setParameter(name, value);
  // The panel for the procedure `name` (a template, the free incision, or null: a loaded plan).
  const showTemplate = (name, state = planner.state) => {
    const incision = name === kIncision;
    $('template-hint').hidden = incision || !name;
    $('incision-hint').hidden = !incision;
    if (!name) {
      $('procedure-summary').textContent = 'A loaded plan (its own cut): its sutures can be changed below.';
      $('parameters').innerHTML = '';
      return;
    }
    if (incision) {
      $('procedure-summary').textContent = 'Your own cut, drawn on the skin, and your own sutures.';
      $('parameters').innerHTML = '';
      return;
    }
    const t = planner.templates.get(name);
    $('procedure-summary').textContent = t.summary;
    const same = state?.procedure === name;
    buildParameters(t, { ...(same ? state.parameters : planner.parameters),
      orientation: same ? state.orientation : 90 }, onParameter);
  };
  menu.addEventListener('change', () => {
    planner.setProcedure(menu.value);
    showTemplate(menu.value);
  });
  menu.value = 'z-plasty';
  planner.setProcedure('z-plasty');
  showTemplate('z-plasty');

  // Views and overlays.
  function lookAtPlan() {
    if (!planner.lines) return;
    const c = planner.lines.centre;
    const p = [c.lps[0] + c.normal_lps[0], c.lps[1] + c.normal_lps[1], c.lps[2] + c.normal_lps[2]];
    const target = lpsToScene(c.lps), tip = lpsToScene(p);
    viewA.lookFrom(target, tip.sub(target), 0.16);
  }
  for (const b of document.querySelectorAll('[data-view]'))
    b.addEventListener('click', () => {
      const v = b.dataset.view;
      if (v === 'plan') lookAtPlan();
      else viewA.setView(v);
    });
  $('show-thickness').addEventListener('change', (e) => {
    skin.show(e.target.checked ? 'thickness' : 'skin');
    $('thickness-legend').hidden = !e.target.checked;
    $('thickness-legend').innerHTML = `0<span class="bar"></span>${thicknessMax.toFixed(1)} mm; grey: not measured`;
    viewA.requestRender();
  });

  // The guides on the skin before the operation: the skin lines and the lesion's outline.
  let skinLineGuides = [];
  const showGuides = () => viewA.setGuides([...skinLineGuides, ...lesionOutlineObjects(lesionOutline)]);
  // The relaxed skin tension lines, fetched once, drawn on the skin before the operation.
  let skinLines = null;
  $('show-skin-lines').addEventListener('change', async (e) => {
    if (!e.target.checked) {
      skinLineGuides = [];
      showGuides();
      document.body.dataset.skinLines = 'hidden';
      return;
    }
    try {
      skinLines ??= await api.skinLines();
    } catch (err) {
      status(`Skin lines: ${err.message}`);
      e.target.checked = false;
      return;
    }
    if (!e.target.checked) return;  // unticked while they came
    skinLineGuides = skinLineObjects(skinLines);
    showGuides();
    status(skinLines.count
      ? `Skin lines (green): Borges's relaxed skin tension lines (1984), laid on this face by its ` +
        'nasion, subnasale and midline; schematic, drawn on the skin before the operation.'
      : `No skin lines here: ${skinLines.note}.`);
    document.body.dataset.skinLines = 'shown';
  });

  // Free incisions and sutures.
  $('remove-point').addEventListener('click', () => planner.removeLastPoint());
  $('new-incision').addEventListener('click', () => planner.newIncision());
  $('add-suture').addEventListener('click', () => planner.startPick(-1));
  $('reset-sutures').addEventListener('click', () => planner.resetSutures());
  $('show-sutures').addEventListener('change', (e) => planner.setShowSutures(e.target.checked));

  // Simulate.
  $('simulate').addEventListener('click', async () => {
    if (!planner.plan) return;
    const options = { material: $('material').value, tissue: $('tissue').value };
    if ($('mesh-size').value) options.mesh_size = Number($('mesh-size').value);
    if (options.material !== 'linear') options.time_limit = Number($('time-limit').value);
    $('simulate').disabled = true;
    $('cancel-simulation').hidden = false;
    try {
      status('Simulating…');
      await results.simulate(planner.plan, options, { ownSutures: planner.state?.sutures != null });
      status('');
    } catch (e) {
      if (e.linearShown)
        status(`The finite-strain closure ${whyNotFinished(e)}; the linear (small-strain) answer of the patch is shown.` +
          (/time limit/.test(whyNotFinished(e)) ? ' Choose a longer time limit to wait for it.' : ''));
      else
        status(e.status === 409 ? 'The simulation was cancelled.' : `The simulation failed: ${e.message}`);
    } finally {
      $('simulate').disabled = !planner.plan;
      $('cancel-simulation').hidden = true;
    }
  });
  // Cancel: the server stops the running simulation within a second (DELETE /api/simulate); so
  // does leaving or reloading the page while one runs.
  $('cancel-simulation').addEventListener('click', () => api.cancelSimulation().catch(() => {}));
  window.addEventListener('pagehide', () => {
    if (document.body.dataset.simulation === 'running') api.cancelSimulation(true).catch(() => {});
  });
  // Suggest: for a lesion at the placed plan's centre (docs/planner.md, "Suggest").
  const suggestions = new Suggestions({
    progress: $('suggest-progress'), progressText: $('suggest-progress-text'), plot: $('suggest-plot'),
    table: $('suggestions'), summary: $('suggest-summary'), lines: $('suggest-lines'),
  }, (plan, name) => planner.load(plan, name));
  // The lesion drawn as its outline: while Draw is on, each click on the skin adds a point.
  const showOutline = () => {
    const n = lesionOutline.length;
    let across = 0;
    for (const p of lesionOutline)
      for (const q of lesionOutline) across = Math.max(across, Math.hypot(p[0] - q[0], p[1] - q[1], p[2] - q[2]));
    $('suggest-outline').textContent = n === 0 ? ''
      : n < 3 ? `${n} point${n > 1 ? 's' : ''}: at least 3`
        : `outline of ${n} points, ${across.toFixed(1)} mm across`;
    $('suggest-clear').hidden = n === 0;
    $('suggest-diameter').disabled = n >= 3;
    $('suggest').disabled = !suggestReady();
    document.body.dataset.lesionOutline = String(n);
    showGuides();
  };
  $('suggest-draw').addEventListener('click', () => {
    if (planner.skinClick) {
      planner.skinClick = null;
      $('suggest-draw').textContent = 'Draw the lesion';
      status('');
      return;
    }
    planner.skinClick = (lps) => {
      lesionOutline.push(lps);
      showOutline();
    };
    $('suggest-draw').textContent = 'Done drawing';
    status('Click around the lesion on the skin, in order (Backspace takes the last point back); ' +
      'Done drawing or Enter when it is closed.');
  });
  $('suggest-clear').addEventListener('click', () => {
    lesionOutline.length = 0;
    showOutline();
  });
  $('suggest').addEventListener('click', async () => {
    const centre = lesionCentre();
    const drawn = lesionOutline.length >= 3;
    if (!centre && !drawn) return;
    const options = { material: $('material').value, tissue: $('tissue').value,
      procedures: $('suggest-procedures').value, step: Number($('suggest-step').value),
      objective: $('suggest-objective').value };
    if ($('mesh-size').value) options.mesh_size = Number($('mesh-size').value);
    $('suggest').disabled = $('simulate').disabled = true;
    $('cancel-suggest').hidden = false;
    try {
      status('Suggesting: each design is closed in turn…');
      // A drawn lesion is fitted by its outline, about its own centre; else the placed plan's
      // centre and the diameter.
      const lesion = drawn
        ? { outline_xyz: lesionOutline.map((p) => p.map((v) => v.toFixed(2)).join(',')).join(';') }
        : { diameter: Number($('suggest-diameter').value) };
      const s = await suggestions.run(drawn ? {} : centre,
        { ...lesion, margin: Number($('suggest-margin').value) }, options);
      status(`Suggested in ${s.timings_s.suggest.toFixed(0)} s: open a design to simulate it and compare.`);
    } catch (e) {
      status(e.status === 409 ? 'The suggestion was cancelled.' : `No suggestion: ${e.message}`);
    } finally {
      $('suggest').disabled = !suggestReady();
      $('simulate').disabled = !planner.plan;
      $('cancel-suggest').hidden = true;
    }
  });
  $('cancel-suggest').addEventListener('click', () => api.cancelSimulation().catch(() => {}));
  $('morph').addEventListener('input', (e) => results.setMorph(Number(e.target.value)));
  $('play').addEventListener('click', () => results.play());
  $('show-tension').addEventListener('change', (e) => results.setTension(e.target.checked));

  // Two views.
  const setCompare = (on) => {
    $('view-b').hidden = !on;
    viewA.resize();
    viewB.resize();
    if (on) viewB.copyCamera(viewA);
  };
  $('compare').addEventListener('change', (e) => setCompare(e.target.checked));

  // Undo, redo, save, load, keys.
  $('undo').addEventListener('click', () => planner.undo());
  $('redo').addEventListener('click', () => planner.redo());
  const savePlan = (plan) => download(`${plan.procedure?.name ?? 'plan'}-plan.json`,
    `${JSON.stringify(plan, null, 2)}\n`);
  $('save').addEventListener('click', () => {
    if (planner.plan) savePlan(planner.plan);
  });

  // Export what view A shows.
  results.onShown = (row) => {
    $('export').hidden = !row;
    $('export-files').innerHTML = '';
    if (row) $('export-which').textContent = `(#${row.n}, view A)`;
  };
  $('export-plan').addEventListener('click', () => results.shown[0] && savePlan(results.shown[0].plan));
  $('export-result').addEventListener('click', async () => {
    const row = results.shown[0];
    if (row) download(`result-${row.n}.json`, await (await apiFetch(`${row.result.result_url}result.json`)).text());
  });
  $('export-report').addEventListener('click', async () => {
    const row = results.shown[0];
    if (!row) return;
    status('Rendering the pictures for the report…');
    try {
      download(`report-${row.n}.html`, await results.report(row), 'text/html');
      status('');
    } catch (e) {
      status(`The report could not be made: ${e.message}`);
    }
  });
  $('export-render').addEventListener('click', async () => {
    const row = results.shown[0];
    if (!row) return;
    status('Rendering the pictures and the 3D skin…');
    $('export-render').disabled = true;
    try {
      const files = await results.exportFiles(row);
      $('export-files').innerHTML = files.map((f) =>
        `<li><a href="${f.url}" download="${escapeHtml(`${row.n}-${f.name}`)}">${escapeHtml(f.name)}</a></li>`).join('');
      status('');
    } catch (e) {
      status(`The export failed: ${e.message}`);
    } finally {
      $('export-render').disabled = false;
    }
  });
  $('load').addEventListener('change', async (e) => {
    const file = e.target.files[0];
    if (!file) return;
    try {
      await planner.load(JSON.parse(await file.text()), file.name);
    } catch (err) {
      showCheck(null, `${file.name}: ${err.message}`);
    }
    e.target.value = '';
  });
  window.addEventListener('keydown', (e) => {
    if ((e.ctrlKey || e.metaKey) && e.key.toLowerCase() === 'z') {
      e.shiftKey ? planner.redo() : planner.undo();
      e.preventDefault();
    } else if ((e.ctrlKey || e.metaKey) && e.key.toLowerCase() === 'y') {
      planner.redo();
      e.preventDefault();
    } else if (planner.skinClick && !e.target.closest?.('input, select, textarea') &&
               ['Backspace', 'Delete', 'Escape', 'Enter'].includes(e.key)) {
      // Drawing the lesion: Backspace takes the last point back, Escape or Enter ends drawing.
      if (e.key === 'Backspace' || e.key === 'Delete') {
        lesionOutline.pop();
        showOutline();
      } else {
        $('suggest-draw').click();
      }
      e.preventDefault();
    } else if (planner.onKey(e)) e.preventDefault();
  });

  // For tests and the console: the page's parts.
  window.caps = { planner, results, suggestions, viewA, viewB };
  status(kPlaceHint);
  document.body.dataset.ready = 'true';
}


main().catch((e) => {
  status(`The planner could not start: ${e.message}`);
  document.body.dataset.ready = 'failed';
});
