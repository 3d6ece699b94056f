// Opens a loopsfm report.html in headless Chromium (Debian's /usr/bin/chromium, driven by
// playwright-core) and checks that it works offline:
//   - no console error or warning, no page error, no request other than file: and data:;
//   - the 3D canvas and the plots drew: each region of a screenshot has a share of pixels
//     that differ from the region's background colour;
//   - a click on a camera (frustum) names that frame in #selected-camera and highlights it.
//
//   node report_browser_test.mjs REPORT_HTML SCREENSHOT_PNG
//
// Exit codes: 0 passed, 1 failed, 2 usage, 77 skipped (no Chromium at LOOPSFM_CHROMIUM or
// /usr/bin/chromium; scripts/setup installs Debian's chromium).
import fs from 'node:fs';
import path from 'node:path';
import { pathToFileURL } from 'node:url';

import { PNG } from 'pngjs';
import { chromium } from 'playwright-core';

const [reportPath, screenshotPath] = process.argv.slice(2);
if (!reportPath || !screenshotPath) {
  console.error('usage: node report_browser_test.mjs REPORT_HTML SCREENSHOT_PNG');
  process.exit(2);
}
const executablePath = process.env.LOOPSFM_CHROMIUM || '/usr/bin/chromium';
if (!fs.existsSync(executablePath)) {
  console.log(`SKIP: no Chromium at ${executablePath}; run scripts/setup (installs Debian's chromium)`);
  process.exit(77);
}

// WebGL without a GPU: ANGLE on SwiftShader, which Chromium only allows when asked. Without
// these, Chromium 156 picks another software GL that warns "GPU stall due to ReadPixels" on
// every screenshot.
const kChromiumArgs = ['--use-angle=swiftshader', '--enable-unsafe-swiftshader'];
// Least share of non-background pixels in each region (the drawings cover far more).
const kMinShare = { canvas3d: 0.01, topView: 0.01, perFrame: 0.01, stages: 0.01 };

const failures = [];
const fail = (message) => {
  failures.push(message);
  console.log(`FAIL: ${message}`);
};

// Share of pixels in `rect` (CSS pixels, device scale 1) that differ from the region's most
// common colour by more than `tolerance` in some channel.
function nonBackgroundShare(png, rect, tolerance = 24) {
  const x0 = Math.max(0, Math.round(rect.x));
  const y0 = Math.max(0, Math.round(rect.y));
  const x1 = Math.min(png.width, Math.round(rect.x + rect.width));
  const y1 = Math.min(png.height, Math.round(rect.y + rect.height));
  if (x1 <= x0 || y1 <= y0) return 0;
  const counts = new Map();
  for (let y = y0; y < y1; ++y) {
    for (let x = x0; x < x1; ++x) {
      const i = 4 * (y * png.width + x);
      const key = (png.data[i] << 16) | (png.data[i + 1] << 8) | png.data[i + 2];
      counts.set(key, (counts.get(key) || 0) + 1);
    }
  }
  const background = [...counts.entries()].reduce((a, b) => (b[1] > a[1] ? b : a))[0];
  const bg = [(background >> 16) & 255, (background >> 8) & 255, background & 255];
  let different = 0;
  for (const [key, count] of counts) {
    const c = [(key >> 16) & 255, (key >> 8) & 255, key & 255];
    if (c.some((v, k) => Math.abs(v - bg[k]) > tolerance)) different += count;
  }
  return different / ((x1 - x0) * (y1 - y0));
}

// Pixels in `rect` within `tolerance` of an rgb colour.
function countColour(png, rect, rgb, tolerance = 40) {
  let n = 0;
  for (let y = Math.round(rect.y); y < Math.round(rect.y + rect.height); ++y) {
    for (let x = Math.round(rect.x); x < Math.round(rect.x + rect.width); ++x) {
      const i = 4 * (y * png.width + x);
      if (rgb.every((v, k) => Math.abs(png.data[i + k] - v) <= tolerance)) ++n;
    }
  }
  return n;
}

const started = Date.now();
const browser = await chromium.launch({ executablePath, headless: true, args: kChromiumArgs });
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 }, deviceScaleFactor: 1 });
  page.on('console', (message) => {
    if (message.type() === 'error' || message.type() === 'warning') {
      fail(`console ${message.type()}: ${message.text()}`);
    }
  });
  page.on('pageerror', (error) => fail(`page error: ${error.message}`));
  // Offline: the report may load nothing but itself and data: URLs.
  await page.route('**/*', (route) => {
    const url = route.request().url();
    if (url.startsWith('file:') || url.startsWith('data:')) return route.continue();
    fail(`request outside the file: ${url}`);
    return route.abort();
  });

  await page.goto(pathToFileURL(path.resolve(reportPath)).href);
  await page.waitForFunction(() => window.loopsfmReport && window.loopsfmReport.ready, null, { timeout: 30000 });
  // One viewport for the whole page: page and viewport pixels are then the same.
  const height = await page.evaluate(() => document.documentElement.scrollHeight);
  await page.setViewportSize({ width: 1280, height: Math.min(height, 16000) });
  await page.evaluate(() => new Promise((resolve) => requestAnimationFrame(() => requestAnimationFrame(resolve))));

  const regions = await page.evaluate(() => window.loopsfmReport.regions());
  let png = PNG.sync.read(await page.screenshot());
  for (const [name, minShare] of Object.entries(kMinShare)) {
    if (!regions[name]) {
      fail(`region ${name} is missing`);
      continue;
    }
    const share = nonBackgroundShare(png, regions[name]);
    console.log(`region ${name}: ${(100 * share).toFixed(1)} % of its pixels drawn`);
    if (!(share >= minShare)) fail(`region ${name} looks empty: ${(100 * share).toFixed(2)} % drawn, want >= ${100 * minShare} %`);
  }

  // Click a camera: the middle one of those in view.
  const indices = await page.evaluate(() => (window.LOOPSFM_REPORT.frames || [])
    .filter((f) => f.registered && (f.model ?? 0) === 0).map((f) => f.index));
  const inView = [];
  for (const i of indices) {
    const p = await page.evaluate((k) => window.loopsfmReport.cameraScreenPosition(k), i);
    if (p) inView.push({ index: i, ...p });
  }
  console.log(`cameras in view: ${inView.length} of ${indices.length} registered`);
  if (inView.length === 0) {
    fail('no camera in view to click');
  } else {
    const target = inView[Math.floor(inView.length / 2)];
    const highlightBefore = countColour(png, regions.canvas3d, [255, 122, 0]);
    await page.mouse.click(target.x, target.y);
    const label = await page.textContent('#selected-camera');
    console.log(`clicked frame ${target.index} at (${target.x.toFixed(0)}, ${target.y.toFixed(0)}): "${label}"`);
    if (!label.startsWith(`frame ${target.index}:`)) fail(`#selected-camera says "${label}", want frame ${target.index}`);
    png = PNG.sync.read(await page.screenshot());
    const highlightAfter = countColour(png, regions.canvas3d, [255, 122, 0]);
    console.log(`highlight pixels: ${highlightBefore} before the click, ${highlightAfter} after`);
    if (!(highlightAfter > highlightBefore + 20)) fail('the selected camera is not highlighted in the 3D view');
  }
  fs.mkdirSync(path.dirname(path.resolve(screenshotPath)), { recursive: true });
  fs.writeFileSync(screenshotPath, PNG.sync.write(png));
  console.log(`screenshot: ${screenshotPath}`);

  // The same report with most of its data left out (no poses, points, plots or timings):
  // the sections without data are omitted, and nothing breaks.
  await page.addInitScript(() => {
    let data;
    Object.defineProperty(window, 'LOOPSFM_REPORT', {
      get: () => data,
      set: (full) => {
        data = { title: full.title, frames: full.frames.map((f) => ({ index: f.index, registered: false })) };
      },
    });
  });
  await page.reload();
  await page.waitForFunction(() => window.loopsfmReport && window.loopsfmReport.ready, null, { timeout: 30000 });
  const sparse = await page.evaluate(() => ({
    regions: window.loopsfmReport.regions(),
    sections: [...document.querySelectorAll('section')].map((s) => s.id),
  }));
  console.log(`with little data: sections ${sparse.sections.join(', ')}`);
  if (sparse.sections.join(',') !== 'summary,per-frame' || sparse.regions.canvas3d || !sparse.regions.perFrame) {
    fail(`with little data, want the sections summary and per-frame only, got ${sparse.sections.join(', ')}`);
  }
} finally {
  await browser.close();
}
console.log(`${failures.length ? 'FAILED' : 'passed'} in ${((Date.now() - started) / 1000).toFixed(1)} s`);
process.exit(failures.length ? 1 : 0);
