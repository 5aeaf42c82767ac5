// What the planner's browser tests share: `caps serve` on a model, Debian's chromium headless
// (software GL) through playwright-core, the page opened and ready, and screen positions of
// points on the skin in view A.
import { spawn } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const require = createRequire(join(here, '..', '..', 'web', 'package.json'));
const { chromium } = require('playwright-core');

/** A log line with the seconds since `t0`. */
export function logger(t0 = Date.now()) {
  return (m) => console.log(`[${((Date.now() - t0) / 1000).toFixed(1)} s] ${m}`);
}

// Starts caps serve on a free port; resolves with its URL (from the line it prints).
function serve(caps, model, webRoot) {
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

/**
 * Serves `model` and runs `body({page, url, allow})` in chromium on the opened page (not yet
 * ready); then checks that nothing was fetched from elsewhere and the page had no error but those
 * the body expects (`allow(regexp)`: e.g. the browser's log line for a refusal the test asks
 * for), and stops the browser and the server.
 */
export async function withPlanner({ caps, model, webRoot, log }, body) {
  const { server, url } = await serve(caps, model, webRoot);
  log(`caps serve at ${url}`);
  const profile = mkdtempSync(join(tmpdir(), 'caps-chromium-'));
  const browser = await chromium.launchPersistentContext(profile, {
    executablePath: process.env.CAPS_CHROMIUM ?? '/usr/bin/chromium',
    headless: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
    viewport: { width: 1400, height: 850 },
    acceptDownloads: true,
  });
  try {
    const page = browser.pages()[0] ?? (await browser.newPage());
    const errors = [];
    page.on('pageerror', (e) => errors.push(`page error: ${e.message}`));
    page.on('console', (m) => m.type() === 'error' && errors.push(`console: ${m.text()}`));
    // Nothing is fetched from anywhere but the server.
    const foreign = [];
    page.on('request', (r) => !r.url().startsWith(url) && !r.url().startsWith('blob:') &&
      !r.url().startsWith('data:') && foreign.push(r.url()));
    await page.goto(url);
    const allowed = [];
    await body({ page, url, allow: (re) => allowed.push(re) });
    if (foreign.length) throw new Error(`requests outside the server: ${foreign.join(', ')}`);
    const real = errors.filter((e) => !/WebGL|GPU|GL_/i.test(e) && !allowed.some((re) => re.test(e)));
    if (real.length) throw new Error(`errors on the page: ${real.join('; ')}`);
  } finally {
    await browser.close();
    server.kill('SIGTERM');
    rmSync(profile, { recursive: true, force: true });
  }
}

/** The screen position (page pixels) of the LPS point `lps` (mm) in view A. */
export function screenOf(page, lps) {
  return page.evaluate((p) => {
    const { viewA } = window.caps;
    const v = viewA.camera.position.clone().set(p[0] / 1000, p[2] / 1000, -p[1] / 1000).project(viewA.camera);
    const r = viewA.renderer.domElement.getBoundingClientRect();
    return { x: r.left + ((v.x + 1) / 2) * r.width, y: r.top + ((1 - v.y) / 2) * r.height };
  }, lps);
}

/** Clicks `selector` and saves the file it downloads as `path`. */
export async function downloadOf(page, selector, path) {
  const [download] = await Promise.all([page.waitForEvent('download'), page.click(selector)]);
  await download.saveAs(path);
  return path;
}

// Engineer's words a surgeon should not meet on the page (issue 38): a node number ("node 5",
// "5–0 ↔ 5–4"), the model's cylindrical coordinate "theta", or a command line ("caps model
// chart ...", "--extent"): the page's own controls stand for those.
const kEngineersWords = [
  [/\bnodes? \d/i, 'a node number'],
  [/\d+\s*[–-]\s*\d+\s*↔/, 'a suture pair as loop nodes'],
  [/\btheta\b/i, '"theta"'],
  [/\bcaps (model|plan|simulate|render|serve|mesh|solve|compare)\b/, 'a caps command'],
  [/(^|\s)--[a-z]/m, 'a command-line option'],
];

/** Fails if the text the page shows (its visible text: not tooltips or hidden panels) holds
 * engineer's words; `where` names the moment for the message. */
export async function assertSurgeonWords(page, where) {
  const text = await page.evaluate(() => document.body.innerText);
  for (const [re, what] of kEngineersWords) {
    const m = re.exec(text);
    if (m) {
      const at = Math.max(0, m.index - 120);
      throw new Error(`${where}: the page shows ${what}: "…${text.slice(at, m.index + 120)}…"`);
    }
  }
}
