// Small DOM and formatting helpers shared by the report's sections.

// Creates an element with attributes (class, id, ...) and children (nodes or text).
export function el(tag, attributes = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attributes)) {
    if (value !== undefined && value !== null) node.setAttribute(key, String(value));
  }
  for (const child of children.flat()) {
    if (child === undefined || child === null) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

// A titled section of the page; `note` is an optional line under the title.
export function section(id, title, note) {
  return el('section', { id, class: 'card' }, el('h2', {}, title), note ? el('p', { class: 'note' }, note) : null);
}

export function isNumber(x) {
  return typeof x === 'number' && Number.isFinite(x);
}

// Fixed digits for finite numbers, an en dash for missing ones.
export function fmt(x, digits = 0) {
  if (!isNumber(x)) return '–';
  return x.toLocaleString('en-US', { minimumFractionDigits: digits, maximumFractionDigits: digits });
}

// Seconds as "12.3 s" or "4 min 05 s".
export function fmtSeconds(s) {
  if (!isNumber(s)) return '–';
  if (s < 60) return `${s.toFixed(s < 10 ? 2 : 1)} s`;
  const minutes = Math.floor(s / 60);
  return `${minutes} min ${String(Math.round(s - 60 * minutes)).padStart(2, '0')} s`;
}

// A two-column table of [label, value] rows; rows whose value is missing are left out.
export function keyValueTable(rows) {
  const body = rows
    .filter(([, value]) => value !== undefined && value !== null && value !== '–')
    .map(([label, value]) => el('tr', {}, el('th', {}, label), el('td', {}, value)));
  return body.length ? el('table', { class: 'kv' }, el('tbody', {}, body)) : null;
}

// Colours of the report, one per series (paths, models).
export const kPalette = ['#1f5fd6', '#d6452b', '#2a9d4b', '#9b4dca', '#e0a100', '#0f9fb0', '#7a5c3e'];
export const kGroundTruthColour = '#8c8c8c';
