// Which frames of the source were kept as keyframes and why, along the video (data.timeline:
// frames_read, kept [[index, reason], ...], blurred [...], localized [...]): one row per
// kind of frame, drawn one pixel column at a time, so that tens of thousands of frames cost
// one pass over them and a few rectangles per row.
import { Chart } from 'chart.js';

import { chartBox } from './charts.js';
import { fmt } from './dom.js';

// What a frame can be, in the order of the legend; `row` is its row of the chart.
const kKinds = [
  { name: 'parallax', colour: '#1f5fd6', row: 'kept' },
  { name: 'overlap', colour: '#2a9d4b', row: 'kept' },
  { name: 'tracking lost', colour: '#d6452b', row: 'kept' },
  { name: 'fill-in', note: 'in-between frame added where keyframes did not verify or register', colour: '#9b4dca', row: 'kept' },
  { name: 'first / last', colour: '#1d2330', row: 'kept' },
  { name: 'window', colour: '#e0a100', row: 'kept' },
  { name: 'reason not recorded', colour: '#8c8c8c', row: 'kept' },
  { name: 'localised', note: 'pose from tracking, not mapped', colour: '#0f9fb0', row: 'localised' },
  { name: 'blurred, skipped', colour: '#7a5c3e', row: 'blurred, skipped' },
  { name: 'skipped', colour: '#c3c8d0', row: 'skipped' },
];
const kRows = ['kept', 'localised', 'blurred, skipped', 'skipped'];
// Kinds of kept frames by reason; an empty reason (a database older than the reasons) or
// one this report does not know is "not recorded".
const kReasonKind = { parallax: 0, overlap: 1, 'tracking-lost': 2, 'fill-in': 3, first: 4, last: 4, window: 5 };
const kNotRecorded = 6;
const kLocalised = 7;
const kBlurred = 8;
const kSkipped = 9;

// The kind of every frame (kept before localised before blurred), with the count of each
// kind, of the frames judged blurred (kept or not) and of those localised.
export function classifyFrames(timeline) {
  const n = timeline.frames_read;
  const kind = new Uint8Array(n).fill(kSkipped);
  const inRange = (i) => Number.isInteger(i) && i >= 0 && i < n;
  const blurred = (timeline.blurred || []).filter(inRange);
  const localised = (timeline.localized || []).filter(inRange);
  for (const i of blurred) kind[i] = kBlurred;
  for (const i of localised) kind[i] = kLocalised;
  for (const [i, reason] of timeline.kept || []) {
    if (inRange(i)) kind[i] = kReasonKind[reason] ?? kNotRecorded;
  }
  const counts = new Array(kKinds.length).fill(0);
  for (const k of kind) ++counts[k];
  return { n, kind, counts, blurred: new Set(blurred).size, localised: new Set(localised).size };
}

// "N of M frames kept (count by reason), K blurred, L localised".
export function timelineCaption(frames) {
  const kept = frames.counts.slice(0, kLocalised);
  const reasons = kept.map((c, k) => (c ? `${fmt(c)} ${kKinds[k].name}` : null)).filter(Boolean);
  const total = kept.reduce((a, b) => a + b, 0);
  return `${fmt(total)} of ${fmt(frames.n)} frames kept${reasons.length ? ` (${reasons.join(', ')})` : ''}, `
    + `${fmt(frames.blurred)} blurred, ${fmt(frames.localised)} localised`;
}

// Draws each row as one-pixel columns: a column shows a kind where any frame under it is of
// that kind (frame i spans i - 0.5 to i + 0.5 on the axis). Over the row of kept frames, the
// frames of every reason but the commonest are drawn again at least 3 pixels wide, rarest on
// top, so that a lone tracking loss among hundreds of parallax keyframes stays in sight.
// Kinds hidden from the legend are left out; `kept` holds the kept frames of each kind.
function stripPlugin(frames, kept, datasetOfKind) {
  return {
    id: 'frameStrip',
    beforeDatasetsDraw(chart) {
      const { ctx, chartArea: area, scales: { x, y } } = chart;
      const shown = kKinds.map((_, k) => datasetOfKind[k] !== undefined && chart.isDatasetVisible(datasetOfKind[k]));
      const rows = y.getLabels();
      const rowOf = kKinds.map((k) => rows.indexOf(k.row));
      const height = Math.min(22, (0.7 * (area.bottom - area.top)) / rows.length);
      // The run of one colour being drawn in each row.
      const runs = rows.map(() => ({ from: 0, colour: null }));
      const extend = (row, px, colour) => {
        const run = runs[row];
        if (run.colour === colour) return;
        if (run.colour) {
          ctx.fillStyle = run.colour;
          ctx.fillRect(run.from, y.getPixelForValue(row) - height / 2, px - run.from, height);
        }
        runs[row] = { from: px, colour };
      };
      ctx.save();
      ctx.beginPath();
      ctx.rect(area.left, area.top, area.right - area.left, area.bottom - area.top);
      ctx.clip();
      const right = Math.ceil(area.right);
      for (let px = Math.floor(area.left); px < right; ++px) {
        const lo = Math.max(0, Math.floor(x.getValueForPixel(px) - 0.5) + 1);
        const end = Math.min(frames.n, Math.ceil(x.getValueForPixel(px + 1) + 0.5));
        const best = rows.map(() => -1);
        for (let i = lo; i < end; ++i) {
          const k = frames.kind[i];
          if (shown[k]) best[rowOf[k]] = k;
        }
        best.forEach((k, row) => extend(row, px, k < 0 ? null : kKinds[k].colour));
      }
      rows.forEach((_, row) => extend(row, right, null));
      const rare = kKinds.map((_, k) => k).filter((k) => k < kLocalised && shown[k])
        .sort((a, b) => frames.counts[b] - frames.counts[a]).slice(1);
      const width = Math.max(3, x.getPixelForValue(1) - x.getPixelForValue(0));
      const top = y.getPixelForValue(0) - height / 2;
      for (const k of rare) {
        ctx.fillStyle = kKinds[k].colour;
        for (const { x: i } of kept[k]) ctx.fillRect(x.getPixelForValue(i) - width / 2, top, width, height);
      }
      ctx.restore();
    },
  };
}

// The strip chart of classifyFrames' `frames`: rows of the kinds present (kept always), a
// legend entry per kind present, a tooltip on each kept frame.
export function timelineChart(parent, frames) {
  const canvas = chartBox(parent, 'chart-timeline');
  const rows = kRows.filter((row, r) => r === 0 || kKinds.some((k, j) => k.row === row && frames.counts[j] > 0));
  canvas.parentElement.style.height = `${36 * rows.length + 130}px`;
  // Only kept frames are points (for their tooltips): the strip plugin draws every frame.
  const kept = kKinds.map(() => []);
  frames.kind.forEach((k, i) => {
    if (k < kLocalised) kept[k].push({ x: i, y: 0 });
  });
  const datasetOfKind = [];
  const datasets = [];
  kKinds.forEach((k, j) => {
    if (!frames.counts[j]) return;
    datasetOfKind[j] = datasets.length;
    datasets.push({
      label: k.note ? `${k.name} (${k.note})` : k.name,
      data: kept[j],
      backgroundColor: k.colour,
      borderColor: k.colour,
      pointRadius: 0,
      pointHoverRadius: 0,
      pointHitRadius: 4,
    });
  });
  new Chart(canvas, {
    type: 'scatter',
    data: { datasets },
    plugins: [stripPlugin(frames, kept, datasetOfKind)],
    options: {
      interaction: { mode: 'nearest', axis: 'x', intersect: false },
      plugins: {
        legend: { position: 'top' },
        tooltip: { callbacks: { label: (item) => `frame ${fmt(item.parsed.x)}: kept, ${item.dataset.label}` } },
      },
      scales: {
        x: {
          type: 'linear',
          min: -0.5,
          max: frames.n - 0.5,
          title: { display: true, text: 'frame of the source' },
          ticks: { includeBounds: false, precision: 0, maxRotation: 0 },
        },
        y: { type: 'category', labels: rows, offset: true, grid: { display: false } },
      },
    },
  });
  return canvas;
}
