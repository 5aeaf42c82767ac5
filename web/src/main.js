// The planner page: loads the model's skin and the procedure library, then wires the procedure
// menu, the parameter sliders, the plan check, Simulate, the alternatives and save/load.
import { api } from './api.js';
import { lpsToScene } from './frames.js';
import { Planner } from './planner.js';
import { Results, escapeHtml } from './results.js';
import { loadModelSkin } from './skin.js';
import { Viewer } from './viewer.js';

const $ = (id) => document.getElementById(id);

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

function showCheck(plan, message) {
  const el = $('check');
  if (!plan) {
    el.className = 'check refused';
    el.innerHTML = `<b>Cannot be operated here.</b> ${escapeHtml(message ?? '')}`;
    return;
  }
  const c = plan.check ?? {};
  const warnings = c.warnings ?? [];
  const pairs = plan.suture_quadruples?.length ?? plan.sutures?.length ?? 0;
  el.className = warnings.length ? 'check warn' : 'check ok';
  el.innerHTML = `<b>Can be operated.</b> Cut ${(c.cut_length_mm ?? 0).toFixed(1)} mm on the skin,
    ${pairs} suture pairs, centre at theta ${plan.frame.theta_deg.toFixed(1)}°,
    z ${plan.frame.z_mm.toFixed(1)} mm.` +
    (warnings.length ? `<ul>${warnings.map((w) => `<li>${escapeHtml(w)}</li>`).join('')}</ul>` : '');
}

function download(name, text) {
  const a = document.createElement('a');
  a.href = URL.createObjectURL(new Blob([text], { type: 'application/json' }));
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
  $('model-name').textContent = `${model.source?.path?.split('/').pop() ?? 'model'} · ` +
    `${model.source?.modality ?? model.source?.kind ?? ''}`;
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

  const planner = new Planner(viewA, templates, {
    onState: (s) => {
      menu.value = s.procedure;
      buildParameters(planner.templates.get(s.procedure), { ...s.parameters,
        orientation: s.orientation }, onParameter);
    },
    onCheck: (plan, message) => {
      showCheck(plan, message);
      $('simulate').disabled = !plan;
      $('save').disabled = !plan;
    },
    onHistory: (u, r) => {
      $('undo').disabled = !u;
      $('redo').disabled = !r;
    },
    onPlanChanged: () => results.showPlanning(),
  });
  const onParameter = (name, value) =>
    name === 'orientation' ? planner.setOrientation(value) : planner.setParameter(name, value);
  const showTemplate = (name) => {
    const t = planner.templates.get(name);
    $('procedure-summary').textContent = t.summary;
    buildParameters(t, { ...planner.parameters, orientation: planner.state?.orientation ?? 90 },
      onParameter);
  };
  menu.addEventListener('change', () => {
    planner.setProcedure(menu.value);
    showTemplate(menu.value);
  });
  menu.value = 'z-plasty';
  planner.setProcedure('z-plasty');
  showTemplate('z-plasty');

  // Views and overlays.
  for (const b of document.querySelectorAll('[data-view]'))
    b.addEventListener('click', () => {
      const v = b.dataset.view;
      if (v === 'plan' && planner.lines) {
        const c = planner.lines.centre;
        const p = [c.lps[0] + c.normal_lps[0], c.lps[1] + c.normal_lps[1], c.lps[2] + c.normal_lps[2]];
        const target = lpsToScene(c.lps), tip = lpsToScene(p);
        viewA.lookFrom(target, tip.sub(target), 0.16);
      } else viewA.setView(v);
    });
  $('show-thickness').addEventListener('change', (e) => {
    skin.show(e.target.checked ? 'thickness' : 'skin');
    $('thickness-legend').hidden = !e.target.checked;
    $('thickness-legend').innerHTML = `0<span class="bar"></span>${thicknessMax.toFixed(1)} mm; grey: not measured`;
    viewA.requestRender();
  });

  // Simulate.
  $('simulate').addEventListener('click', async () => {
    if (!planner.plan) return;
    const options = { material: $('material').value };
    if ($('mesh-size').value) options.mesh_size = Number($('mesh-size').value);
    $('simulate').disabled = true;
    try {
      status('Simulating…');
      await results.simulate(planner.plan, options);
      status('');
    } catch (e) {
      status(`The simulation failed: ${e.message}`);
    } finally {
      $('simulate').disabled = !planner.plan;
    }
  });
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
  $('save').addEventListener('click', () => {
    if (planner.plan) download(`${planner.plan.procedure?.name ?? 'plan'}-plan.json`,
      `${JSON.stringify(planner.plan, null, 2)}\n`);
  });
  $('load').addEventListener('change', async (e) => {
    const file = e.target.files[0];
    if (!file) return;
    try {
      await planner.load(JSON.parse(await file.text()));
      showTemplate(planner.procedure);
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
    } else if (planner.onKey(e)) e.preventDefault();
  });

  // For tests and the console: the page's parts.
  window.caps = { planner, results, viewA, viewB };
  status('Click on the skin to place the procedure.');
  document.body.dataset.ready = 'true';
}


main().catch((e) => {
  status(`The planner could not start: ${e.message}`);
  document.body.dataset.ready = 'failed';
});
