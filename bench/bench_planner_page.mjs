// The planner's latency in the browser (docs/benchmarks.md, "Planner latency"): `caps serve` on a
// model, the page in Debian's chromium headless (software GL), the demo's Z-plasty (at 30,105,
// length 15, orientation 90) laid through the page, then Simulate clicked N times; for each, the
// time from the click to the post-operative skin drawn on screen, split into the simulate request,
// the result's view (its skin .glb written and result.json) and loading and drawing it; and the
// time to the first (linear) answer on screen, which a finite-strain Simulate shows first.
//   node bench/bench_planner_page.mjs build/tools/caps out/cranium build/web/dist [N] [OPTIONS_JSON] [PLACE_JSON]
// OPTIONS_JSON: the page's simulate options, e.g. '{"material": "linear", "time_limit": 0}'
// (default: the page's, a 60 s time limit among them). PLACE_JSON: the template and its place,
// e.g. '{"length": 20, "at": "30,110"}' (default: the demo's Z-plasty above).
import { spawn } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const require = createRequire(join(here, '..', 'web', 'package.json'));
const { chromium } = require('playwright-core');

const [caps, model, webRoot, runs = '5', optionsJson = '{}', placeJson = '{}'] = process.argv.slice(2);
const place = { length: 15, angle: 60, orientation: 90, at: '30,105', ...JSON.parse(placeJson) };
const server = spawn(caps, ['serve', model, '--port', '0', '--web-root', webRoot],
  { stdio: ['ignore', 'pipe', 'pipe'] });
const url = await new Promise((resolve, reject) => {
  let text = '';
  const read = (chunk) => {
    text += chunk;
    const m = text.match(/http:\/\/127\.0\.0\.1:\d+\//);
    if (m) resolve(m[0]);
  };
  server.stdout.on('data', read);
  server.stderr.on('data', read);
  server.on('exit', (code) => reject(new Error(`caps serve exited (${code}):\n${text}`)));
});
const profile = mkdtempSync(join(tmpdir(), 'caps-chromium-'));
const browser = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.CAPS_CHROMIUM ?? '/usr/bin/chromium',
  headless: true,
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader', '--no-first-run', '--disable-background-networking'],
  viewport: { width: 1400, height: 850 },
});
const median = (v) => [...v].sort((a, b) => a - b)[Math.floor(v.length / 2)];
// The server's CPU seconds so far (user + system, /proc/PID/stat fields 14 and 15, in clock ticks
// of 1/100 s): the server's work, which the other processes' load does not inflate as it does the
// wall time.
const serverCpuS = () => {
  const fields = readFileSync(`/proc/${server.pid}/stat`, 'utf8').split(') ')[1].split(' ');
  return (Number(fields[11]) + Number(fields[12])) / 100;
};
try {
  const page = browser.pages()[0] ?? (await browser.newPage());
  const t0 = Date.now();
  await page.goto(url);
  await page.waitForSelector('body[data-ready="true"]', { timeout: 120000 });
  console.log(`page open, skin shown: ${((Date.now() - t0) / 1000).toFixed(1)} s`);
  await page.evaluate((p) => window.caps.planner.change({ procedure: 'z-plasty',
    parameters: { length: p.length, angle: p.angle }, orientation: p.orientation, at: p.at,
    at_xyz: '', sutures: null }), place);
  await page.waitForSelector('body[data-check="ok"]');
  console.log(`Z-plasty ${JSON.stringify(place)}; page options ${optionsJson}`);
  const options = JSON.parse(optionsJson);
  if (options.material) await page.selectOption('#material', options.material);
  if (options.mesh_size) await page.selectOption('#mesh-size', String(options.mesh_size));
  if (options.time_limit !== undefined) {
    await page.evaluate((t) => {
      const limit = document.getElementById('time-limit');
      if (![...limit.options].some((o) => o.value === String(t))) limit.add(new Option(`${t} s`, String(t)));
      limit.value = String(t);
    }, options.time_limit);
  }
  const rows = [];
  for (let i = 0; i < Number(runs); ++i) {
    const cpu0 = serverCpuS();
    const tClick = Date.now();
    // A DOM click: Playwright's page.click() retries a click it thinks missed, which here clicked
    // Simulate a second time once the first simulation had re-enabled the button.
    await page.$eval('#simulate', (b) => b.click());
    await page.waitForFunction((n) => window.caps.results.rows.length === n &&
      ['done', 'linear', 'failed'].includes(document.body.dataset.simulation), i + 1, { timeout: 900000, polling: 500 });
    const state = await page.evaluate(() => document.body.dataset.simulation);
    const row = await page.evaluate((n) => {
      const r = window.caps.results.rows[n];
      return { seconds: r.seconds, ...r.timing, server: r.result.timings_s, view: r.view.timings_s,
        subdivisions: r.view.subdivisions, force: r.result.closing_force_n, material: r.result.material };
    }, i);
    row.server_cpu_s = serverCpuS() - cpu0;
    row.state = state;
    if (state !== 'done') {  // the finite-strain closure stopped: the linear answer stays
      row.first_answer_s ??= row.seconds;
      row.seconds = (Date.now() - tClick) / 1000;
      console.log(`#${i + 1}: first (linear) answer on screen after ${row.first_answer_s.toFixed(2)} s; ` +
        `the finite-strain closure stopped after ${row.seconds.toFixed(1)} s: ` +
        `${await page.locator('#status').innerText()}`);
      rows.push(row);
      continue;
    }
    rows.push(row);
    console.log(`#${i + 1}: ${row.seconds.toFixed(2)} s on screen (first answer ` +
      `${row.first_answer_s?.toFixed(2) ?? '-'} s; simulate ${row.simulate_s.toFixed(2)} s ` +
      `[solve ${row.server.solve.toFixed(2)} s; ${JSON.stringify(row.server.steps)}], view ${row.view_s.toFixed(2)} s [skin ` +
      `${row.view.skin.toFixed(2)} s, ${row.subdivisions} subdivisions], load and draw ` +
      `${row.draw_s.toFixed(2)} s); server CPU ${row.server_cpu_s.toFixed(2)} s; closing force ` +
      `${row.force.toFixed(2)} N (${row.material})`);
  }
  const done = rows.filter((r) => r.state === 'done'), firsts = rows.filter((r) => r.first_answer_s);
  if (firsts.length)
    console.log(`first (linear) answer on screen: median ${median(firsts.map((r) => r.first_answer_s)).toFixed(2)} s ` +
      `of ${firsts.length}; ${rows.length - done.length} of ${rows.length} stopped at the time limit`);
  if (done.length) console.log(`median of ${done.length} finished: ${median(done.map((r) => r.seconds)).toFixed(2)} s on screen ` +
    `(simulate ${median(done.map((r) => r.simulate_s)).toFixed(2)} s, view ` +
    `${median(done.map((r) => r.view_s)).toFixed(2)} s, load and draw ${median(done.map((r) => r.draw_s)).toFixed(2)} s; ` +
    `server CPU ${median(done.map((r) => r.server_cpu_s)).toFixed(2)} s)`);
} finally {
  await browser.close();
  server.kill('SIGTERM');
  rmSync(profile, { recursive: true, force: true });
}
