// The model's anatomical landmarks (docs/landmarks.md: GET /api/landmarks, the same as
// `caps model landmarks --no-write --json`) as a small list under the procedure: each found
// landmark with its soft-tissue thickness and a button that centres the plan on it (the plan's
// centre at the landmark's theta, z; `--at glabella+15,20` in the request places relative to it).
import { getJson } from './api.js';

/** Lists the landmarks under the procedure's parameters; a click places `planner`'s template at
 * one. Absent landmarks are listed greyed with the reason. */
export async function showLandmarks(planner) {
  const anchor = document.getElementById('parameters');
  if (!anchor) return;
  const box = document.createElement('details');
  box.id = 'landmarks';
  box.innerHTML = '<summary>Landmarks</summary><table></table>';
  anchor.after(box);
  let answer;
  try {
    answer = await getJson('/api/landmarks');
  } catch (e) {
    box.querySelector('table').textContent = `No landmarks: ${e.message}`;
    return;
  }
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
    row.insertCell().textContent = `${l.thickness_mm.toFixed(1)} mm`;
    const button = document.createElement('button');
    button.textContent = 'Place here';
    button.dataset.landmark = name;
    button.addEventListener('click', () => planner.change({
      procedure: planner.procedure, parameters: { ...planner.parameters },
      orientation: planner.state?.orientation ?? 90, at: `${l.theta_deg},${l.z_mm}`, at_xyz: '',
      sutures: null }));
    row.insertCell().append(button);
  }
}
