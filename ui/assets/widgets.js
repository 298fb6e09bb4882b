// Layout tree and widgets of the console: containers, outputs and command inputs.

const SVG_NS = 'http://www.w3.org/2000/svg';
const EARTH_RADIUS = 6371008.8;

export const PALETTE = ['#3fc1e0', '#f2b33d', '#3ccf8e', '#ff7ab6', '#a98bff', '#f0524f', '#9be15d', '#ffffff'];
const NAMED_COLOURS = {
  green: '#3ccf8e', orange: '#f29a3d', red: '#f0524f', yellow: '#f2d43d', blue: '#4c8dff',
  cyan: '#3fc1e0', grey: '#6b8399', gray: '#6b8399', white: '#e8f1f8', purple: '#a98bff', magenta: '#ff5fd2',
};

// ---------------------------------------------------------------- helpers

export function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  if (attrs) {
    for (const [k, v] of Object.entries(attrs)) {
      if (v === undefined || v === null || v === false) continue;
      if (k === 'class') e.className = v;
      else if (k === 'text') e.textContent = v;
      // through the object model: the page's policy allows no style attributes
      else if (k === 'style') e.style.cssText = v;
      else if (k.startsWith('on') && typeof v === 'function') e.addEventListener(k.slice(2), v);
      else e.setAttribute(k, v === true ? '' : String(v));
    }
  }
  for (const c of children.flat()) {
    if (c === null || c === undefined || c === false) continue;
    e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return e;
}

export function svg(tag, attrs, ...children) {
  const e = document.createElementNS(SVG_NS, tag);
  if (attrs) {
    for (const [k, v] of Object.entries(attrs)) {
      if (v === undefined || v === null) continue;
      if (k === 'text') e.textContent = v;
      else e.setAttribute(k, String(v));
    }
  }
  for (const c of children.flat()) if (c) e.append(c);
  return e;
}

export function colour(name, i) {
  if (!name) return PALETTE[(i || 0) % PALETTE.length];
  const key = String(name).trim().toLowerCase();
  return NAMED_COLOURS[key] || String(name).trim();
}

/** `topic.field` (string) or `{topic, field}` → `{topic, field}`; the field is after the last dot. */
export function parseBind(b) {
  if (!b) return null;
  if (typeof b === 'object') {
    if (typeof b.topic === 'string') return { topic: b.topic, field: b.field == null ? null : String(b.field) };
    return null;
  }
  const s = String(b).trim();
  if (!s) return null;
  const i = s.lastIndexOf('.');
  if (i <= 0) return { topic: s, field: null };
  return { topic: s.slice(0, i), field: s.slice(i + 1) };
}

export function bindText(b) {
  const p = parseBind(b);
  if (!p) return '';
  return p.field ? `${p.topic}.${p.field}` : p.topic;
}

/** A widget attribute naming a whole topic (`position`, health's `bind`): the names it may go by. */
export function topicNames(x) {
  if (!x) return [];
  if (typeof x === 'string') return [x.trim()];
  const p = parseBind(x);
  if (!p) return [];
  return p.field ? [`${p.topic}.${p.field}`, p.topic] : [p.topic];
}

/** Durations: numbers are taken in `unit` ms per unit; strings may carry ms/s/m/h. */
export function parseDuration(x, unitMs, dflt) {
  if (x === undefined || x === null || x === '') return dflt;
  if (typeof x === 'number') return x * unitMs;
  const m = /^\s*(-?[\d.]+)\s*(ms|s|m|min|h)?\s*$/i.exec(String(x));
  if (!m) return dflt;
  const n = parseFloat(m[1]);
  const u = (m[2] || '').toLowerCase();
  if (u === 'ms') return n;
  if (u === 's') return n * 1000;
  if (u === 'm' || u === 'min') return n * 60000;
  if (u === 'h') return n * 3600000;
  return n * unitMs;
}

export function num(x, dflt) {
  if (x === undefined || x === null || x === '') return dflt;
  const n = typeof x === 'number' ? x : parseFloat(x);
  return Number.isFinite(n) ? n : dflt;
}

/** A value typed by a user or written in an attribute: number, boolean or text. */
export function parseValue(s) {
  if (typeof s !== 'string') return s;
  const t = s.trim();
  if (t === 'true') return true;
  if (t === 'false') return false;
  if (t !== '' && /^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/.test(t)) return parseFloat(t);
  return s;
}

/** `F=V, F=V` or an object → an object of typed values. */
export function parseFields(x) {
  if (!x) return {};
  if (typeof x === 'object') return { ...x };
  const out = {};
  for (const part of String(x).split(',')) {
    const i = part.indexOf('=');
    if (i < 0) continue;
    const k = part.slice(0, i).trim();
    if (k) out[k] = parseValue(part.slice(i + 1).trim());
  }
  return out;
}

export function fmtValue(v, precision) {
  if (v === undefined) return '—';
  if (v === null) return 'null';
  if (typeof v === 'number') {
    if (!Number.isFinite(v)) return String(v);
    if (precision !== undefined && precision !== null && precision !== '') {
      const p = Math.max(0, Math.min(12, Math.round(num(precision, 2))));
      return v.toFixed(p);
    }
    if (Number.isInteger(v)) return String(v);
    const a = Math.abs(v);
    return String(+v.toFixed(a >= 1000 ? 1 : a >= 1 ? 3 : 4));
  }
  if (typeof v === 'boolean') return v ? 'true' : 'false';
  if (typeof v === 'object') return fmtObject(v);
  return String(v);
}

/** An attribute that is a flag: `true` (as the layout's JSON or the designer writes it). */
function isOn(x) {
  return x === true || x === 'true';
}

/** An angle in degrees within [0, 360). */
export function angle360(v) {
  let a = v % 360;
  if (a < 0) a += 360;
  return a >= 360 ? 0 : a;
}

/** An angle in degrees as text within [0, 360): 359.96 with precision 0 is `0`, never `360`. */
export function fmtAngle(v, precision) {
  const s = fmtValue(angle360(v), precision);
  return parseFloat(s) >= 360 ? fmtValue(0, precision) : s;
}

/** How a switch shows a boolean field. */
const SWITCH_WORDS = { true: 'on', false: 'off' };

/**
 * A value as an output widget shows it: a boolean as the widget's `true` / `false` words (yes
 * and no without them), a number of an `angle="true"` widget within [0, 360), else as it is.
 */
export function fmtOutput(node, v) {
  if (typeof v === 'boolean') return v ? String(node.true ?? 'yes') : String(node.false ?? 'no');
  if (typeof v === 'number' && Number.isFinite(v) && isOn(node.angle)) return fmtAngle(v, node.precision);
  return fmtValue(v, node.precision);
}

/**
 * Two lists of stamped items, each oldest first, as one list oldest first with one item per
 * stamp (the one already in `list` kept). Appends to `list` when `more` is all newer.
 */
export function mergeByStamp(list, more, stampOf) {
  const last = list.length ? stampOf(list[list.length - 1]) : -Infinity;
  let prev = last;
  let newer = true;
  for (const x of more) {
    const t = stampOf(x);
    if (!(t > prev)) { newer = false; break; }
    prev = t;
  }
  if (newer) {
    for (const x of more) list.push(x);
    return list;
  }
  if (more.length === 1 && stampOf(more[0]) === last) return list;
  const all = list.concat(more).sort((a, b) => stampOf(a) - stampOf(b));
  return all.filter((x, i) => i === 0 || stampOf(x) !== stampOf(all[i - 1]));
}

function fmtObject(v) {
  try {
    const s = JSON.stringify(v);
    return s.length > 200 ? s.slice(0, 199) + '…' : s;
  } catch (_) {
    return String(v);
  }
}

export function fmtFields(fields) {
  if (!fields || typeof fields !== 'object') return fields === undefined ? '' : String(fields);
  return Object.entries(fields).map(([k, v]) => `${k}=${fmtValue(v)}`).join(', ');
}

export function fmtAge(s) {
  if (!Number.isFinite(s) || s < 0) s = 0;
  if (s < 60) return `${Math.floor(s)}s`;
  if (s < 3600) return `${Math.floor(s / 60)}m`;
  if (s < 86400) return `${Math.floor(s / 3600)}h`;
  return `${Math.floor(s / 86400)}d`;
}

/** Seconds since the epoch (or an ISO text) → local HH:MM:SS. */
export function fmtTime(t, millis) {
  let d;
  if (typeof t === 'number') d = new Date(t > 1e11 ? t : t * 1000);
  else if (typeof t === 'string' && t) d = new Date(/^[\d.]+$/.test(t) ? parseFloat(t) * 1000 : t);
  else return '';
  if (isNaN(d.getTime())) return String(t);
  const p = (n, w = 2) => String(n).padStart(w, '0');
  const base = `${p(d.getHours())}:${p(d.getMinutes())}:${p(d.getSeconds())}`;
  return millis ? `${base}.${p(d.getMilliseconds(), 3)}` : base;
}

function niceStep(span, target) {
  if (!(span > 0)) return 1;
  const raw = span / Math.max(1, target);
  const pow = Math.pow(10, Math.floor(Math.log10(raw)));
  const f = raw / pow;
  const m = f < 1.5 ? 1 : f < 3.5 ? 2 : f < 7.5 ? 5 : 10;
  return m * pow;
}

function globToRegExp(p) {
  const esc = p.replace(/[.+^${}()|[\]\\]/g, '\\$&').replace(/\*/g, '.*').replace(/\?/g, '.');
  return new RegExp(`^${esc}$`);
}

function listAttr(x) {
  if (Array.isArray(x)) return x.map(String);
  if (x === undefined || x === null || x === '') return [];
  return String(x).split(/[,\s]+/).filter(Boolean);
}

// ---------------------------------------------------------------- the tree

const CONTAINERS = new Set(['row', 'column', 'grid', 'tabs', 'tab']);
export const OUTPUT_KINDS = ['readout', 'gauge', 'plot', 'track', 'fleet', 'health', 'log', 'history'];
export const INPUT_KINDS = ['button', 'slider', 'number', 'text', 'toggle'];
export const CONTAINER_KINDS = ['row', 'column', 'grid', 'tabs', 'tab'];

export function isContainer(node) {
  return node && CONTAINERS.has(node.kind);
}

export function nodeChildren(node) {
  return Array.isArray(node && node.children) ? node.children : [];
}

/**
 * Renders a node and its children. Returns the element, or null for a node the user may not see.
 * Widgets are registered with ctx.register so that data, time and lease changes reach them.
 */
export function renderNode(ctx, node) {
  if (!node || typeof node !== 'object') return null;
  if (node.role && !ctx.hasRole(node.role)) return null;
  const kind = String(node.kind || 'unknown');
  let e;
  switch (kind) {
    case 'row':
    case 'column':
    case 'tab':
      e = renderFlex(ctx, node, kind === 'row' ? 'row' : 'column');
      break;
    case 'grid':
      e = renderGrid(ctx, node);
      break;
    case 'tabs':
      e = renderTabs(ctx, node);
      break;
    case 'readout': e = readout(ctx, node); break;
    case 'gauge': e = gauge(ctx, node); break;
    case 'plot': e = plot(ctx, node); break;
    case 'track': e = track(ctx, node); break;
    case 'fleet': e = fleet(ctx, node); break;
    case 'health': e = health(ctx, node); break;
    case 'log': e = logWidget(ctx, node); break;
    case 'history': e = history(ctx, node); break;
    case 'button': case 'slider': case 'number': case 'text': case 'toggle':
      e = input(ctx, node, kind);
      break;
    case 'series':
      return null;
    default:
      e = frame(ctx, node, kind, el('div', { class: 'unknown', text: `unknown widget <${kind}>` }));
  }
  if (!e) return null;
  e.classList.add('node');
  if (node.id !== undefined) e.dataset.widgetId = node.id;
  e.dataset.kind = kind;
  ctx.nodeElement(e, node);
  return e;
}

function renderKids(ctx, node) {
  const out = [];
  nodeChildren(node).forEach((c, i) => {
    const e = renderNode(ctx, c);
    if (e) out.push([e, i]);
  });
  return out;
}

function renderFlex(ctx, node, dir) {
  const e = el('div', { class: dir, 'data-testid': 'container' });
  const sizes = Array.isArray(node.sizes) ? node.sizes : listAttr(node.sizes).map(Number);
  for (const [c, i] of renderKids(ctx, node)) {
    const s = num(sizes[i], sizes.length ? 1 : undefined);
    if (dir === 'row') {
      c.style.flex = `${s > 0 ? s : 1} 1 0`;
    } else if (s !== undefined) {
      c.style.flex = `${s > 0 ? s : 1} 0 auto`;
      // in a column of the screen's height, the sizes alone share it (console.css)
      c.dataset.sized = '';
    } else {
      // a column without sizes: natural heights, the big widgets share what is left
      c.style.flex = /^(track|plot|tabs|log|health|history|row|column)$/.test(String(c.dataset.kind || nodeChildren(node)[i].kind)) ? '1 0 auto' : '0 0 auto';
    }
    e.append(c);
  }
  return e;
}

function renderGrid(ctx, node) {
  const cols = Math.max(1, Math.round(num(node.columns, 2)));
  const e = el('div', { class: 'grid', 'data-testid': 'container' });
  e.style.gridTemplateColumns = `repeat(${cols}, minmax(0, 1fr))`;
  for (const [c] of renderKids(ctx, node)) e.append(c);
  return e;
}

function renderTabs(ctx, node) {
  const e = el('div', { class: 'tabs', 'data-testid': 'container' });
  const bar = el('div', { class: 'tab-bar', role: 'tablist' });
  const panels = [];
  const titles = Array.isArray(node.titles) ? node.titles : [];
  const key = `tab:${node.id}`;
  let current = ctx.uiState.get(key) || 0;
  const kids = renderKids(ctx, node);
  kids.forEach(([c, i], n) => {
    const child = nodeChildren(node)[i];
    const title = titles[i] || child.title || child.label || `Tab ${n + 1}`;
    const id = `${String(node.id || 'tabs').replace(/\W/g, '_')}-${n}`;
    const b = el('button', { type: 'button', role: 'tab', id: `${id}-t`, 'aria-controls': `${id}-p`, text: title });
    const p = el('div', { class: 'tab-panel', role: 'tabpanel', id: `${id}-p`, 'aria-labelledby': `${id}-t` }, c);
    b.addEventListener('click', () => select(n));
    bar.append(b);
    panels.push([b, p]);
    e.append(p);
  });
  e.prepend(bar);
  function select(n) {
    current = n;
    ctx.uiState.set(key, n);
    panels.forEach(([b, p], j) => {
      b.setAttribute('aria-selected', j === n ? 'true' : 'false');
      b.tabIndex = j === n ? 0 : -1;
      p.hidden = j !== n;
    });
    ctx.redrawSoon();
  }
  if (current >= panels.length) current = 0;
  if (panels.length) select(current);
  return e;
}

// ---------------------------------------------------------------- frames and status

function frame(ctx, node, kind, body, extraClass) {
  const label = node.label || '';
  const status = el('span', { class: 'w-status', 'data-testid': 'status', 'data-state': 'nodata' });
  const head = el('div', { class: 'w-head' }, el('span', { class: 'w-label', text: label, title: label }), status);
  const e = el('section', {
    class: `widget widget-${kind}${extraClass ? ' ' + extraClass : ''}`,
    'data-testid': 'widget',
    'aria-label': label || kind,
  }, head, el('div', { class: 'w-body' }, body));
  e._status = status;
  return e;
}

/** Fresh / stale / no data / no producer for a widget whose values come from `topicsList`. */
export function applyStatus(ctx, e, topicsList, freshMs) {
  const status = e._status;
  if (!status) return;
  let best = null;
  let missing = [];
  for (const entry of topicsList) {
    // the names a topic goes by, or (`{matching, pattern}`) every topic a pattern matches
    const names = Array.isArray(entry) ? entry : Object.keys(ctx.allTopics()).filter(entry.matching);
    let found = null;
    for (const n of names) {
      const t = ctx.topic(n);
      if (t && (!found || num(t.stamp, 0) > num(found.stamp, 0))) found = t;
      if (found && Array.isArray(entry)) break;
    }
    if (found) {
      const age = ctx.serverNow() - num(found.stamp, 0);
      if (best === null || age < best) best = age;
    } else if (!Array.isArray(entry) && ctx.producer(entry.pattern) === false) {
      missing.push(entry.pattern);
    } else if (names.length && names.every((n) => ctx.producer(n) === false)) {
      missing.push(names[0]);
    }
  }
  let state, text, title = '';
  if (best !== null) {
    if (best * 1000 > freshMs) {
      state = 'stale';
      text = `stale ${fmtAge(best)}`;
      title = `last value ${best.toFixed(1)} s old (fresh: ${freshMs / 1000} s)`;
    } else {
      state = 'fresh';
      text = '';
    }
  } else if (missing.length && missing.length === topicsList.length) {
    state = 'noproducer';
    text = 'no producer';
    title = `no module produces ${missing.join(', ')}`;
  } else {
    state = 'nodata';
    text = 'no data';
  }
  if (status.dataset.state !== state || status.textContent !== text) {
    status.dataset.state = state;
    status.textContent = text;
    status.title = title;
    e.classList.toggle('is-stale', state === 'stale');
    e.classList.toggle('is-nodata', state === 'nodata');
    e.classList.toggle('is-noproducer', state === 'noproducer');
  }
}

function freshOf(node) {
  if (node.fresh_ms !== undefined) return num(node.fresh_ms, 2000);
  return parseDuration(node.fresh, 1000, 2000);
}

function outputWidget(ctx, node, kind, body, topicsList, handlers) {
  const e = frame(ctx, node, kind, body);
  const freshMs = freshOf(node);
  const w = {
    node, el: e,
    update: handlers.update || (() => {}),
    tick() {
      applyStatus(ctx, e, topicsList, freshMs);
      if (handlers.tick) handlers.tick();
    },
    redraw: handlers.redraw,
    onHistory: handlers.onHistory,
    onLease: handlers.onLease,
    onBacklog: handlers.onBacklog,
    drawn: handlers.drawn,
  };
  ctx.register(w);
  w.update();
  w.tick();
  return e;
}

function valueOf(ctx, b) {
  if (!b) return undefined;
  const t = ctx.topic(b.topic);
  if (!t || !t.fields || b.field === null) return undefined;
  return t.fields[b.field];
}

// ---------------------------------------------------------------- readout

function readout(ctx, node) {
  const b = parseBind(node.bind);
  const value = el('span', { class: 'readout-num', 'data-testid': 'value', text: '—' });
  const unit = node.unit ? el('span', { class: 'readout-unit', text: node.unit }) : null;
  const body = el('div', { class: 'readout-value', 'aria-live': 'off' }, value, unit);
  if (!node.label && b) node = { ...node, label: bindText(b) };
  // the number is made smaller until it fits its box (never cut short), whenever its length or
  // the box changes
  let fitted = '';
  function fit() {
    const key = `${value.textContent.length}/${body.clientWidth}`;
    if (key === fitted || !body.clientWidth) return;
    fitted = key;
    body.style.fontSize = '';
    const need = body.scrollWidth, have = body.clientWidth;
    if (need > have) {
      const full = parseFloat(getComputedStyle(body).fontSize) || 32;
      body.style.fontSize = `${Math.max(10, Math.floor(full * have / need * 0.97))}px`;
    }
  }
  return outputWidget(ctx, node, 'readout', body, b ? [[b.topic]] : [], {
    update() {
      const s = fmtOutput(node, valueOf(ctx, b));
      if (value.textContent !== s) {
        value.textContent = s;
        fit();
      }
    },
    redraw: fit,
    tick: fit,
  });
}

// ---------------------------------------------------------------- gauge

export function parseRanges(x) {
  if (!x) return [];
  if (Array.isArray(x)) {
    return x.map((r) => {
      if (Array.isArray(r)) return { from: num(r[0], 0), to: num(r[1], 0), colour: r[2] };
      return { from: num(r.from, 0), to: num(r.to, 0), colour: r.colour || r.color };
    });
  }
  return String(x).split(',').map((s) => s.trim()).filter(Boolean).map((s) => {
    const [a, b, c] = s.split(':');
    return { from: num(a, 0), to: num(b, 0), colour: (c || '').trim() };
  });
}

/**
 * A dial: an arc of 270° from `min` to `max` with coloured ranges, or (`angle="true"`) a compass
 * dial over 0–360° with 0 at the top. The needle stays inside the tick numbers; the value is
 * written below the dial.
 */
function gauge(ctx, node) {
  const b = parseBind(node.bind);
  const compass = isOn(node.angle);
  const min = compass ? 0 : num(node.min, 0);
  let max = compass ? 360 : num(node.max, 100);
  if (!(max > min)) max = min + 1;
  const cx = 100, cy = compass ? 88 : 100, r = compass ? 70 : 78;
  const ang = compass
    ? (v) => angle360(v)
    : (v) => -135 + 270 * Math.max(0, Math.min(1, (v - min) / (max - min)));
  const pt = (a, rr) => [cx + rr * Math.sin(a * Math.PI / 180), cy - rr * Math.cos(a * Math.PI / 180)];
  const arc = (a1, a2, rr) => {
    const [x1, y1] = pt(a1, rr);
    const [x2, y2] = pt(a2, rr);
    return `M${x1.toFixed(2)},${y1.toFixed(2)} A${rr},${rr} 0 ${a2 - a1 > 180 ? 1 : 0} 1 ${x2.toFixed(2)},${y2.toFixed(2)}`;
  };
  const height = compass ? 206 : 168;
  const s = svg('svg', { viewBox: `0 0 200 ${height}`, role: 'img', 'aria-label': node.label || 'gauge' });
  if (compass) s.append(svg('circle', { cx, cy, r, fill: 'none', stroke: '#1c3750', 'stroke-width': 12 }));
  else s.append(svg('path', { d: arc(-135, 135, r), fill: 'none', stroke: '#1c3750', 'stroke-width': 12, 'stroke-linecap': 'butt' }));
  parseRanges(node.ranges).forEach((rg, i) => {
    const lo = Math.min(rg.from, rg.to), hi = Math.max(rg.from, rg.to);
    const a1 = compass ? lo : ang(lo), a2 = compass ? hi : ang(hi);
    if (a2 > a1) s.append(svg('path', { d: arc(a1, Math.min(a2, a1 + 359.99), r), fill: 'none', stroke: colour(rg.colour, i), 'stroke-width': 12 }));
  });
  // ticks: a compass every 30° (numbers every 90°, 0 at the top and never 360 beside it)
  const step = compass ? 30 : niceStep(max - min, 5);
  const last = compass ? max - step / 2 : max + step * 1e-6;
  for (let v = Math.ceil(min / step) * step; v <= last; v += step) {
    const a = ang(v);
    const [x1, y1] = pt(a, r - 8);
    const [x2, y2] = pt(a, r + 6);
    const [tx, ty] = pt(a, r - 20);
    s.append(svg('line', { x1, y1, x2, y2, stroke: '#7f9bb3', 'stroke-width': 1.2 }));
    if (!compass || v % 90 === 0) {
      s.append(svg('text', { x: tx, y: ty + 3, 'text-anchor': 'middle', class: 'gauge-tick', text: fmtValue(+v.toFixed(6)) }));
    }
  }
  // the needle ends short of the numbers (their centres sit 20 units in from the arc; a number
  // of three digits reaches 8 units either side)
  const tip = r - 34;
  const needle = svg('line', { x1: cx, y1: cy, x2: cx, y2: cy - tip, stroke: '#ffffff', 'stroke-width': 3, 'stroke-linecap': 'round', 'data-testid': 'needle' });
  const needleG = svg('g', { transform: `rotate(${ang(min)} ${cx} ${cy})` }, needle);
  s.append(needleG, svg('circle', { cx, cy, r: 6, fill: '#d8e6f2' }));
  const valY = compass ? cy + r + 26 : 142;
  const valText = svg('text', { x: cx, y: valY, 'text-anchor': 'middle', class: 'gauge-value', 'data-testid': 'value', text: '—' });
  const unitText = svg('text', { x: cx, y: valY + 18, 'text-anchor': 'middle', class: 'gauge-unit', text: node.unit || '' });
  s.append(valText, unitText);
  const body = el('div', { class: 'gauge' }, s);
  if (!node.label && b) node = { ...node, label: bindText(b) };
  return outputWidget(ctx, node, 'gauge', body, b ? [[b.topic]] : [], {
    update() {
      const v = valueOf(ctx, b);
      const t = fmtOutput(node, v);
      if (valText.textContent !== t) valText.textContent = t;
      if (typeof v === 'number' && Number.isFinite(v)) {
        needleG.setAttribute('transform', `rotate(${ang(v).toFixed(2)} ${cx} ${cy})`);
        needle.setAttribute('stroke', !compass && (v < min || v > max) ? '#ff2d6f' : '#ffffff');
      }
    },
  });
}

// ---------------------------------------------------------------- plot

/** A line breaks where no sample came for this long, and longer than 3 usual intervals around. */
const GAP_FLOOR_S = 1;
/** Intervals either side that say what is usual where a line may break. */
const GAP_NEIGHBOURS = 5;
/** The width of one y axis with its tick labels, in CSS pixels. */
const AXIS_W = 46;

function plotSeries(node) {
  const list = Array.isArray(node.series) ? node.series : nodeChildren(node).filter((c) => c && c.kind === 'series');
  return list.map((s, i) => ({
    bind: parseBind(s.bind),
    label: s.label || bindText(s.bind) || `series ${i + 1}`,
    colour: colour(s.colour || s.color, i),
    unit: s.unit ? String(s.unit) : '',
    angle: isOn(s.angle),
    samples: [],
  })).filter((s) => s.bind);
}

/** The y axes of `series`: one per unit (angles apart), in the order the series come. */
function plotAxes(series) {
  const axes = [];
  for (const s of series) {
    const key = `${s.unit}\u0000${s.angle}`;
    let i = axes.findIndex((a) => a.key === key);
    if (i < 0) {
      i = axes.length;
      axes.push({ key, unit: s.unit || (s.angle ? '°' : ''), angle: s.angle, colour: s.colour, side: i % 2 ? 'right' : 'left', slot: i >> 1 });
    }
    s.axis = i;
  }
  return axes;
}

/** Whether the line breaks before `samples[i]`: a gap of more than 3 usual intervals and the floor. */
function breaksBefore(samples, i) {
  const dt = samples[i][0] - samples[i - 1][0];
  if (!(dt > GAP_FLOOR_S)) return false;
  const around = [];
  for (let j = Math.max(1, i - GAP_NEIGHBOURS); j <= Math.min(samples.length - 1, i + GAP_NEIGHBOURS); j++) {
    if (j !== i) around.push(samples[j][0] - samples[j - 1][0]);
  }
  if (!around.length) return false;
  around.sort((a, b) => a - b);
  return dt > 3 * around[around.length >> 1];
}

/** The difference of two angles in degrees, within [−180, 180). */
function turn(d) {
  return angle360(d + 180) - 180;
}

/**
 * The samples of `s` from `from` on as lines of [t, v]: broken at gaps, and an angle unwrapped
 * (359 → 1 goes on to 361), starting in [0, 360) or near where `refs` says its axis is.
 */
function plotLines(s, from, refs) {
  const lines = [];
  let line = null;
  let prevRaw, prevV;
  let i = s.samples.findIndex(([t]) => t >= from);
  if (i < 0) return lines;
  for (; i < s.samples.length; i++) {
    const [t, raw] = s.samples[i];
    let v = raw;
    if (s.angle) {
      if (prevRaw === undefined) {
        v = angle360(raw);
        const ref = refs.get(s.axis);
        if (ref === undefined) refs.set(s.axis, v);
        else v += 360 * Math.round((ref - v) / 360);
      } else {
        v = prevV + turn(raw - prevRaw);
      }
      prevRaw = raw;
      prevV = v;
    }
    if (!line || breaksBefore(s.samples, i)) {
      line = [];
      lines.push(line);
    }
    line.push([t, v]);
  }
  return lines;
}

function plot(ctx, node) {
  const series = plotSeries(node);
  const axes = plotAxes(series);
  const windowMs = node.window_ms !== undefined ? num(node.window_ms, 60000) : parseDuration(node.window, 1000, 60000);
  const fixedMin = num(node.min, undefined);
  const fixedMax = num(node.max, undefined);
  const canvas = el('canvas', { role: 'img', 'aria-label': `plot of ${series.map((s) => s.label).join(', ')}` });
  const wrap = el('div', { class: 'plot-canvas-wrap' }, canvas);
  const legend = el('div', { class: 'plot-legend' });
  const legendVals = series.map((s) => {
    const v = el('span', { class: 'val', text: '—' });
    const item = el('span', {}, el('span', { class: 'sw', style: `background:${s.colour}` }), s.label, v);
    legend.append(item);
    return [item, v];
  });
  const body = el('div', { class: 'w-stack' }, wrap, legend);
  let drawn = null;
  if (!node.label) node = { ...node, label: series.map((x) => x.label).join(' · ') || 'Plot' };

  function draw() {
    if (!canvas.isConnected || !canvas.offsetParent) return;
    const dpr = window.devicePixelRatio || 1;
    const W = Math.max(50, wrap.clientWidth), H = Math.max(50, wrap.clientHeight);
    if (canvas.width !== Math.round(W * dpr) || canvas.height !== Math.round(H * dpr)) {
      canvas.width = Math.round(W * dpr);
      canvas.height = Math.round(H * dpr);
    }
    const g = canvas.getContext('2d');
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, W, H);
    const now = ctx.serverNow();
    const wS = windowMs / 1000;
    const t0 = now - wS;
    const refs = new Map();
    const lines = series.map((s) => plotLines(s, t0 - wS * 0.05, refs));
    const ranges = axes.map((a, k) => {
      let lo = Infinity, hi = -Infinity;
      series.forEach((s, i) => {
        if (s.axis !== k) return;
        for (const line of lines[i]) for (const [t, v] of line) if (t >= t0) { if (v < lo) lo = v; if (v > hi) hi = v; }
      });
      const fixLo = k === 0 && !a.angle ? fixedMin : undefined;
      const fixHi = k === 0 && !a.angle ? fixedMax : undefined;
      if (fixLo !== undefined) lo = fixLo;
      if (fixHi !== undefined) hi = fixHi;
      if (!Number.isFinite(lo) || !Number.isFinite(hi)) { lo = 0; hi = 1; }
      if (hi - lo < 1e-9) { lo -= 1; hi += 1; } else {
        const pad = (hi - lo) * 0.06;
        if (fixLo === undefined) lo -= pad;
        if (fixHi === undefined) hi += pad;
      }
      return [lo, hi];
    });
    const left = axes.filter((a) => a.side === 'left').length;
    const right = axes.length - left;
    const L = Math.max(1, left) * AXIS_W + 2, R = right ? right * AXIS_W + 2 : 8;
    const T = axes.some((a) => a.unit) ? 18 : 6, B = 18;
    const pw = Math.max(1, W - L - R), ph = Math.max(1, H - T - B);
    const X = (t) => L + ((t - t0) / wS) * pw;
    const Ys = ranges.map(([lo, hi]) => (v) => T + (1 - (v - lo) / (hi - lo)) * ph);
    g.font = '11px ui-monospace, monospace';
    g.lineWidth = 1;
    const axesDrawn = axes.map((a, k) => {
      const [lo, hi] = ranges[k];
      const Y = Ys[k];
      const x = a.side === 'left' ? L - a.slot * AXIS_W : L + pw + a.slot * AXIS_W;
      const out = a.side === 'left' ? -1 : 1;
      const ink = axes.length > 1 ? a.colour : '#7f9bb3';
      const ystep = niceStep(hi - lo, 4);
      const ticks = [];
      g.textAlign = a.side === 'left' ? 'right' : 'left';
      g.textBaseline = 'middle';
      for (let v = Math.ceil(lo / ystep) * ystep; v <= hi + 1e-9; v += ystep) {
        const y = Math.round(Y(v)) + 0.5;
        if (k === 0) {
          g.strokeStyle = Math.abs(v) < ystep * 1e-6 && !a.angle ? '#2f5d80' : '#173550';
          g.beginPath(); g.moveTo(L, y); g.lineTo(L + pw, y); g.stroke();
        }
        g.strokeStyle = '#1f4563';
        g.beginPath(); g.moveTo(x, y); g.lineTo(x + 4 * out, y); g.stroke();
        const text = a.angle ? fmtAngle(+v.toFixed(6)) : fmtValue(+v.toFixed(6));
        g.fillStyle = ink;
        g.fillText(text, x + 5 * out, y);
        ticks.push(text);
      }
      if (a.slot > 0) {
        g.strokeStyle = '#1f4563';
        g.beginPath(); g.moveTo(x + 0.5, T); g.lineTo(x + 0.5, T + ph); g.stroke();
      }
      if (a.unit) {
        g.fillStyle = ink;
        g.textBaseline = 'bottom';
        g.fillText(a.unit, x + 5 * out, T - 3);
      }
      return { unit: a.unit, angle: a.angle, side: a.side, min: lo, max: hi, ticks };
    });
    const tstep = niceStep(wS, 4);
    g.textAlign = 'center';
    g.textBaseline = 'top';
    for (let a = 0; a <= wS + 1e-9; a += tstep) {
      const x = Math.round(X(now - a)) + 0.5;
      g.strokeStyle = '#173550';
      g.beginPath(); g.moveTo(x, T); g.lineTo(x, T + ph); g.stroke();
      g.fillStyle = '#7f9bb3';
      g.fillText(a === 0 ? 'now' : `-${fmtValue(+a.toFixed(3))}s`, Math.min(L + pw - 12, Math.max(L + 12, x)), T + ph + 3);
    }
    g.save();
    g.beginPath(); g.rect(L, T, pw, ph); g.clip();
    const linesDrawn = [];
    series.forEach((s, i) => {
      const Y = Ys[s.axis];
      g.strokeStyle = s.colour;
      g.fillStyle = s.colour;
      g.lineWidth = 2;
      for (const line of lines[i]) {
        const points = line.map(([t, v]) => [X(t), Y(v)]);
        if (points.length === 1) {
          g.beginPath(); g.arc(points[0][0], points[0][1], 1.5, 0, Math.PI * 2); g.fill();
        } else {
          g.beginPath();
          points.forEach(([x, y], j) => (j ? g.lineTo(x, y) : g.moveTo(x, y)));
          g.stroke();
        }
        linesDrawn.push({ series: s.label, axis: s.axis, points: points.map(([x, y]) => [+x.toFixed(1), +y.toFixed(1)]) });
      }
      const last = lines[i].length ? lines[i][lines[i].length - 1].at(-1) : undefined;
      if (last && last[0] >= t0) {
        g.beginPath(); g.arc(X(last[0]), Y(last[1]), 3, 0, Math.PI * 2); g.fill();
      }
    });
    g.restore();
    g.strokeStyle = '#1f4563';
    g.strokeRect(L + 0.5, T + 0.5, pw, ph);
    drawn = { area: { left: L, top: T, width: pw, height: ph }, axes: axesDrawn, lines: linesDrawn };
  }

  /** Drops what is out of the window (and more than 20000 samples a series). */
  function trim() {
    const cut = ctx.serverNow() - windowMs / 1000 * 1.2;
    for (const s of series) {
      let k = 0;
      while (k < s.samples.length && s.samples[k][0] < cut) k++;
      if (k) s.samples.splice(0, k);
      if (s.samples.length > 20000) s.samples.splice(0, s.samples.length - 20000);
    }
  }

  const topics = series.map((s) => [s.bind.topic]);
  return outputWidget(ctx, node, 'plot', body, topics, {
    update() {
      series.forEach((s, i) => {
        const t = ctx.topic(s.bind.topic);
        if (!t || !t.fields) return;
        const v = t.fields[s.bind.field];
        const stamp = num(t.stamp, NaN);
        if (typeof v === 'number' && Number.isFinite(v) && Number.isFinite(stamp)) {
          s.samples = mergeByStamp(s.samples, [[stamp, v]], (x) => x[0]);
        }
        const txt = fmtOutput({ angle: s.angle, precision: node.precision }, v);
        if (legendVals[i][1].textContent !== txt) {
          legendVals[i][1].textContent = txt;
          legendVals[i][0].classList.remove('noproducer');
          legendVals[i][0].title = '';
        }
      });
      trim();
    },
    onBacklog(backlog) {
      for (const s of series) {
        const list = backlog[s.bind.topic];
        if (!Array.isArray(list)) continue;
        const got = [];
        for (const m of list) {
          const v = m && m.fields ? m.fields[s.bind.field] : undefined;
          const stamp = num(m && m.stamp, NaN);
          if (typeof v === 'number' && Number.isFinite(v) && Number.isFinite(stamp)) got.push([stamp, v]);
        }
        s.samples = mergeByStamp(s.samples, got.sort((a, b) => a[0] - b[0]), (x) => x[0]);
      }
      trim();
      draw();
    },
    tick() {
      const now = ctx.serverNow();
      const fresh = freshOf(node) / 1000;
      series.forEach((s, i) => {
        const last = s.samples[s.samples.length - 1];
        const [item, val] = legendVals[i];
        item.classList.toggle('stale', !last || now - last[0] > fresh);
        const none = !last && ctx.producer(s.bind.topic) === false;
        if (item.classList.contains('noproducer') !== none) {
          item.classList.toggle('noproducer', none);
          item.title = none ? `no module produces ${s.bind.topic}` : '';
          if (none) val.textContent = 'no producer';
        }
      });
      draw();
    },
    redraw: draw,
    drawn: () => drawn,
  });
}

// ---------------------------------------------------------------- track

export function parseWaypoints(x) {
  if (!x) return [];
  if (Array.isArray(x)) {
    return x.map((p) => Array.isArray(p) ? { lat: num(p[0], NaN), lon: num(p[1], NaN) } : { lat: num(p.lat, NaN), lon: num(p.lon, NaN) })
      .filter((p) => Number.isFinite(p.lat) && Number.isFinite(p.lon));
  }
  return String(x).split(';').map((s) => s.trim()).filter(Boolean).map((s) => {
    const [a, b] = s.split(',');
    return { lat: num(a, NaN), lon: num(b, NaN) };
  }).filter((p) => Number.isFinite(p.lat) && Number.isFinite(p.lon));
}

/**
 * A seabus topic pattern (`*` one segment, `**` any) as a RegExp whose groups are what each
 * wildcard captured; null for a plain topic.
 */
export function patternRegExp(p) {
  if (!/\*/.test(p)) return null;
  const parts = String(p).split('.').map((seg) => {
    if (seg === '**') return '(.*)';
    if (seg === '*') return '([^.]+)';
    return seg.replace(/[.+^${}()|[\]\\?]/g, '\\$&');
  });
  // `a.**` also matches `a`
  return new RegExp(`^${parts.join('\\.').replace(/\\\.\(\.\*\)$/, '(?:\\.(.*))?')}$`);
}

/** `pattern` with its wildcards replaced, in order, by `captured`. */
function fillPattern(pattern, captured) {
  let i = 0;
  return String(pattern).split('.').map((seg) => (seg === '*' || seg === '**' ? captured[i++] ?? '' : seg)).filter((s) => s !== '').join('.');
}

function track(ctx, node) {
  const posNames = topicNames(node.position);
  // a pattern (`*.nav.position`) draws one trail per vehicle, named by what the wildcards match
  const posPattern = posNames.length ? patternRegExp(posNames[0]) : null;
  const headB = parseBind(node.heading);
  const trailN = Math.max(2, Math.round(num(node.trail, 600)));
  const waypoints = parseWaypoints(node.waypoints);
  const gridAttr = node.grid;
  // per vehicle ('' for a single topic): positions oldest first, {lat, lon, t}, one per stamp,
  // none the same as the one before; and its heading
  const vehicles = new Map();
  let origin = waypoints.length ? { ...waypoints[0] } : null;
  const wrap = el('div', { class: 'track-wrap' });
  const s = svg('svg', { role: 'img', 'aria-label': node.label || 'vehicle track' });
  wrap.append(s);
  const info = el('div', { class: 'track-info', 'data-testid': 'track-info' });
  const body = el('div', { class: 'w-stack' }, wrap, info);
  let dirty = true;
  if (!node.label) node = { ...node, label: posPattern ? 'Tracks' : 'Track' };

  function vehicle(key) {
    let v = vehicles.get(key);
    if (!v) {
      v = { trail: [], heading: undefined, colour: PALETTE[vehicles.size % PALETTE.length] };
      vehicles.set(key, v);
    }
    return v;
  }

  /** Takes in positions of vehicle `key` (oldest first): merged by stamp, kept to `trail` points. */
  function addPositions(key, more) {
    const v = vehicle(key);
    const before = v.trail.length;
    const merged = mergeByStamp(v.trail, more, (p) => p.t);
    if (merged === v.trail && merged.length === before) return;
    v.trail = merged.filter((p, i) => i === 0 || p.lat !== merged[i - 1].lat || p.lon !== merged[i - 1].lon);
    if (v.trail.length > trailN) v.trail.splice(0, v.trail.length - trailN);
    dirty = true;
  }

  /** A position message's point, or null. */
  function positionOf(m) {
    if (!m || !m.fields) return null;
    const p = { lat: num(m.fields.lat, NaN), lon: num(m.fields.lon, NaN), t: num(m.stamp, NaN) };
    return Number.isFinite(p.lat) && Number.isFinite(p.lon) && Number.isFinite(p.t) ? p : null;
  }

  /** The position topics among `names`, each with its vehicle's key and what its wildcards caught. */
  function positionTopics(names) {
    const out = [];
    if (!posPattern) {
      const n = posNames.find((x) => names.includes(x));
      if (n) out.push({ name: n, key: '', captured: [] });
      return out;
    }
    for (const n of names) {
      const m = posPattern.exec(n);
      if (m) out.push({ name: n, key: m.slice(1).filter((x) => x !== undefined).join('.'), captured: m.slice(1) });
    }
    return out.sort((a, b) => (a.key < b.key ? -1 : a.key > b.key ? 1 : 0));
  }

  /** The heading of the vehicle whose position wildcards caught `captured`. */
  function headingOf(captured) {
    if (!headB) return undefined;
    const topic = posPattern ? fillPattern(headB.topic, captured) : headB.topic;
    const h = valueOf(ctx, { topic, field: headB.field });
    return typeof h === 'number' && Number.isFinite(h) ? h : undefined;
  }

  const project = (p) => {
    const lat0 = origin.lat * Math.PI / 180;
    return [
      (p.lon - origin.lon) * Math.PI / 180 * EARTH_RADIUS * Math.cos(lat0),
      (p.lat - origin.lat) * Math.PI / 180 * EARTH_RADIUS,
    ];
  };

  function draw() {
    if (!dirty || !wrap.isConnected || !wrap.offsetParent) return;
    dirty = false;
    const W = Math.max(100, wrap.clientWidth), H = Math.max(100, wrap.clientHeight);
    s.setAttribute('viewBox', `0 0 ${W} ${H}`);
    s.replaceChildren();
    if (!origin) {
      s.append(svg('text', { x: W / 2, y: H / 2, 'text-anchor': 'middle', fill: '#7f9bb3', 'font-size': 13, text: 'waiting for a position' }));
      return;
    }
    const drawn = [...vehicles.entries()].map(([key, v]) => ({ key, v, pts: v.trail.map(project) }));
    const wps = waypoints.map(project);
    const all = drawn.flatMap((d) => d.pts).concat(wps);
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    for (const [x, y] of all) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
    if (!all.length) { x0 = x1 = y0 = y1 = 0; }
    const minSpan = 20;
    const cxm = (x0 + x1) / 2, cym = (y0 + y1) / 2;
    const spanX = Math.max(minSpan, x1 - x0), spanY = Math.max(minSpan, y1 - y0);
    const scale = Math.min((W - 40) / (spanX * 1.15), (H - 40) / (spanY * 1.15));
    const SX = (x) => W / 2 + (x - cxm) * scale;
    const SY = (y) => H / 2 - (y - cym) * scale;
    const left = cxm - W / 2 / scale, right = cxm + W / 2 / scale;
    const bottom = cym - H / 2 / scale, top = cym + H / 2 / scale;
    let step = num(gridAttr, NaN);
    const autoStep = niceStep(Math.max(right - left, top - bottom), 6);
    if (!(step > 0) || (right - left) / step > 60 || (top - bottom) / step > 60) step = autoStep;
    const grid = svg('g', { stroke: '#143452', 'stroke-width': 1 });
    // where the scale bar (bottom right) and the grid label (top left) go: no number there
    const barM = niceStep((W / 4) / scale, 1);
    const barPx = barM * scale;
    const bx = W - barPx - 14, by = H - 16;
    const textW = (t) => 6.2 * t.length;
    const labels = svg('g', { fill: '#56778f', 'font-size': 10, 'font-family': 'ui-monospace, monospace' });
    for (let x = Math.ceil(left / step) * step; x <= right; x += step) {
      const X = Math.round(SX(x)) + 0.5;
      grid.append(svg('line', { x1: X, y1: 0, x2: X, y2: H, stroke: Math.abs(x) < step / 1e6 ? '#24557c' : undefined }));
      const t = `${fmtValue(+x.toFixed(3))}`;
      if (X + 3 + textW(t) < bx - 8) labels.append(svg('text', { x: X + 3, y: H - 4, text: t }));
    }
    for (let y = Math.ceil(bottom / step) * step; y <= top; y += step) {
      const Y = Math.round(SY(y)) + 0.5;
      grid.append(svg('line', { x1: 0, y1: Y, x2: W, y2: Y, stroke: Math.abs(y) < step / 1e6 ? '#24557c' : undefined }));
      if (Y - 3 > 30 && Y - 3 < H - 18) labels.append(svg('text', { x: 3, y: Y - 3, text: `${fmtValue(+y.toFixed(3))}` }));
    }
    s.append(grid, labels);
    if (wps.length) {
      s.append(svg('polyline', {
        points: wps.map(([x, y]) => `${SX(x).toFixed(1)},${SY(y).toFixed(1)}`).join(' '),
        fill: 'none', stroke: '#f2b33d', 'stroke-width': 1.5, 'stroke-dasharray': '6 4', opacity: 0.8,
      }));
      wps.forEach(([x, y], i) => {
        s.append(svg('circle', { cx: SX(x), cy: SY(y), r: 6, fill: '#061422', stroke: '#f2b33d', 'stroke-width': 2 }));
        s.append(svg('text', { x: SX(x) + 9, y: SY(y) - 7, fill: '#f2b33d', 'font-size': 11, text: `WP${i + 1}` }));
      });
    }
    for (const { key, v, pts } of drawn) {
      if (pts.length > 1) {
        s.append(svg('polyline', {
          points: pts.map(([x, y]) => `${SX(x).toFixed(1)},${SY(y).toFixed(1)}`).join(' '),
          fill: 'none', stroke: v.colour, 'stroke-width': 2, 'stroke-linejoin': 'round', opacity: 0.9,
          'data-testid': 'trail', 'data-vehicle': key,
        }));
      }
      if (!pts.length) continue;
      const [x, y] = pts[pts.length - 1];
      const X = SX(x), Y = SY(y);
      if (typeof v.heading === 'number') {
        s.append(svg('path', {
          d: 'M0,-16 L9,10 L0,4 L-9,10 Z',
          transform: `translate(${X.toFixed(1)},${Y.toFixed(1)}) rotate(${v.heading.toFixed(1)})`,
          fill: '#ffffff', stroke: v.colour, 'stroke-width': 1.5, 'data-testid': 'heading-arrow', 'data-vehicle': key,
        }));
      } else {
        s.append(svg('circle', { cx: X, cy: Y, r: 6, fill: '#ffffff', stroke: v.colour, 'stroke-width': 2, 'data-vehicle': key }));
      }
      if (key) s.append(svg('text', { x: X + 12, y: Y + 4, fill: v.colour, 'font-size': 12, 'data-testid': 'vehicle-label', text: key }));
    }
    // scale bar
    s.append(svg('g', { 'data-testid': 'scale-bar' },
      svg('rect', { x: bx - 6, y: by - 18, width: barPx + 12, height: 26, rx: 4, fill: 'rgba(6,20,34,.75)' }),
      svg('path', { d: `M${bx},${by - 5} v5 h${barPx} v-5`, fill: 'none', stroke: '#d8e6f2', 'stroke-width': 2 }),
      svg('text', { x: bx + barPx / 2, y: by - 7, 'text-anchor': 'middle', fill: '#d8e6f2', 'font-size': 11, text: `${fmtValue(barM)} m` })));
    // north
    s.append(svg('g', { transform: `translate(${W - 20},22)` },
      svg('path', { d: 'M0,-12 L6,6 L0,2 L-6,6 Z', fill: '#d8e6f2' }),
      svg('text', { x: 0, y: 18, 'text-anchor': 'middle', fill: '#d8e6f2', 'font-size': 10, text: 'N' })));
    s.append(svg('text', { x: 6, y: 14, fill: '#56778f', 'font-size': 10, text: `grid ${fmtValue(step)} m` }));
  }

  /** The line under the map: one vehicle's place and heading, or how many vehicles are drawn. */
  function infoText() {
    if (posPattern) {
      const keys = [...vehicles.keys()].filter((k) => vehicles.get(k).trail.length);
      return keys.length ? `${keys.length} vehicle${keys.length === 1 ? '' : 's'}: ${keys.join(', ')}` : '';
    }
    const v = vehicles.get('');
    const cur = v && v.trail[v.trail.length - 1];
    const parts = [];
    if (cur) parts.push(`${cur.lat.toFixed(6)}, ${cur.lon.toFixed(6)}`);
    if (v && typeof v.heading === 'number') parts.push(`hdg ${fmtAngle(v.heading, 0)}°`);
    if (cur && origin) {
      const [x, y] = project(cur);
      parts.push(`${x >= 0 ? 'E' : 'W'} ${Math.abs(x).toFixed(0)} m  ${y >= 0 ? 'N' : 'S'} ${Math.abs(y).toFixed(0)} m from ${waypoints.length ? 'WP1' : 'start'}`);
    }
    return parts.join('   ');
  }

  // a single topic goes by its names; a pattern by every topic it matches
  const topicsList = [posPattern ? { matching: (n) => posPattern.test(n), pattern: posNames[0] } : posNames];
  return outputWidget(ctx, node, 'track', body, topicsList, {
    update() {
      for (const { name, key, captured } of positionTopics(Object.keys(ctx.allTopics()))) {
        const p = positionOf(ctx.topic(name));
        if (p) {
          if (!origin) origin = { lat: p.lat, lon: p.lon };
          addPositions(key, [p]);
        }
        const h = headingOf(captured);
        const v = vehicle(key);
        if (h !== v.heading) { v.heading = h; dirty = true; }
      }
      const txt = infoText();
      if (info.textContent !== txt) info.textContent = txt;
    },
    onBacklog(backlog) {
      for (const { name, key } of positionTopics(Object.keys(backlog))) {
        const list = Array.isArray(backlog[name]) ? backlog[name] : [];
        addPositions(key, list.map(positionOf).filter(Boolean).sort((a, b) => a.t - b.t));
      }
      // without waypoints the first trail's start is where distances are measured from
      const first = [...vehicles.values()].find((v) => v.trail.length);
      if (!waypoints.length && first) origin = { lat: first.trail[0].lat, lon: first.trail[0].lon };
      draw();
    },
    tick: () => draw(),
    redraw() { dirty = true; draw(); },
    drawn: () => Object.fromEntries([...vehicles.entries()].map(([k, v]) => [k, v.trail.length])),
  });
}

// ---------------------------------------------------------------- fleet

/** Where a fleet table finds each vehicle's values, under the vehicle's name, unless it says. */
const FLEET_COLUMNS = {
  mode: 'vehicle.state.mode',
  battery: 'power.battery.percent',
  severity: 'vehicle.health.severity',
  position: 'nav.position',
};

/**
 * Every vehicle of the fleet in one table: online (from the fleet's own topic), mode, battery,
 * severity, the age of its last position, who controls it, and a button that opens the layout
 * `open` for it (its name in variable `var`, default `vehicle`).
 */
function fleet(ctx, node) {
  const fleetTopic = node.bind || 'seabus.fleet';
  const at = (name) => parseBind(node[name] || FLEET_COLUMNS[name]);
  const cols = { mode: at('mode'), battery: at('battery'), severity: at('severity') };
  const position = String(node.position || FLEET_COLUMNS.position);
  const varName = node.var || 'vehicle';
  const tbody = el('tbody');
  const table = el('table', { class: 'tbl fleet-table', 'data-testid': 'fleet-table' },
    el('thead', {}, el('tr', {}, ['vehicle', 'online', 'mode', 'battery', 'severity', 'position', 'control', node.open ? '' : null]
      .filter((h) => h !== null).map((h) => el('th', { scope: 'col', text: h })))),
    tbody);
  const body = el('div', { class: 'scroll' }, table);
  if (!node.label) node = { ...node, label: 'Fleet' };
  let rows = [];

  /** The vehicles: those the fleet announces (the console's own node left out) and those heard. */
  function vehicles() {
    const t = ctx.topic(fleetTopic);
    const announced = t && t.fields && typeof t.fields === 'object' ? t.fields : {};
    const names = new Set(Object.keys(announced));
    const suffix = `.${position}`;
    for (const n of Object.keys(ctx.allTopics())) {
      if (n.endsWith(suffix) && !n.slice(0, -suffix.length).includes('.')) names.add(n.slice(0, -suffix.length));
    }
    names.delete(ctx.node() || '');
    return [...names].sort().map((name) => {
      const a = announced[name] && typeof announced[name] === 'object' ? announced[name] : null;
      const value = (b) => valueOf(ctx, b && { topic: `${name}.${b.topic}`, field: b.field });
      const pos = ctx.topic(`${name}.${position}`);
      return {
        name,
        online: a ? a.online === true : null,
        since: a ? num(a.since, NaN) : NaN,
        latency: a ? num(a.latency, NaN) : NaN,
        mode: value(cols.mode),
        battery: value(cols.battery),
        severity: value(cols.severity),
        positionAge: pos ? ctx.serverNow() - num(pos.stamp, NaN) : NaN,
        holder: ctx.leaseOf(name).holder,
      };
    });
  }

  /** A row's cells, made once per vehicle and updated in place (a button stays under the pointer). */
  const made = new Map();
  function rowOf(name) {
    let r = made.get(name);
    if (r) return r;
    const cell = (col) => el('td', { 'data-col': col });
    r = { tr: el('tr', { 'data-vehicle': name }), cells: {} };
    for (const col of ['vehicle', 'online', 'mode', 'battery', 'severity', 'position', 'control']) {
      r.cells[col] = cell(col);
      r.tr.append(r.cells[col]);
    }
    r.cells.vehicle.textContent = name;
    if (node.open) {
      const b = el('button', { type: 'button', class: 'btn', 'data-testid': 'fleet-open', text: 'Open' });
      b.addEventListener('click', () => ctx.openFor(node.open, { [varName]: name }));
      r.tr.append(el('td', { 'data-col': 'open' }, b));
    }
    made.set(name, r);
    return r;
  }

  /** Sets a cell's text, class and title when they changed. */
  function put(td, text, cls, title) {
    if (td.textContent !== text) td.textContent = text;
    if (td.className !== (cls || '')) td.className = cls || '';
    if ((td.title || '') !== (title || '')) td.title = title || '';
  }

  function render() {
    rows = vehicles();
    const names = new Set(rows.map((v) => v.name));
    for (const [name, r] of made) {
      if (!names.has(name)) { r.tr.remove(); made.delete(name); }
    }
    rows.forEach((v, i) => {
      const r = rowOf(v.name);
      const since = Number.isFinite(v.since) ? `since ${fmtTime(v.since)}` : '';
      const latency = Number.isFinite(v.latency) ? `, latency ${(v.latency * 1000).toFixed(0)} ms` : '';
      if (v.online === null) put(r.cells.online, '—', 'muted');
      else put(r.cells.online, v.online ? 'online' : 'OFFLINE', v.online ? 'yes' : 'no', since + latency);
      put(r.cells.mode, v.mode === undefined ? '—' : fmtValue(v.mode));
      put(r.cells.battery, typeof v.battery === 'number' ? `${v.battery.toFixed(0)} %` : '—');
      put(r.cells.severity, v.severity === undefined ? '—' : String(v.severity), v.severity ? `st-${v.severity}` : '');
      put(r.cells.position, Number.isFinite(v.positionAge) ? fmtAge(Math.max(0, v.positionAge)) : '—', v.positionAge > 5 ? 'st-UNAVAILABLE' : '');
      put(r.cells.control, v.holder ? (v.holder === ctx.S.user ? `you (${v.holder})` : v.holder) : 'free');
      r.tr.classList.toggle('is-offline', v.online === false);
      if (tbody.children[i] !== r.tr) tbody.insertBefore(r.tr, tbody.children[i] || null);
    });
  }

  const topicsList = [[fleetTopic]];
  return outputWidget(ctx, node, 'fleet', body, topicsList, {
    update: render,
    tick: render,
    onLease: render,
    drawn: () => rows.map((r) => ({ ...r })),
  });
}

// ---------------------------------------------------------------- health

function healthMap(ctx, node) {
  const names = node.bind ? topicNames(node.bind) : ['vehicle.health'];
  const b = parseBind(node.bind || 'vehicle.health');
  for (const n of names) {
    const t = ctx.topic(n);
    if (t && t.fields) return t.fields;
  }
  if (b && b.field) {
    const t = ctx.topic(b.topic);
    if (t && t.fields && t.fields[b.field] !== undefined) {
      const v = t.fields[b.field];
      return typeof v === 'object' && v !== null ? v : { value: v };
    }
  }
  return undefined;
}

function yesNo(v) {
  if (v === true) return el('span', { class: 'yes', text: 'yes' });
  if (v === false) return el('span', { class: 'no', text: 'NO' });
  if (v === undefined || v === null) return el('span', { class: 'muted', text: '—' });
  return el('span', { text: fmtValue(v) });
}

/** The sum of a map of counts (`{gps: 412, compass: 3}`), 0 for anything else. */
function countSum(o) {
  return o && typeof o === 'object' ? Object.values(o).reduce((a, v) => a + (Number(v) || 0), 0) : 0;
}

/** A count with its parts: `415 (gps 412, compass 3)`, or `0`. */
function countText(o) {
  const n = countSum(o);
  return n ? `${n} (${Object.entries(o).map(([k, v]) => `${k} ${v}`).join(', ')})` : '0';
}

/**
 * The health snapshot's `media` (the media that lost anything, each with its counters as the
 * runtime publishes them on `seabus.media`) as rows: messages its receivers' full queues dropped,
 * input rejected (by reason), bytes dropped, device overruns.
 */
function mediaRows(media) {
  const rows = [];
  if (!media || typeof media !== 'object' || Array.isArray(media)) return rows;
  for (const [name, c] of Object.entries(media)) {
    if (!c || typeof c !== 'object') continue;
    const lost = countSum(c.queue_dropped);
    rows.push(el('tr', { 'data-medium': name },
      el('td', { text: name }),
      el('td', { class: lost ? 'st-UNAVAILABLE' : '', text: countText(c.queue_dropped) }),
      el('td', { text: countText(c.rejected) }),
      el('td', { text: String(c.dropped_bytes ?? 0) }),
      el('td', { class: Number(c.overruns) ? 'st-UNAVAILABLE' : '', text: String(c.overruns ?? 0) })));
  }
  return rows;
}

function health(ctx, node) {
  const names = node.bind ? topicNames(node.bind) : ['vehicle.health'];
  const b = parseBind(node.bind || 'vehicle.health');
  const topics = b && b.field ? names.concat([b.topic]) : names;
  const sev = el('span', { class: 'health-severity', 'data-testid': 'severity', text: 'severity —' });
  const tbody = el('tbody');
  const table = el('table', { class: 'tbl' },
    el('thead', {}, el('tr', {}, ['component', 'online', 'healthy', 'data', 'state', 'why'].map((h) => el('th', { scope: 'col', text: h })))),
    tbody);
  // the media that lost anything: dropped for a receiver too slow, rejected, overrun
  const mediaBody = el('tbody');
  const mediaTable = el('table', { class: 'tbl health-media', 'data-testid': 'health-media', hidden: true },
    el('caption', { text: 'media with losses' }),
    el('thead', {}, el('tr', {}, ['medium', 'lost (queue full)', 'rejected', 'bytes dropped', 'overruns'].map((h) => el('th', { scope: 'col', text: h })))),
    mediaBody);
  const extra = el('div', { class: 'fields' });
  const body = el('div', { style: 'display:flex;flex-direction:column;gap:6px;flex:1;min-height:0' }, sev, el('div', { class: 'scroll' }, table, mediaTable, extra));
  if (!node.label) node = { ...node, label: 'Health' };
  let lastJson = '';
  return outputWidget(ctx, node, 'health', body, [topics], {
    update() {
      const m = healthMap(ctx, node);
      const j = JSON.stringify(m === undefined ? null : m);
      if (j === lastJson) return;
      lastJson = j;
      tbody.replaceChildren();
      extra.replaceChildren();
      mediaBody.replaceChildren(...mediaRows(m && m.media));
      mediaTable.hidden = mediaBody.children.length === 0;
      if (!m || typeof m !== 'object') return;
      const severity = m.severity !== undefined ? m.severity : m.Severity;
      const sevName = typeof severity === 'number' ? ['NONE', 'WARN', 'ABORT', 'EMERGENCY'][severity] || String(severity) : String(severity ?? '—');
      sev.textContent = `severity ${sevName}`;
      sev.className = `health-severity sev-${sevName.toUpperCase()}`;
      let comps = m.components !== undefined ? m.components : m.Components;
      // why each unhealthy component is so ("nav.position silent for 4.2 s")
      const reasons = m.reasons && typeof m.reasons === 'object' ? m.reasons : {};
      if (comps && typeof comps === 'object' && !Array.isArray(comps)) {
        for (const [name, c] of Object.entries(comps)) {
          let online, healthy, data, state;
          if (c && typeof c === 'object') {
            ({ online, healthy, data } = c);
            state = c.state !== undefined ? c.state : '';
            if (online === undefined && state) online = String(state).toUpperCase() !== 'OFFLINE';
            if (healthy === undefined && state) healthy = String(state).toUpperCase() === 'HEALTHY';
          } else {
            state = c;
            const st = String(c).toUpperCase();
            online = st !== 'OFFLINE';
            healthy = st === 'HEALTHY';
          }
          const stText = typeof state === 'object' ? fmtValue(state) : String(state ?? '');
          tbody.append(el('tr', { 'data-component': name },
            el('td', { text: name }), el('td', {}, yesNo(online)), el('td', {}, yesNo(healthy)), el('td', {}, yesNo(data)),
            el('td', { class: `st-${stText.toUpperCase()}`, text: stText }),
            el('td', { class: 'health-reason', 'data-testid': 'health-reason', text: reasons[name] !== undefined ? String(reasons[name]) : '' })));
        }
      } else if (comps !== undefined) {
        extra.append(el('div', { text: `components: ${fmtValue(comps)}` }));
      }
      for (const [k, v] of Object.entries(m)) {
        if (['severity', 'Severity', 'components', 'Components', 'reasons', 'media'].includes(k)) continue;
        if (k === 'unknown' && typeof v === 'number') {
          if (v > 0) {
            extra.append(el('div', {
              class: 'fields', 'data-testid': 'health-unknown',
              text: `${fmtValue(v)} ${v === 1 ? 'update' : 'updates'} from components the health rules do not name (not judged)`,
            }));
          }
          continue;
        }
        extra.append(el('div', { class: 'fields', text: `${k}: ${fmtValue(v)}` }));
      }
    },
  });
}

// ---------------------------------------------------------------- log

function logWidget(ctx, node) {
  const patterns = listAttr(node.topics !== undefined ? node.topics : 'cmd.status, vehicle.state');
  const res = patterns.map(globToRegExp);
  const maxLines = Math.max(1, Math.round(num(node.lines, 200)));
  const pre = el('div', { class: 'log-lines', 'data-testid': 'log-lines', role: 'log', 'aria-label': node.label || 'messages' });
  const seen = new Map();
  if (!node.label) node = { ...node, label: `Log ${patterns.join(', ')}` };
  const matching = () => Object.keys(ctx.allTopics()).filter((t) => res.some((r) => r.test(t)));
  const topicsList = patterns.filter((p) => !/[*?]/.test(p)).map((p) => [p]);
  return outputWidget(ctx, node, 'log', pre, topicsList.length ? topicsList : [], {
    update() {
      const atBottom = pre.scrollHeight - pre.scrollTop - pre.clientHeight < 30;
      let added = false;
      const names = matching().sort((a, b) => num(ctx.topic(a).stamp, 0) - num(ctx.topic(b).stamp, 0));
      for (const name of names) {
        const t = ctx.topic(name);
        if (seen.get(name) === t.stamp) continue;
        seen.set(name, t.stamp);
        pre.append(el('div', { class: 'line' },
          el('span', { class: 't', text: fmtTime(t.stamp, true) }), ' ',
          el('span', { class: 'tp', text: name }), ' ', fmtFields(t.fields)));
        added = true;
      }
      while (pre.childElementCount > maxLines) pre.firstElementChild.remove();
      if (added && atBottom) pre.scrollTop = pre.scrollHeight;
    },
  });
}

// ---------------------------------------------------------------- history

function history(ctx, node) {
  const lines = Math.max(1, Math.round(num(node.lines, 50)));
  const tbody = el('tbody');
  const table = el('table', { class: 'tbl' },
    el('thead', {}, el('tr', {}, ['time', 'user', 'command', 'state'].map((h) => el('th', { scope: 'col', text: h })))),
    tbody);
  if (!node.label) node = { ...node, label: 'Commands' };
  const e = frame(ctx, node, 'history', el('div', { class: 'scroll' }, table));
  e._status.hidden = true;
  function render() {
    const list = ctx.history().slice(-lines).reverse();
    tbody.replaceChildren(...list.map((c) => {
      const state = String(c.state || 'pending');
      return el('tr', { 'data-command-id': c.id, 'data-state': state },
        el('td', { text: fmtTime(c.time) }),
        el('td', { text: c.user || '' }),
        // the command with its fields (and why it was refused) below it, so that a narrow
        // history keeps its state column in sight
        el('td', { class: 'command' },
          el('div', { class: 'name', text: c.command || c.topic || '', title: c.topic || '' }),
          el('div', { class: 'fields', 'data-testid': 'history-fields', text: fmtFields(c.fields) }),
          c.reason ? el('div', { class: 'reason', text: c.reason }) : null),
        el('td', {}, el('span', { class: `state state-${state}`, text: state })));
    }));
    if (!list.length) tbody.append(el('tr', {}, el('td', { colspan: 4, class: 'muted', text: 'no commands yet' })));
  }
  const w = { node, el: e, update() {}, tick() {}, onHistory: render };
  ctx.register(w);
  render();
  return e;
}

// ---------------------------------------------------------------- inputs

/** `NAME.FIELD` (or an object) → {name, field}; a whole name that is a command has no field. */
export function parseCommandRef(ctx, x, fieldAttr) {
  if (!x) return null;
  if (typeof x === 'object') return { name: x.command || x.name, field: x.field ?? fieldAttr ?? null };
  const s = String(x).trim();
  if (fieldAttr) return { name: s, field: fieldAttr };
  if (ctx.command(s)) return { name: s, field: null };
  const i = s.lastIndexOf('.');
  if (i > 0) return { name: s.slice(0, i), field: s.slice(i + 1) };
  return { name: s, field: null };
}

function input(ctx, node, kind) {
  const ref = parseCommandRef(ctx, node.command, node.field);
  const cmd = ref && ctx.command(ref.name);
  if (!ref || !cmd) {
    if (!ctx.canCommandAny()) return null;
    return frame(ctx, { ...node, label: node.label || kind }, 'input', el('div', { class: 'unknown', text: `unknown command ${bindText(node.command) || ''}` }), 'widget-input');
  }
  const access = ctx.access(ref.name);
  if (access.hidden) return null;
  const label = node.label || (ref.field ? `${ref.name}.${ref.field}` : ref.name);
  const why = el('div', { class: 'why', 'data-testid': 'why' });
  const lim = ctx.limits(ref.name, ref.field);
  const min = num(node.min, lim.min);
  const max = num(node.max, lim.max);
  const step = num(node.step, undefined);
  let control, sync;
  // what the safe action does to the input while it is being changed
  let safeStop = null;
  const controls = [];

  if (kind === 'button') {
    const c = ctx.command(ref.name);
    const hold = c.confirm === 'hold';
    const fill = el('span', { class: 'fill' });
    const b = el('button', { type: 'button', class: `btn cmd-button${hold ? ' hold' : ''}${c.confirm === 'dialog' ? ' btn-danger' : ''}`, 'data-testid': 'command-button' },
      fill, el('span', { class: 'txt', text: node.label || ref.name }));
    controls.push(b);
    const setFields = () => {
      const set = parseFields(node.set);
      if (ref.field && node.value !== undefined) set[ref.field] = parseValue(node.value);
      return set;
    };
    if (hold) {
      b.title = `hold for ${(ctx.holdMs(ref.name) / 1000).toFixed(1)} s`;
      let h = null;
      const start = (ev) => {
        if (b.disabled || h) return;
        if (ev.type === 'pointerdown') { if (ev.button !== 0) return; b.setPointerCapture?.(ev.pointerId); }
        ev.preventDefault();
        b.classList.add('armed');
        h = ctx.hold(ref.name, setFields(), {
          progress(f) { fill.style.width = `${(f * 100).toFixed(1)}%`; },
          end() { h = null; b.classList.remove('armed'); fill.style.width = '0'; },
        });
      };
      const stop = () => { if (h) { h.cancel(); h = null; } };
      b.addEventListener('pointerdown', start);
      b.addEventListener('pointerup', stop);
      b.addEventListener('pointercancel', stop);
      b.addEventListener('lostpointercapture', stop);
      b.addEventListener('keydown', (ev) => { if ((ev.key === ' ' || ev.key === 'Enter') && !ev.repeat) start(ev); });
      b.addEventListener('keyup', (ev) => { if (ev.key === ' ' || ev.key === 'Enter') stop(); });
      b.addEventListener('blur', stop);
      b.addEventListener('contextmenu', (ev) => ev.preventDefault());
      b.setAttribute('aria-description', 'press and hold to send');
    } else {
      b.addEventListener('click', () => ctx.send(ref.name, setFields()));
    }
    control = b;
  } else if (kind === 'slider') {
    const r = el('input', { type: 'range', 'aria-label': label, 'data-testid': 'slider' });
    r.min = String(min ?? 0);
    r.max = String(max ?? 100);
    r.step = step !== undefined ? String(step) : 'any';
    const out = el('output', { class: 'input-value', 'data-testid': 'input-value' });
    let dragging = false;
    // a drag the safe action cut short: nothing goes when it is let go
    let abandoned = false;
    const show = () => { out.textContent = fmtValue(parseFloat(r.value), node.precision); };
    // the knob moves only when it is dragged (or by keys): a click on the track beside it would
    // send wherever the click landed
    r.addEventListener('pointerdown', (ev) => {
      abandoned = false;
      if (r.disabled || ev.button !== 0 || onKnob(r, ev)) return;
      ev.preventDefault();
      r.focus();
    });
    r.addEventListener('input', () => { dragging = true; show(); });
    r.addEventListener('change', () => {
      dragging = false;
      if (abandoned) { abandoned = false; sync(); return; }
      ctx.setAndSend(ref.name, ref.field, parseFloat(r.value));
    });
    safeStop = () => {
      abandoned = dragging;
      dragging = false;
      sync();
    };
    sync = () => {
      if (dragging) return;
      const v = ctx.fieldValue(ref.name, ref.field);
      if (typeof v === 'number') { r.value = String(v); show(); } else out.textContent = '—';
    };
    controls.push(r);
    control = [r, out];
  } else if (kind === 'number') {
    const n = el('input', { type: 'number', class: 'num-input', 'aria-label': label, 'data-testid': 'number', enterkeyhint: 'send' });
    if (min !== undefined) n.min = String(min);
    if (max !== undefined) n.max = String(max);
    n.step = step !== undefined ? String(step) : 'any';
    const go = el('button', { type: 'button', class: 'btn btn-small', text: 'Send' });
    const send = () => {
      const v = parseFloat(n.value);
      if (!Number.isFinite(v)) { n.setCustomValidity('a number'); n.reportValidity(); return; }
      if ((min !== undefined && v < min) || (max !== undefined && v > max)) {
        n.setCustomValidity(`between ${min ?? '−∞'} and ${max ?? '∞'}`); n.reportValidity(); return;
      }
      n.setCustomValidity('');
      ctx.setAndSend(ref.name, ref.field, v);
    };
    n.addEventListener('keydown', (ev) => { if (ev.key === 'Enter') { ev.preventDefault(); send(); } });
    n.addEventListener('input', () => n.setCustomValidity(''));
    go.addEventListener('click', send);
    sync = () => {
      if (document.activeElement === n) return;
      const v = ctx.fieldValue(ref.name, ref.field);
      if (v !== undefined) n.value = String(v);
    };
    controls.push(n, go);
    control = [n, go];
  } else if (kind === 'text') {
    const t = el('input', { type: 'text', class: 'text-input', 'aria-label': label, 'data-testid': 'text', enterkeyhint: 'send' });
    const go = el('button', { type: 'button', class: 'btn btn-small', text: 'Send' });
    const send = () => ctx.setAndSend(ref.name, ref.field, t.value);
    t.addEventListener('keydown', (ev) => { if (ev.key === 'Enter') { ev.preventDefault(); send(); } });
    go.addEventListener('click', send);
    sync = () => {
      if (document.activeElement === t) return;
      const v = ctx.fieldValue(ref.name, ref.field);
      if (v !== undefined) t.value = String(v);
    };
    controls.push(t, go);
    control = [t, go];
  } else if (kind === 'toggle') {
    const onV = node.on !== undefined ? parseValue(node.on) : true;
    const offV = node.off !== undefined ? parseValue(node.off) : false;
    const c = el('input', { type: 'checkbox', role: 'switch', 'aria-label': label, 'data-testid': 'toggle' });
    const state = el('span', { class: 'input-value', 'data-testid': 'input-value' });
    c.addEventListener('change', () => {
      const v = c.checked ? onV : offV;
      state.textContent = fmtOutput(SWITCH_WORDS, v);
      ctx.setAndSend(ref.name, ref.field, v);
    });
    sync = () => {
      const v = ctx.fieldValue(ref.name, ref.field);
      c.checked = v === onV || String(v) === String(onV);
      state.textContent = fmtOutput(SWITCH_WORDS, v);
    };
    controls.push(c);
    control = [el('label', { class: 'switch' }, c), state];
  }

  const e = frame(ctx, { ...node, label: kind === 'button' ? (c2label(ctx, ref)) : label }, 'input', [control, why].flat(), 'widget-input');
  e._status.hidden = true;
  e.dataset.command = ref.name;
  if (ref.field) e.dataset.field = ref.field;
  const w = {
    node, el: e,
    update() {},
    tick() {},
    onSafe() { if (safeStop) safeStop(); },
    permissions() {
      let a = ctx.access(ref.name);
      // a slider with no known value would send wherever the browser put its knob
      if (a.ok && kind === 'slider' && ref.field && ctx.fieldSource && ctx.fieldSource(ref.name, ref.field) === 'unknown') {
        a = { ok: false, why: 'no value yet: nothing commanded or measured' };
      }
      const dis = !a.ok;
      for (const c of controls) {
        c.disabled = dis;
        c.title = dis ? a.why : (c.title || '');
      }
      e.classList.toggle('disabled', dis);
      e.title = dis ? a.why : '';
      why.textContent = dis ? a.why : '';
      why.hidden = !dis;
    },
    sync() {
      if (sync) sync();
      if (kind === 'slider') w.permissions();
      if (!ref.field || !ctx.fieldSource) return;
      // where the value shown comes from; a field the pilot changed is marked until it is sent
      const src = ctx.fieldSource(ref.name, ref.field);
      e.dataset.source = src;
      e.classList.toggle('changed', src === 'changed');
      e.classList.toggle('no-value', src === 'unknown');
    },
  };
  ctx.register(w);
  w.permissions();
  w.sync();
  return e;
}

/** Whether a pointer event on range input `r` is on its knob (within the knob's width of where
 * the value puts it), rather than elsewhere on the track. */
function onKnob(r, ev) {
  const box = r.getBoundingClientRect();
  const min = parseFloat(r.min), max = parseFloat(r.max), v = parseFloat(r.value);
  const knob = 16; // Chromium's and Firefox's default knob, in CSS pixels
  const f = max > min && Number.isFinite(v) ? (v - min) / (max - min) : 0;
  const x = box.left + knob / 2 + f * (box.width - knob);
  return Math.abs(ev.clientX - x) <= knob;
}

function c2label(ctx, ref) {
  const c = ctx.command(ref.name);
  if (!c) return ref.name;
  const bits = [ref.name];
  if (c.confirm === 'hold') bits.push('hold to send');
  else if (c.confirm === 'dialog') bits.push('confirm');
  return bits.join(' · ');
}
