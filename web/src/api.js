// The server's JSON API (docs/planner.md). Every refusal carries {"error": message}: the message
// the command line prints for the same input; it is thrown as an ApiError with the HTTP status.
// Every request carries the session's token, which the server put into the page it served
// (<meta name="caps-token">); the server refuses /api/ requests without it (docs/reliability.md).

const token = document.querySelector('meta[name="caps-token"]')?.content ?? '';

/** fetch() with the session's token. */
export function apiFetch(path, init = {}) {
  return fetch(path, { ...init, headers: { ...(init.headers ?? {}), 'X-Caps-Token': token } });
}

export class ApiError extends Error {
  constructor(status, message) {
    super(message);
    this.status = status;
  }
}

async function answer(response) {
  const text = await response.text();
  let body;
  try {
    body = text ? JSON.parse(text) : {};
  } catch {
    body = { error: text };
  }
  if (!response.ok) throw new ApiError(response.status, body.error ?? `HTTP ${response.status}`);
  return body;
}

/** GET a JSON route. */
export async function getJson(path) {
  return answer(await apiFetch(path));
}

/** POST `body` (an object) as JSON; the parsed JSON answer. */
export async function postJson(path, body, signal) {
  return answer(
    await apiFetch(path, {
      method: 'POST',
      headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify(body),
      signal,
    }),
  );
}

/** GET a binary file as an ArrayBuffer. */
export async function getBinary(path) {
  const response = await apiFetch(path);
  if (!response.ok) await answer(response);
  return response.arrayBuffer();
}

export const api = {
  model: () => getJson('/api/model'),
  skin: () => getJson('/api/skin'),
  /** The relaxed skin tension lines over the face (`caps plan skin-lines MODEL --json`). */
  skinLines: () => getJson('/api/skin-lines'),
  templates: () => getJson('/api/templates'),
  /** caps plan new: {procedure, at | at_xyz, orientation, parameters} -> the plan with its check. */
  planNew: (request, signal) => postJson('/api/plan/new', request, signal),
  /** caps plan check: a plan file's JSON -> the plan with its check. */
  planCheck: (plan, signal, name) =>
    postJson(`/api/plan/check${name ? `?name=${encodeURIComponent(name)}` : ''}`, plan, signal),
  /** The plan's cutting lines and points on the skin (LPS mm). */
  planLines: (plan, signal) => postJson('/api/plan/lines', plan, signal),
  /** caps simulate: the result JSON with result_id and result_url; `firstAnswer`: the server
   * closes the plan with the linear model first and puts that result on /api/progress. */
  simulate: (plan, options, firstAnswer = false) =>
    postJson('/api/simulate', firstAnswer ? { plan, options, first_answer: true } : { plan, options }),
  /** caps plan suggest for a lesion on the served model: {at | at_xyz, diameter, margin,
   * procedures, step, objective, and simulate's options} -> suggestions.json with result_id and
   * result_url (suggestions.png and each design's plan are under it). Shares the simulation's
   * slot: cancelSimulation() and a newer simulate request cancel it (409). */
  suggest: (request) => postJson('/api/suggest', request),
  /** Cancels the running simulation (its request is answered 409); {cancelled: was one running}.
   * `keepalive`: sent even while the page is being left. */
  cancelSimulation: async (keepalive = false) =>
    answer(await apiFetch('/api/simulate', { method: 'DELETE', keepalive })),
  /** The post-operative skin (.glb with the morph target) and the tension map of a result. */
  resultView: (id) => getJson(`/api/results/${id}/view`),
  resultFile: (id, file) => getJson(`/api/results/${id}/${file}`),
  progress: () => getJson('/api/progress'),
  /** caps model chart on the started model at {at} or {at_xyz}, served from then on; {head: true}
   * serves the started model again. Answers the served model's model.json. */
  chart: (request) => postJson('/api/chart', request),
  /** caps render of a result (pictures, tension map, skin.glb): {files: [{name, url}], render}. */
  resultExport: (id) => postJson(`/api/results/${id}/export`, {}),
};
