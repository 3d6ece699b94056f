// The report's plots, drawn with Chart.js: time per stage, the top view of the camera paths
// (one scale on both axes) and the per-frame chart along the video.
import {
  BarController,
  BarElement,
  CategoryScale,
  Chart,
  Legend,
  LineController,
  LineElement,
  LinearScale,
  PointElement,
  ScatterController,
  Title,
  Tooltip,
} from 'chart.js';

import { el, isNumber, kGroundTruthColour, kPalette } from './dom.js';

Chart.register(BarController, BarElement, CategoryScale, LineController, LineElement, LinearScale,
  PointElement, ScatterController, Title, Tooltip, Legend);
// Drawn once, no animation: what a screenshot shows is the final plot.
Chart.defaults.animation = false;
Chart.defaults.font.family = 'system-ui, sans-serif';
Chart.defaults.maintainAspectRatio = false;

// A canvas in a box of fixed height; Chart.js fills the box.
export function chartBox(parent, className) {
  const canvas = el('canvas');
  parent.append(el('div', { class: `chart ${className}` }, canvas));
  return canvas;
}

// Horizontal bars: seconds per stage.
export function stagesChart(parent, stages) {
  const canvas = chartBox(parent, 'chart-stages');
  canvas.parentElement.style.height = `${Math.max(120, 34 * stages.length + 60)}px`;
  new Chart(canvas, {
    type: 'bar',
    data: {
      labels: stages.map((s) => s.name),
      datasets: [{ label: 'seconds', data: stages.map((s) => s.seconds), backgroundColor: kPalette[0] }],
    },
    options: {
      indexAxis: 'y',
      plugins: { legend: { display: false }, title: { display: true, text: 'time per stage (s)' } },
      scales: { x: { beginAtZero: true, title: { display: true, text: 'seconds' } } },
    },
  });
  return canvas;
}

// Bounds of the paths, widened on one axis so that one unit is as long on both axes of a
// chart area of the given size in pixels.
function equalScaleBounds(paths, width, height) {
  let [x0, x1, y0, y1] = [Infinity, -Infinity, Infinity, -Infinity];
  for (const p of paths) {
    for (const [x, y] of p.xy) {
      x0 = Math.min(x0, x); x1 = Math.max(x1, x);
      y0 = Math.min(y0, y); y1 = Math.max(y1, y);
    }
  }
  const pad = 0.05 * Math.max(x1 - x0, y1 - y0, 1e-9);
  [x0, x1, y0, y1] = [x0 - pad, x1 + pad, y0 - pad, y1 + pad];
  const unitsPerPixel = Math.max((x1 - x0) / width, (y1 - y0) / height);
  const cx = (x0 + x1) / 2;
  const cy = (y0 + y1) / 2;
  return {
    x: { min: cx - (unitsPerPixel * width) / 2, max: cx + (unitsPerPixel * width) / 2 },
    y: { min: cy - (unitsPerPixel * height) / 2, max: cy + (unitsPerPixel * height) / 2 },
  };
}

// Lines of the given 2D paths, one colour each (grey for the ground truth), one scale, and the
// loop links (topView.links) as thin lines under them.
export function topViewChart(parent, topView) {
  const paths = topView.paths.filter((p) => Array.isArray(p.xy) && p.xy.length > 0);
  const canvas = chartBox(parent, 'chart-top-view');
  let colour = 0;
  const datasets = paths.map((p, k) => {
    // The ground truth wide and beneath the estimates, which are drawn over it in order.
    const truth = /ground truth/i.test(p.label || '');
    const c = truth ? kGroundTruthColour : kPalette[colour++ % kPalette.length];
    return {
      label: p.label || 'path',
      data: p.xy.map(([x, y]) => ({ x, y })),
      order: truth ? paths.length : k,
      showLine: true,
      borderColor: c,
      backgroundColor: c,
      borderWidth: truth ? 4 : 1.5,
      pointRadius: 0,
      pointHitRadius: 4,
    };
  });
  // Loop links: thin lines between the two frames each loop correction tied together, under
  // the paths; a point without coordinates ends one segment before the next.
  const kLinkColours = { split: 'rgb(230, 140, 0)', posegraph: 'rgb(150, 0, 200)' };
  for (const group of topView.links || []) {
    const data = group.segments.flatMap(([x1, y1, x2, y2]) => [{ x: x1, y: y1 }, { x: x2, y: y2 }, { x: null, y: null }]);
    const c = kLinkColours[group.method] || 'rgb(120, 120, 120)';
    datasets.push({
      label: group.label,
      data,
      order: paths.length + 1,
      showLine: true,
      spanGaps: false,
      borderColor: c,
      backgroundColor: c,
      borderWidth: 0.75,
      pointRadius: 0,
      pointHitRadius: 0,
    });
  }
  const axis = (text) => ({
    type: 'linear', title: { display: Boolean(text), text: text || '' }, ticks: { includeBounds: false },
  });
  const chart = new Chart(canvas, {
    type: 'scatter',
    data: { datasets },
    options: {
      scales: { x: axis(topView.x_label), y: axis(topView.y_label) },
      // Legend in the data's order (`order` above only sets the drawing order).
      plugins: { legend: { position: 'top', labels: { sort: (a, b) => a.datasetIndex - b.datasetIndex } } },
    },
  });
  // Equal scales need the chart area's size, known after the first layout; the tick labels
  // of the new bounds barely move it, so two passes settle it.
  for (let pass = 0; pass < 2; ++pass) {
    const area = chart.chartArea;
    const bounds = equalScaleBounds(paths, area.right - area.left, area.bottom - area.top);
    Object.assign(chart.options.scales.x, bounds.x);
    Object.assign(chart.options.scales.y, bounds.y);
    chart.update('none');
  }
  return canvas;
}

// Per frame along the video: 3D points observed (bars, one colour per model) and the
// frames left unregistered (red crosses on the axis).
export function perFrameChart(parent, frames) {
  const canvas = chartBox(parent, 'chart-per-frame');
  const labels = frames.map((f, i) => (isNumber(f.index) ? f.index : i));
  const models = [...new Set(frames.filter((f) => f.registered).map((f) => f.model ?? 0))].sort((a, b) => a - b);
  const datasets = models.map((m, k) => ({
    type: 'bar',
    label: models.length > 1 ? `3D points observed (model ${m})` : '3D points observed',
    data: frames.map((f) => (f.registered && (f.model ?? 0) === m ? f.num_points3D ?? 0 : null)),
    backgroundColor: kPalette[k % kPalette.length],
    grouped: false,
    barPercentage: 1.0,
    categoryPercentage: 1.0,
  }));
  if (frames.some((f) => isNumber(f.num_points2D))) {
    datasets.push({
      type: 'line',
      label: 'keypoints',
      data: frames.map((f) => f.num_points2D ?? null),
      borderColor: '#7d7d7d',
      borderWidth: 1,
      pointRadius: 0,
    });
  }
  const unregistered = frames.filter((f) => !f.registered).length;
  datasets.push({
    type: 'line',
    label: `not registered (${unregistered})`,
    data: frames.map((f) => (f.registered ? null : 0)),
    showLine: false,
    pointStyle: 'crossRot',
    pointRadius: 6,
    pointBorderWidth: 2,
    borderColor: '#e0201b',
    backgroundColor: '#e0201b',
  });
  new Chart(canvas, {
    type: 'bar',
    data: { labels, datasets },
    options: {
      plugins: { legend: { position: 'top' } },
      interaction: { mode: 'index', intersect: false },
      scales: {
        x: { title: { display: true, text: 'frame' }, ticks: { autoSkip: true, maxRotation: 0 } },
        y: { beginAtZero: true, title: { display: true, text: 'points per frame' } },
      },
    },
  });
  return canvas;
}

// The alternate pose diagnostic along the video: inlier ratio of each frame's registration,
// and of the second RANSAC over what the first rejected (triangles where that found a
// second plausible pose).
export function registrationChart(parent, frames) {
  const canvas = chartBox(parent, 'chart-registration');
  const labels = frames.map((f, i) => (isNumber(f.index) ? f.index : i));
  const ratio = (value) => (isNumber(value) ? value : null);
  new Chart(canvas, {
    type: 'line',
    data: {
      labels,
      datasets: [
        {
          label: 'registration inlier ratio',
          data: frames.map((f) => ratio(f.registration_inlier_ratio)),
          borderColor: kPalette[0],
          backgroundColor: kPalette[0],
          pointRadius: 0,
          borderWidth: 1.5,
        },
        {
          label: 'second round inlier ratio',
          data: frames.map((f) => ratio(f.alternate_inlier_ratio)),
          borderColor: '#e08a1b',
          backgroundColor: '#e08a1b',
          pointRadius: frames.map((f) => (f.alternate_pose ? 5 : 0)),
          pointStyle: 'triangle',
          borderWidth: 1,
        },
      ],
    },
    options: {
      plugins: { legend: { position: 'top' } },
      interaction: { mode: 'index', intersect: false },
      spanGaps: false,
      scales: {
        x: { title: { display: true, text: 'frame' }, ticks: { autoSkip: true, maxRotation: 0 } },
        y: { beginAtZero: true, max: 1, title: { display: true, text: 'inlier ratio' } },
      },
    },
  });
  return canvas;
}
