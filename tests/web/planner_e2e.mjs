// End-to-end test of the planner page: starts `caps serve` on a model, drives Debian's chromium
// (headless, software GL) through the page as a surgeon would — place a Z-plasty by clicking on
// the skin, rotate it with a key and undo, drag its handle and undo, simulate, read the forces in
// the table, change the angle and simulate again, show the two alternatives side by side, save
// the plan and load it back — and checks the saved plan with `caps plan check`. Screenshots go
// to OUT_DIR.
//
// node planner_e2e.mjs CAPS_EXE MODEL_DIR WEB_ROOT OUT_DIR    (run by run_planner_e2e.sh)
import assert from 'node:assert/strict';
import { spawn, spawnSync } from 'node:child_process';
import { mkdirSync, mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const require = createRequire(join(here, '..', '..', 'web', 'package.json'));
const { chromium } = require('playwright-core');

const [caps, model, webRoot, out] = process.argv.slice(2);
const chromiumPath = process.env.CAPS_CHROMIUM ?? '/usr/bin/chromium';
mkdirSync(out, { recursive: true });
const t0 = Date.now();
const log = (m) => console.log(`[${((Date.now() - t0) / 1000).toFixed(1)} s] ${m}`);

// Starts caps serve on a free port; resolves with its URL (from the line it prints).
function serve() {
  const server = spawn(caps, ['serve', model, '--port', '0', '--web-root', webRoot],
    { stdio: ['ignore', 'pipe', 'pipe'] });
  return new Promise((resolve, reject) => {
    let text = '';
    const timer = setTimeout(() => reject(new Error(`caps serve printed no URL:\n${text}`)), 20000);
    const read = (chunk) => {
      text += chunk;
      const m = text.match(/http:\/\/127\.0\.0\.1:\d+\//);
      if (m) {
        clearTimeout(timer);
        resolve({ server, url: m[0] });
      }
    };
    server.stdout.on('data', read);
    server.stderr.on('data', read);
    server.on('exit', (code) => reject(new Error(`caps serve exited (${code}):\n${text}`)));
  });
}

const { server, url } = await serve();
log(`caps serve at ${url}`);
const profile = mkdtempSync(join(tmpdir(), 'caps-chromium-'));
const browser = await chromium.launchPersistentContext(profile, {
  executablePath: chromiumPath,
  headless: true,
  args: ['--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader', '--disable-quic', '--no-first-run',
    '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  viewport: { width: 1400, height: 850 },
  acceptDownloads: true,
});
const errors = [];
try {
  const page = browser.pages()[0] ?? (await browser.newPage());
  page.on('pageerror', (e) => errors.push(`page error: ${e.message}`));
  page.on('console', (m) => m.type() === 'error' && errors.push(`console: ${m.text()}`));
  // Nothing is fetched from anywhere but the server.
  const foreign = [];
  page.on('request', (r) => !r.url().startsWith(url) && !r.url().startsWith('blob:') &&
    !r.url().startsWith('data:') && foreign.push(r.url()));

  await page.goto(url);
  await page.waitForSelector('body[data-ready="true"]', { timeout: 30000 });
  log('page ready, skin shown');
  await page.screenshot({ path: join(out, '1-loaded.png') });

  // Place the Z-plasty (the default procedure) by clicking on the middle of the face.
  assert.equal(await page.locator('#procedure').inputValue(), 'z-plasty');
  await page.click('[data-view="front"]');
  const canvas = page.locator('#view-a canvas');
  const box = await canvas.boundingBox();
  await canvas.click({ position: { x: box.width / 2, y: box.height * 0.42 } });
  await page.waitForSelector('body[data-check="ok"]', { timeout: 15000 });
  const check = await page.locator('#check').innerText();
  assert.match(check, /Can be operated/, check);
  log(`placed: ${check.split('\n')[0]}`);
  // Keys: rotate by 5 degrees, then undo it.
  await page.locator('#view-a canvas').focus();
  await page.keyboard.press('r');
  await page.waitForFunction(() => window.caps.planner.state.orientation === 95);
  await page.waitForSelector('body[data-check="ok"]');
  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.caps.planner.state.orientation === 90);
  await page.waitForSelector('body[data-check="ok"]');
  // Drag the handle 40 pixels up: the plan moves up the skin (one undo step).
  const before = await page.evaluate(() => window.caps.planner.plan.frame.z_mm);
  const handle = await page.evaluate(() => {
    const { viewA, planner } = window.caps;
    const p = planner.handle.position.clone().project(viewA.camera);
    const r = viewA.renderer.domElement.getBoundingClientRect();
    return { x: r.left + ((p.x + 1) / 2) * r.width, y: r.top + ((1 - p.y) / 2) * r.height };
  });
  await page.mouse.move(handle.x, handle.y);
  await page.mouse.down();
  for (let i = 1; i <= 4; ++i) await page.mouse.move(handle.x, handle.y - 10 * i);
  await page.mouse.up();
  await page.waitForFunction((z) => window.caps.planner.plan?.frame.z_mm > z + 2, before);
  await page.waitForSelector('body[data-check="ok"]');
  const after = await page.evaluate(() => window.caps.planner.plan.frame.z_mm);
  log(`dragged the handle: centre z ${before.toFixed(1)} -> ${after.toFixed(1)} mm`);
  await page.keyboard.press('Control+z');
  await page.waitForFunction((z) => Math.abs(window.caps.planner.plan?.frame.z_mm - z) < 1e-6, before);
  await page.waitForSelector('body[data-check="ok"]');
  await page.click('[data-view="plan"]');
  await page.screenshot({ path: join(out, '2-placed.png') });

  // Simulate: the result and the forces appear.
  await page.selectOption('#mesh-size', '2.5');
  await page.click('#simulate');
  await page.waitForSelector('body[data-simulation="done"]', { timeout: 45000 });
  const row1 = page.locator('#alternatives tbody tr').nth(0);
  const closing1 = Number(await row1.locator('td.closing').innerText());
  const largest1 = Number(await row1.locator('td.largest').innerText());
  assert.ok(closing1 > 0 && largest1 > 0, `forces in the table: ${closing1} N, ${largest1} N`);
  const plan1 = await page.evaluate(() => window.caps.results.rows[0].result.closing_force_n);
  assert.ok(Math.abs(plan1 - closing1) < 0.006, `table ${closing1} N, result ${plan1} N`);
  assert.match(await page.locator('#result-summary').innerText(), /Closing force/);
  const sutureRows = await page.locator('#sutures tr').count();
  assert.ok(sutureRows > 1, 'forces per suture listed');
  log(`simulated: closing force ${closing1} N, largest suture ${largest1} N, ${sutureRows - 1} sutures`);
  await page.screenshot({ path: join(out, '3-simulated.png') });
  await page.check('#show-tension');
  await page.screenshot({ path: join(out, '4-tension.png') });
  await page.uncheck('#show-tension');

  // An alternative: a 45 degree Z-plasty, simulated too; both shown side by side.
  const angle = page.locator('#param-angle');
  await angle.fill('45');
  await angle.dispatchEvent('change');
  await page.waitForFunction(() => window.caps.planner.state.parameters.angle === 45);
  await page.waitForSelector('body[data-check="ok"]');
  await page.click('#simulate');
  await page.waitForFunction(() => window.caps.results.rows.length === 2, null, { timeout: 45000 });
  await page.waitForSelector('body[data-simulation="done"]');
  const closing2 = Number(await page.locator('#alternatives tbody tr').nth(1).locator('td.closing').innerText());
  assert.ok(closing2 > 0 && closing2 !== closing1, `two alternatives: ${closing1} N and ${closing2} N`);
  await page.locator('#alternatives tbody tr').nth(0).locator('button[data-show="1"]').click();
  await page.waitForFunction(() => window.caps.results.shown[1]?.n === 1);
  assert.equal(await page.locator('#view-b').isVisible(), true);
  log(`alternatives: ${closing1} N (60 deg) and ${closing2} N (45 deg), side by side`);
  await page.screenshot({ path: join(out, '5-compare.png') });

  // Save the plan and check it with the command line.
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#save')]);
  const saved = join(out, 'planner-plan.json');
  await download.saveAs(saved);
  const cli = spawnSync(caps, ['plan', 'check', saved, '--json', '-q'], { encoding: 'utf8' });
  assert.equal(cli.status, 0, `caps plan check ${saved}: ${cli.stdout}${cli.stderr}`);
  const checked = JSON.parse(cli.stdout);
  assert.equal(checked.ok, true);
  assert.equal(checked.procedure.name, 'z-plasty');
  assert.equal(checked.procedure.parameters.angle, 45);
  assert.equal(JSON.parse(readFileSync(saved, 'utf8')).format, 'caps-plan');
  log(`saved plan accepted by caps plan check (${checked.procedure.name}, angle 45)`);
  // Load it back after changing the angle: the page takes the file's angle again.
  await angle.fill('75');
  await angle.dispatchEvent('change');
  await page.waitForFunction(() => window.caps.planner.state.parameters.angle === 75);
  await page.setInputFiles('#load', saved);
  await page.waitForFunction(() => window.caps.planner.state.parameters.angle === 45);
  assert.match(await page.locator('#check').innerText(), /Can be operated/);
  assert.equal(await page.locator('#param-angle').inputValue(), '45');

  assert.deepEqual(foreign, [], 'requests outside the server');
  assert.deepEqual(errors.filter((e) => !/WebGL|GPU|GL_/i.test(e)), [], 'errors on the page');
} finally {
  await browser.close();
  server.kill('SIGTERM');
  rmSync(profile, { recursive: true, force: true });
}
log('passed');
