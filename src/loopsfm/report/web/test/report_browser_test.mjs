// Opens a loopsfm report.html in headless Chromium (Debian's /usr/bin/chromium, driven by
// playwright-core) and checks that it works offline:
//   - no console error or warning, no page error, no request other than file: and data:;
//   - the 3D canvas and the plots drew: each region of a screenshot has a share of pixels
//     that differ from the region's background colour;
//   - a click on a camera (frustum) names that frame in #selected-camera and highlights it;
//   - the keyframes along the video: the run's, and those of a made-up 20,000-frame video
//     with every kind of frame, whose caption counts are known (screenshot beside the first,
//     its name ending _timeline.png).
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
const kMinShare = { canvas3d: 0.01, topView: 0.01, perFrame: 0.01, timeline: 0.01, stages: 0.01 };

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

// The timeline of a made-up video of 20,000 frames: a keyframe every 20 frames (every 20th
// of those for overlap, two after tracking was lost), one fill-in, three of an old database
// (no reason), 21 frames blurred around the first tracking loss and 950 localised between
// frames 10,000 and 11,000.
function madeUpTimeline() {
  const kept = [[0, 'first'], [30, ''], [50, ''], [70, ''], [7010, 'fill-in'], [19999, 'last']];
  for (let i = 20; i <= 19980; i += 20) {
    kept.push([i, i === 5020 || i === 12020 ? 'tracking-lost' : i % 400 === 200 ? 'overlap' : 'parallax']);
  }
  kept.sort((a, b) => a[0] - b[0]);
  const blurred = Array.from({ length: 21 }, (_, k) => 5000 + k);
  const localized = Array.from({ length: 999 }, (_, k) => 10001 + k).filter((i) => i % 20 !== 0);
  return { frames_read: 20000, kept, blurred, localized };
}
const kMadeUpCaption = '1,005 of 20,000 frames kept (947 parallax, 50 overlap, 2 tracking lost, 1 fill-in, '
  + '2 first / last, 3 reason not recorded), 21 blurred, 950 localised';

// A page that fails the test on a console error or warning, a page error or a request other
// than file: and data: (the report must open offline).
async function reportPage(browser) {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 }, deviceScaleFactor: 1 });
  page.on('console', (message) => {
    if (message.type() === 'error' || message.type() === 'warning') {
      fail(`console ${message.type()}: ${message.text()}`);
    }
  });
  page.on('pageerror', (error) => fail(`page error: ${error.message}`));
  await page.route('**/*', (route) => {
    const url = route.request().url();
    if (url.startsWith('file:') || url.startsWith('data:')) return route.continue();
    fail(`request outside the file: ${url}`);
    return route.abort();
  });
  return page;
}

// Title and caption of the keyframes section, null when it is left out.
const timelineSection = (page) => page.evaluate(() => {
  const card = document.getElementById('timeline');
  return card && { title: card.querySelector('h2').textContent, caption: card.querySelector('.note').textContent };
});

const started = Date.now();
const browser = await chromium.launch({ executablePath, headless: true, args: kChromiumArgs });
try {
  const page = await reportPage(browser);
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

  // The run's keyframes: the caption counts what the data holds.
  const timeline = await page.evaluate(() => window.LOOPSFM_REPORT.timeline);
  const shownTimeline = await timelineSection(page);
  console.log(`keyframes along the video: "${shownTimeline?.caption}"`);
  if (!timeline || !shownTimeline) {
    fail('no keyframes along the video (data.timeline or section #timeline missing)');
  } else {
    const want = `${timeline.kept.length.toLocaleString('en-US')} of ${timeline.frames_read.toLocaleString('en-US')} frames kept`;
    if (!shownTimeline.caption.startsWith(want)) fail(`keyframes caption "${shownTimeline.caption}", want "${want} ..."`);
  }

  // The run mapped well: its summary carries no warning.
  const runWarnings = await page.$$eval('#summary .warning', (ws) => ws.map((w) => w.textContent));
  if (runWarnings.length) fail(`warnings in a good run's summary: ${JSON.stringify(runWarnings)}`);

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
        data = {
          title: full.title,
          summary: { warnings: ['1 component likely bent (a made-up warning)'] },
          frames: full.frames.map((f) => ({ index: f.index, registered: false })),
        };
      },
    });
  });
  await page.reload();
  await page.waitForFunction(() => window.loopsfmReport && window.loopsfmReport.ready, null, { timeout: 30000 });
  const sparse = await page.evaluate(() => ({
    regions: window.loopsfmReport.regions(),
    sections: [...document.querySelectorAll('section')].map((s) => s.id),
    warnings: [...document.querySelectorAll('#summary .warning')].map((w) => w.textContent),
  }));
  console.log(`with little data: sections ${sparse.sections.join(', ')}; warnings ${JSON.stringify(sparse.warnings)}`);
  if (sparse.warnings.length !== 1 || !sparse.warnings[0].includes('likely bent (a made-up warning)')) {
    fail(`the summary's warning is not shown: ${JSON.stringify(sparse.warnings)}`);
  }
  if (sparse.sections.join(',') !== 'summary,per-frame' || sparse.regions.canvas3d || !sparse.regions.perFrame) {
    fail(`with little data, want the sections summary and per-frame only, got ${sparse.sections.join(', ')}`);
  }

  // The same report with the timeline of a long video in place of the run's: it draws, with
  // its counts, in a blink.
  const longVideo = await reportPage(browser);
  await longVideo.addInitScript((timeline) => {
    let data;
    Object.defineProperty(window, 'LOOPSFM_REPORT', {
      get: () => data,
      set: (full) => {
        data = { title: full.title, timeline };
      },
    });
  }, madeUpTimeline());
  const loading = Date.now();
  await longVideo.goto(pathToFileURL(path.resolve(reportPath)).href);
  await longVideo.waitForFunction(() => window.loopsfmReport && window.loopsfmReport.ready, null, { timeout: 30000 });
  const loadSeconds = (Date.now() - loading) / 1000;
  const long = await timelineSection(longVideo);
  console.log(`20,000 frames: "${long?.caption}", ready in ${loadSeconds.toFixed(2)} s`);
  if (long?.title !== 'Keyframes along the video') fail(`with 20,000 frames, section #timeline is "${long?.title}"`);
  if (long?.caption !== kMadeUpCaption) fail(`with 20,000 frames, caption "${long?.caption}", want "${kMadeUpCaption}"`);
  // Generous: the strip itself takes well under a second; a slow machine loads the page slowly.
  if (!(loadSeconds < 10)) fail(`with 20,000 frames, the report took ${loadSeconds.toFixed(1)} s to draw`);
  const longRegion = await longVideo.evaluate(() => window.loopsfmReport.regions().timeline);
  const longPng = await longVideo.screenshot();
  const share = longRegion ? nonBackgroundShare(PNG.sync.read(longPng), longRegion) : 0;
  console.log(`region timeline (20,000 frames): ${(100 * share).toFixed(1)} % of its pixels drawn`);
  if (!(share >= kMinShare.timeline)) fail('with 20,000 frames, the keyframes chart looks empty');
  const longScreenshot = screenshotPath.replace(/(\.png)?$/, '_timeline.png');
  fs.writeFileSync(longScreenshot, longPng);
  console.log(`screenshot: ${longScreenshot}`);
} finally {
  await browser.close();
}
console.log(`${failures.length ? 'FAILED' : 'passed'} in ${((Date.now() - started) / 1000).toFixed(1)} s`);
process.exit(failures.length ? 1 : 0);
