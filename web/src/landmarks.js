// The model's anatomical landmarks (docs/landmarks.md: GET /api/landmarks, the same as
// `caps model landmarks --no-write --json`) as a small list under the procedure: each found
// landmark with its soft-tissue thickness and a button that places the plan at it, offset by the
// millimetres to the patient's left and up along the skin given above the list (the command
// line's `--at glabella+15,20`; the saved plan records the landmark and the offsets as the command
// line's plan file does).
import { getJson } from './api.js';

/** The `at` text of a landmark placement: "glabella+15,20", "nasion-10,-5" (mm left, mm up). */
export function landmarkAt(name, leftMm, upMm) {
  return `${name}${leftMm < 0 ? '' : '+'}${leftMm},${upMm}`;
}

/** {name, leftMm, upMm} of a landmark placement's `at` text, or null for THETA,Z. */
export function parseLandmarkAt(at) {
  const m = /^([a-z_]+)(?:([+-][0-9.]+),(-?[0-9.]+))?$/i.exec(at ?? '');
  return m ? { name: m[1], leftMm: Number(m[2] ?? 0), upMm: Number(m[3] ?? 0) } : null;
}

/** Lists the landmarks under the procedure's parameters; a click places `planner`'s template at
 * one, offset by the two fields above the list. Absent landmarks are listed greyed with the
 * reason. */
export async function showLandmarks(planner) {
  const anchor = document.getElementById('parameters');
  if (!anchor) return;
  const box = document.createElement('details');
  box.id = 'landmarks';
  box.innerHTML = `<summary>Landmarks</summary>
    <p class="offset">Place <input type="number" id="landmark-left" value="0" step="1"> mm to the
      patient's left and <input type="number" id="landmark-up" value="0" step="1"> mm up along
      the skin from:</p><table></table>`;
  anchor.after(box);
  let answer;
  try {
    answer = await getJson('/api/landmarks');
  } catch (e) {
    box.querySelector('table').textContent = `No landmarks: ${e.message}`;
    return;
  }
  const offset = (id) => {
    const v = Number(document.getElementById(id).value);
    return Number.isFinite(v) ? v : 0;
  };
  const table = box.querySelector('table');
  for (const [name, l] of Object.entries(answer.items ?? {})) {
    const row = table.insertRow();
    row.title = l.note ?? '';
    row.insertCell().textContent = name.replace('_', ' ');
    if (!l.found) {
      row.className = 'muted';
      row.insertCell().textContent = 'absent';
      continue;
    }
    const depth = row.insertCell();
    depth.textContent = `${l.thickness_mm.toFixed(1)} mm`;
    if (l.doubt) {  // a depth that cannot be this landmark's (docs/landmarks.md, "doubt")
      depth.textContent += ' (implausible)';
      depth.className = 'doubt';
      depth.title = row.title = l.doubt;
    }
    const button = document.createElement('button');
    button.textContent = 'Place here';
    button.dataset.landmark = name;
    button.addEventListener('click', () => planner.change({
      procedure: planner.procedure, parameters: { ...planner.parameters },
      orientation: planner.state?.orientation ?? 90,
      at: landmarkAt(name, offset('landmark-left'), offset('landmark-up')), at_xyz: '',
      sutures: null }));
    row.insertCell().append(button);
  }
}
