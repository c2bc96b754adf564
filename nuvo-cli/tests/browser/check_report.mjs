// Opens a `nuvo report` page in headless Chromium and says what a person would see, as JSON on
// stdout: console errors and page errors, every plot and picture, and screenshots of each 3-D view
// before and after a drag and a zoom. The Rust test (`nuvo-cli/tests/report.rs`) judges it.
//
// usage: node check_report.mjs REPORT.html SCREENSHOT_DIR
// env:   CHROMIUM (default /usr/bin/chromium)
import { chromium } from 'playwright-core';
import { pathToFileURL } from 'node:url';
import path from 'node:path';

const [page_path, shots] = process.argv.slice(2);
if (!page_path || !shots) {
  console.error('usage: node check_report.mjs REPORT.html SCREENSHOT_DIR');
  process.exit(2);
}
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  // As root in a container Chromium needs --no-sandbox; the network flags keep it from calling
  // home (this machine's network refuses, and each refusal would be a console error).
  args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
         '--disable-background-networking', '--disable-component-update', '--disable-sync',
         '--no-first-run', '--disable-quic'],
});
const result = { console_errors: [], requests: [], plots: 0, curves: [], pictures: 0, broken_pictures: [],
                 runs: 0, metrics_rows: 0, viewers: [] };
try {
  const page = await browser.newPage({ viewport: { width: 1000, height: 800 } });
  page.on('console', m => { if (m.type() === 'error') result.console_errors.push(m.text()); });
  page.on('pageerror', e => result.console_errors.push('page error: ' + e.message));
  // Anything the page asks for beyond its own file and data: URIs breaks "opens with no network".
  const url = pathToFileURL(path.resolve(page_path)).href;
  page.on('request', r => {
    const u = r.url();
    if (!u.startsWith('data:') && !u.startsWith('blob:') && u !== url) result.requests.push(u);
  });
  // Timings on stderr, which the Rust test shows only when it fails (a software-rendered view
  // takes seconds to load).
  const t0 = Date.now();
  const lap = what => console.error(`${what}: ${Date.now() - t0} ms`);
  await page.goto(url, { waitUntil: 'load' });
  lap('loaded');

  result.plots = await page.locator('svg.plot').count();
  result.curves = await page.$$eval('.by-step svg.plot', s => s.map(e => e.dataset.curve));
  result.runs = await page.locator('article.run').count();
  result.metrics_rows = await page.locator('#metrics-table tbody tr').count();
  const pictures = await page.$$eval('img.picture',
    imgs => imgs.map(i => ({ alt: i.alt, ok: i.complete && i.naturalWidth > 0 })));
  result.pictures = pictures.filter(p => p.ok).length;
  result.broken_pictures = pictures.filter(p => !p.ok).map(p => p.alt);

  // Sorting: click the first metric's header twice; the rows must come back in both orders.
  result.sorted = await page.evaluate(() => {
    const th = document.querySelectorAll('#metrics-table thead tr:last-child th')[1];
    const names = () => [...document.querySelectorAll('#metrics-table tbody tr td:first-child')].map(td => td.textContent);
    th.click(); const a = names(); th.click(); const b = names();
    return { up: a, down: b };
  });

  const viewers = page.locator('model-viewer');
  const n = await viewers.count();
  for (let k = 0; k < n; k++) {
    const v = viewers.nth(k);
    await v.scrollIntoViewIfNeeded();
    // The model is loaded when `loaded` is true; then wait for a few frames to be drawn.
    await page.waitForFunction(el => el.loaded === true, await v.elementHandle(), { timeout: 60000 });
    lap(`viewer ${k} loaded`);
    await page.waitForTimeout(1500);
    const before = path.join(shots, `viewer_${k}_before.png`);
    await v.screenshot({ path: before });
    const box = await v.boundingBox();
    const cx = box.x + box.width / 2, cy = box.y + box.height / 2;
    await page.mouse.move(cx, cy);
    await page.mouse.down();
    await page.mouse.move(cx + 160, cy + 40, { steps: 12 });
    await page.mouse.up();
    await page.mouse.wheel(0, -200);
    await page.waitForTimeout(1500);
    const after = path.join(shots, `viewer_${k}_after.png`);
    await v.screenshot({ path: after });
    result.viewers.push({ before, after });
  }
} finally {
  await browser.close();
}
console.log(JSON.stringify(result));
