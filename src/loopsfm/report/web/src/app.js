// The loopsfm HTML report: renders window.LOOPSFM_REPORT (written by loopsfm beside this
// script, schema in ../../html_report.h) into the page. Every field is optional; a section
// without data is left out.
import { perFrameChart, registrationChart, stagesChart, topViewChart } from './charts.js';
import { el, fmt, fmtSeconds, isNumber, keyValueTable, section } from './dom.js';
import { scene3d } from './scene3d.js';
import { classifyFrames, timelineCaption, timelineChart } from './timeline.js';

function header(data) {
  const s = data.summary || {};
  const meta = [
    data.input ? `input ${data.input}` : null,
    data.output ? `output ${data.output}` : null,
    data.created ? `created ${data.created}` : null,
  ].filter(Boolean).join(' · ');
  const summary = keyValueTable([
    ['frames', fmt(s.frames)],
    ['registered', isNumber(s.registered) && isNumber(s.frames) && s.frames > 0
      ? `${fmt(s.registered)} (${fmt((100 * s.registered) / s.frames, 1)} %)` : fmt(s.registered)],
    ['models', fmt(s.models)],
    ['mapper', s.mapper || null],
    ['3D points', fmt(s.points)],
    ['mean track length', fmt(s.mean_track_length, 2)],
    ['reprojection error', isNumber(s.reprojection_error_px) ? `${fmt(s.reprojection_error_px, 3)} px` : null],
    ['total time', fmtSeconds(s.total_seconds)],
    ['peak memory', isNumber(s.peak_memory_mib) ? `${fmt(s.peak_memory_mib, 0)} MiB` : null],
  ]);
  const card = el('section', { id: 'summary', class: 'card' }, el('h1', {}, data.title || 'loopsfm report'),
    meta ? el('p', { class: 'note' }, meta) : null);
  const row = el('div', { class: 'summary-row' }, summary);
  card.append(row);
  for (const warning of Array.isArray(s.warnings) ? s.warnings : []) {
    card.append(el('p', { class: 'warning' }, `warning: ${warning}`));
  }
  const stages = (data.stages || []).filter((st) => isNumber(st.seconds));
  const canvas = stages.length ? stagesChart(row, stages) : null;
  return { card, stagesCanvas: canvas };
}

function evaluation(e) {
  const pct = (x) => (isNumber(x) ? `${fmt(100 * x, 3)} % of the path` : null);
  const table = keyValueTable([
    ['ATE', isNumber(e.ate_rmse) ? `${fmt(e.ate_rmse, 4)} (RMSE)` : null],
    ['ATE / path length', pct(e.ate_fraction_of_path)],
    ['rotation error (mean)', isNumber(e.rotation_error_mean_deg) ? `${fmt(e.rotation_error_mean_deg, 3)}°` : null],
    ['loop gap (max)', isNumber(e.loop_gap_max) ? fmt(e.loop_gap_max, 4) : null],
    ['loop gap (mean)', isNumber(e.loop_gap_mean) ? fmt(e.loop_gap_mean, 4) : null],
  ]);
  if (!table) return null;
  const card = section('evaluation', 'Against the ground truth', 'after a similarity alignment of the camera centres');
  card.append(table);
  return card;
}

function matrices(list) {
  const shown = list.filter((m) => typeof m.png_base64 === 'string' && m.png_base64.length > 0);
  if (!shown.length) return null;
  const card = section('matrices', 'Similarity and matches', 'frame against frame, in capture order');
  card.append(el('div', { class: 'matrices' }, shown.map((m) => el('figure', {},
    el('img', { src: `data:image/png;base64,${m.png_base64}`, alt: m.title || 'matrix' }),
    el('figcaption', {}, m.title || '')))));
  return card;
}

function loops(list) {
  if (!list.length) return null;
  const card = section('loops', `Loops closed (${list.length})`);
  const head = ['recent frame', 'old frame', 'inliers', 'correction: translation', 'rotation', 'scale', 'time'];
  const rows = list.map((l) => el('tr', {},
    el('td', {}, l.recent_frame ?? '–'), el('td', {}, l.old_frame ?? '–'),
    el('td', {}, isNumber(l.num_correspondences) ? `${fmt(l.num_inliers)} / ${fmt(l.num_correspondences)}` : fmt(l.num_inliers)),
    el('td', {}, fmt(l.correction_translation, 3)),
    el('td', {}, isNumber(l.correction_rotation_deg) ? `${fmt(l.correction_rotation_deg, 2)}°` : '–'),
    el('td', {}, fmt(l.correction_scale, 4)), el('td', {}, fmtSeconds(l.seconds))));
  card.append(el('table', { class: 'grid' }, el('thead', {}, el('tr', {}, head.map((h) => el('th', {}, h)))),
    el('tbody', {}, rows)));
  return card;
}

// Page rectangle (CSS pixels) of an element, null when absent.
function pageRect(node) {
  if (!node) return null;
  const r = node.getBoundingClientRect();
  return { x: r.left + window.scrollX, y: r.top + window.scrollY, width: r.width, height: r.height };
}

function main() {
  const data = window.LOOPSFM_REPORT || {};
  const root = document.getElementById('report') || document.body;
  document.title = data.title || 'loopsfm report';
  // Hooks for the browser test: ready once everything drew.
  const hooks = { ready: false, cameraScreenPosition: () => null, regions: () => ({}) };
  window.loopsfmReport = hooks;

  const { card, stagesCanvas } = header(data);
  root.append(card);
  if (data.evaluation) root.append(evaluation(data.evaluation) || '');

  let view = null;
  const frames = Array.isArray(data.frames) ? data.frames : [];
  if (frames.some((f) => f.registered) || (data.points?.xyz?.length ?? 0) >= 3) {
    const models = new Set(frames.filter((f) => f.registered).map((f) => f.model ?? 0));
    const card3d = section('view3d', '3D view',
      `points and cameras${models.size > 1 ? ' of model 0' : ''}; drag to orbit, wheel to zoom, right-drag to pan, click a camera to select it`);
    root.append(card3d);
    try {
      view = scene3d(card3d, data);
    } catch (error) {
      // No WebGL (e.g. a browser with it turned off): the rest of the report still shows.
      card3d.append(el('p', { class: 'note' }, `The 3D view needs WebGL: ${error.message}`));
      console.error('loopsfm report: 3D view failed:', error);
    }
  }

  let topCanvas = null;
  const paths = (data.top_view?.paths || []).filter((p) => Array.isArray(p.xy) && p.xy.length);
  if (paths.length) {
    const card2 = section('top-view', 'Camera path from above',
      'camera centres seen from above, one scale on both axes');
    root.append(card2);
    topCanvas = topViewChart(card2, { ...data.top_view, paths });
  }

  let frameCanvas = null;
  if (frames.length) {
    const card3 = section('per-frame', 'Along the video', 'points observed per frame; red crosses mark frames left unregistered');
    root.append(card3);
    frameCanvas = perFrameChart(card3, frames);
  }

  let timelineCanvas = null;
  if (isNumber(data.timeline?.frames_read) && data.timeline.frames_read > 0) {
    const sourceFrames = classifyFrames(data.timeline);
    const card = section('timeline', 'Keyframes along the video', timelineCaption(sourceFrames));
    root.append(card);
    timelineCanvas = timelineChart(card, sourceFrames);
  }

  if (frames.some((f) => isNumber(f.registration_inlier_ratio))) {
    const card = section('registration', 'Alternate poses',
      'inlier ratio of each registration, and of a second RANSAC over the correspondences it rejected; triangles mark a second plausible pose');
    root.append(card);
    registrationChart(card, frames);
  }

  for (const part of [matrices(data.matrices || []), loops(data.loops || [])]) if (part) root.append(part);

  hooks.cameraScreenPosition = (index) => (view ? view.cameraScreenPosition(index) : null);
  hooks.regions = () => ({
    canvas3d: pageRect(view?.canvas),
    topView: pageRect(topCanvas),
    perFrame: pageRect(frameCanvas),
    timeline: pageRect(timelineCanvas),
    stages: pageRect(stagesCanvas),
  });
  hooks.ready = true;
}

if (document.readyState === 'loading') {
  document.addEventListener('DOMContentLoaded', main);
} else {
  main();
}
