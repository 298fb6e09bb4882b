// The layout designer: edit mode, palette, attribute panel and saving back to XML.

import {
  el, bindText, parseBind, parseValue, parseDuration, parseRanges, parseWaypoints,
  nodeChildren, isContainer, OUTPUT_KINDS, INPUT_KINDS, CONTAINER_KINDS,
} from './widgets.js';

const ATTRS = {
  row: ['sizes'],
  column: ['sizes'],
  grid: ['columns'],
  tabs: [],
  tab: ['title', 'sizes'],
  readout: ['bind', 'unit', 'precision', 'angle', 'true', 'false', 'fresh'],
  gauge: ['bind', 'min', 'max', 'unit', 'ranges', 'precision', 'fresh'],
  plot: ['window', 'min', 'max', 'fresh'],
  track: ['position', 'heading', 'trail', 'waypoints', 'grid', 'fresh'],
  fleet: ['open', 'var', 'bind', 'mode', 'battery', 'severity', 'position', 'fresh'],
  health: ['bind', 'fresh'],
  log: ['topics', 'lines'],
  history: ['lines'],
  button: ['command', 'set'],
  slider: ['command', 'min', 'max', 'step'],
  number: ['command', 'min', 'max', 'step'],
  text: ['command'],
  toggle: ['command', 'on', 'off'],
};
const COMMON = ['id', 'label', 'role'];
const SERIES = ['bind', 'label', 'colour', 'unit', 'angle'];
const NUMERIC = new Set(['min', 'max', 'step', 'precision', 'columns', 'trail', 'lines']);
const TEXTUAL = new Set(['label', 'unit', 'title', 'role', 'command', 'set', 'ranges', 'waypoints', 'topics', 'position', 'on', 'off', 'grid', 'id', 'open', 'var', 'mode', 'battery', 'severity']);
const BINDS = new Set(['bind', 'heading']);

const clone = (x) => (x === undefined ? undefined : JSON.parse(JSON.stringify(x)));

function esc(s) {
  return String(s).replace(/&/g, '&amp;').replace(/</g, '&lt;').replace(/>/g, '&gt;').replace(/"/g, '&quot;').replace(/\n/g, '&#10;');
}

function scalar(v) {
  if (typeof v === 'boolean') return v ? 'true' : 'false';
  if (typeof v === 'number') return String(v);
  if (v === null || v === undefined) return '';
  if (typeof v === 'object' && typeof v.topic === 'string') return bindText(v);
  return String(v);
}

function fieldsText(f) {
  if (!f) return '';
  if (typeof f !== 'object') return String(f);
  return Object.entries(f).map(([k, v]) => `${k}=${scalar(v)}`).join(', ');
}

function ms(n) {
  if (n % 3600000 === 0 && n) return `${n / 3600000}h`;
  if (n % 60000 === 0 && n >= 60000) return `${n / 60000}m`;
  if (n % 1000 === 0) return `${n / 1000}s`;
  return `${n}ms`;
}

function autoId(node) {
  return typeof node.id === 'string' && new RegExp(`^${node.kind}-\\d+$`).test(node.id);
}

function attrsText(pairs) {
  return pairs.filter(([, v]) => v !== undefined && v !== null && v !== '').map(([k, v]) => ` ${k}="${esc(v)}"`).join('');
}

/** Attribute text of a node's attribute as written in XML. */
function attrValue(node, k) {
  const v = node[k];
  if (k === 'sizes') return Array.isArray(v) ? v.join(' ') : scalar(v);
  if (k === 'ranges') return Array.isArray(v) ? parseRanges(v).map((r) => `${r.from}:${r.to}:${r.colour || ''}`).join(', ') : scalar(v);
  if (k === 'waypoints') return Array.isArray(v) ? parseWaypoints(v).map((p) => `${p.lat},${p.lon}`).join('; ') : scalar(v);
  if (k === 'topics') return Array.isArray(v) ? v.join(', ') : scalar(v);
  if (k === 'set') return typeof v === 'object' && v ? fieldsText(v) : scalar(v);
  if (k === 'command' && node.field && typeof v === 'string') return `${v}.${node.field}`;
  if (k === 'command' && v && typeof v === 'object') return v.field ? `${v.command || v.name}.${v.field}` : (v.command || v.name);
  if (Array.isArray(v)) return v.map(scalar).join(', ');
  return scalar(v);
}

function nodeAttrPairs(node, freshDefault) {
  const pairs = [];
  for (const k of Object.keys(node)) {
    if (['kind', 'children', 'titles', 'series', 'field'].includes(k)) continue;
    if (k === 'id' && autoId(node)) continue;
    if (k === 'fresh_ms') {
      if (node.fresh_ms !== freshDefault) pairs.push(['fresh', ms(node.fresh_ms)]);
      continue;
    }
    if (k === 'window_ms') {
      if (node.window_ms !== 60000) pairs.push(['window', ms(node.window_ms)]);
      continue;
    }
    const v = node[k];
    if (v === undefined || v === null) continue;
    if (typeof v === 'object' && !Array.isArray(v) && typeof v.topic !== 'string' && k !== 'set' && k !== 'command') continue;
    pairs.push([k, attrValue(node, k)]);
  }
  return pairs;
}

function seriesXml(s, pad) {
  return `${pad}<series${attrsText(SERIES.map((k) => [k, k === 'colour' ? s.colour || s.color : scalar(s[k])]))}/>`;
}

function nodeXml(node, ind) {
  const pad = '  '.repeat(ind);
  const kind = node.kind;
  const attrs = attrsText(nodeAttrPairs(node, 2000));
  const kids = [];
  const children = nodeChildren(node);
  if (kind === 'tabs' && Array.isArray(node.titles) && children.some((c) => c.kind !== 'tab')) {
    children.forEach((c, i) => {
      if (c.kind === 'tab') kids.push(nodeXml(c, ind + 1));
      else kids.push(`${pad}  <tab${attrsText([['title', node.titles[i] || `Tab ${i + 1}`]])}>\n${nodeXml(c, ind + 2)}\n${pad}  </tab>`);
    });
  } else {
    for (const c of children) kids.push(nodeXml(c, ind + 1));
  }
  if (Array.isArray(node.series)) {
    for (const s of node.series) kids.push(seriesXml(s, `${pad}  `));
  }
  if (kind === 'series') return seriesXml(node, pad);
  if (!kids.length) return `${pad}<${kind}${attrs}/>`;
  return `${pad}<${kind}${attrs}>\n${kids.join('\n')}\n${pad}</${kind}>`;
}

/** The layout JSON written back as a layout document. */
export function layoutToXml(L, leaseRole) {
  const out = [];
  const roles = Array.isArray(L.roles) ? L.roles.join(' ') : L.roles;
  out.push(`<layout${attrsText([['name', L.name], ['title', L.title], ['roles', roles], ['vehicle', L.vehicle]])}>`);
  for (const [n, v] of Object.entries(L.vars || {})) out.push(`  <var${attrsText([['name', n], ['default', scalar(v)]])}/>`);
  const cmds = Object.entries(L.commands || {});
  if (Object.keys(L.vars || {}).length && cmds.length) out.push('');
  for (const [n, c] of cmds) {
    const p = [['name', n], ['topic', c.topic], ['fields', fieldsText(c.fields)]];
    if (c.role && c.role !== leaseRole) p.push(['role', c.role]);
    if (c.confirm && c.confirm !== 'none') p.push(['confirm', c.confirm]);
    if (c.confirm === 'hold' && c.hold_ms && c.hold_ms !== 1000) p.push(['hold', ms(c.hold_ms)]);
    if (c.rate_hz) p.push(['rate', `${c.rate_hz}Hz`]);
    if (c.neutral && (typeof c.neutral !== 'object' || Object.keys(c.neutral).length)) p.push(['neutral', fieldsText(c.neutral)]);
    if (c.frozen_ms && c.frozen_ms !== 1000) p.push(['frozen', ms(c.frozen_ms)]);
    if (c.lease === false) p.push(['lease', 'false']);
    for (const [f, v] of Object.entries(c.min || {})) p.push([`min.${f}`, scalar(v)]);
    for (const [f, v] of Object.entries(c.max || {})) p.push([`max.${f}`, scalar(v)]);
    out.push(`  <command${attrsText(p)}/>`);
  }
  if (L.root) {
    out.push('');
    out.push(nodeXml(L.root, 1));
  }
  const keys = Array.isArray(L.keys) ? L.keys : [];
  if (keys.length) {
    out.push('', '  <keys>');
    for (const k of keys) {
      out.push(`    <key${attrsText([['key', k.key], ['command', k.field ? `${k.command}.${k.field}` : k.command], ['value', scalar(k.value)], ['step', scalar(k.step)]])}/>`);
    }
    out.push('  </keys>');
  }
  const gp = L.gamepad || {};
  const axes = Array.isArray(gp.axes) ? gp.axes : [];
  const buttons = Array.isArray(gp.buttons) ? gp.buttons : [];
  if (axes.length || buttons.length) {
    out.push('', '  <gamepad>');
    for (const a of axes) {
      out.push(`    <axis${attrsText([['index', scalar(a.index)], ['command', a.field ? `${a.command}.${a.field}` : a.command],
        ['deadband', scalar(a.deadband)], ['expo', scalar(a.expo)], ['gain', scalar(a.gain)], ['offset', scalar(a.offset)]])}/>`);
    }
    for (const b of buttons) {
      out.push(`    <button${attrsText([['index', scalar(b.index)], ['command', b.field ? `${b.command}.${b.field}` : b.command], ['value', scalar(b.value)]])}/>`);
    }
    out.push('  </gamepad>');
  }
  out.push('</layout>', '');
  return out.join('\n');
}

// ---------------------------------------------------------------- the designer panel

export function createDesigner(ctx, panel, toggle) {
  let enabled = false;
  let editing = false;
  let working = null;
  let selected = null;
  let saving = false;
  let status = { text: '', kind: '' };
  let seq = 0;

  toggle.addEventListener('click', () => (editing ? stop() : start()));

  function start() {
    if (!enabled || !ctx.S.layout) return;
    working = clone(ctx.S.layout);
    selected = null;
    editing = true;
    status = { text: '', kind: '' };
    document.body.classList.add('editing');
    toggle.setAttribute('aria-pressed', 'true');
    toggle.textContent = 'Done';
    panel.hidden = false;
    renderPanel();
    ctx.rerender();
  }

  function stop() {
    if (!editing) return;
    editing = false;
    saving = false;
    selected = null;
    working = null;
    document.body.classList.remove('editing');
    toggle.setAttribute('aria-pressed', 'false');
    toggle.textContent = 'Edit';
    panel.hidden = true;
    ctx.rerender();
  }

  function changed() {
    renderPanel();
    ctx.rerender();
  }

  // ---------------------------------------------------------------- tree operations

  function parentOf(target, node = working.root, parent = null) {
    if (node === target) return parent;
    for (const c of nodeChildren(node)) {
      const p = parentOf(target, c, node);
      if (p !== undefined) return p;
    }
    return undefined;
  }

  function allIds(node = working.root, out = new Set()) {
    if (!node) return out;
    if (node.id !== undefined) out.add(String(node.id));
    for (const c of nodeChildren(node)) allIds(c, out);
    return out;
  }

  // ids of the `kind-N` form are left out of the XML (the server numbers widgets by place)
  function newId(kind) {
    const ids = allIds();
    let n = 1000 + seq++;
    while (ids.has(`${kind}-${n}`)) n++;
    return `${kind}-${n}`;
  }

  function defaults(kind) {
    const n = { kind, id: newId(kind) };
    switch (kind) {
      case 'row': case 'column': case 'tabs': case 'tab': n.children = []; break;
      case 'grid': n.columns = 2; n.children = []; break;
      case 'readout': n.bind = null; n.label = 'New readout'; break;
      case 'gauge': n.bind = null; n.min = 0; n.max = 100; break;
      case 'plot': n.children = []; break;
      case 'track': n.position = 'nav.position'; n.grid = 'auto'; break;
      case 'health': n.bind = { topic: 'vehicle', field: 'health' }; break;
      case 'log': n.topics = 'cmd.status, vehicle.state'; break;
      case 'history': break;
      default: {
        const first = Object.keys(ctx.S.layout.commands || {})[0] || '';
        const fields = first ? Object.keys((ctx.S.layout.commands[first] || {}).fields || {}) : [];
        n.command = kind === 'button' || !fields.length ? first : `${first}.${fields[0]}`;
        n.label = `New ${kind}`;
      }
    }
    if (n.bind === null) delete n.bind;
    return n;
  }

  function add(kind) {
    const n = defaults(kind);
    if (kind === 'tab') {
      const host = selected && selected.kind === 'tabs' ? selected : null;
      if (!host) { status = { text: 'select a <tabs> to add a tab to it', kind: 'error' }; renderPanel(); return; }
    }
    if (!working.root) working.root = { kind: 'column', id: newId('column'), children: [] };
    if (selected && isContainer(selected)) {
      selected.children = nodeChildren(selected).concat([n]);
      if (Array.isArray(selected.sizes)) selected.sizes.push(1);
    } else if (selected && parentOf(selected)) {
      const p = parentOf(selected);
      const i = p.children.indexOf(selected);
      p.children.splice(i + 1, 0, n);
      if (Array.isArray(p.sizes)) p.sizes.splice(i + 1, 0, 1);
      if (Array.isArray(p.titles)) p.titles.splice(i + 1, 0, 'New tab');
    } else if (isContainer(working.root)) {
      working.root.children = nodeChildren(working.root).concat([n]);
      if (Array.isArray(working.root.sizes)) working.root.sizes.push(1);
    } else {
      working.root = { kind: 'column', id: newId('column'), children: [working.root, n] };
    }
    if (working.root.kind === 'tabs' && Array.isArray(working.root.titles)) {
      while (working.root.titles.length < working.root.children.length) working.root.titles.push('New tab');
    }
    selected = n;
    status = { text: `added ${kind}`, kind: 'ok' };
    changed();
  }

  function move(d) {
    const p = selected && parentOf(selected);
    if (!p) return;
    const i = p.children.indexOf(selected);
    const j = i + d;
    if (j < 0 || j >= p.children.length) return;
    for (const arr of [p.children, p.sizes, p.titles]) {
      if (Array.isArray(arr) && arr.length > Math.max(i, j)) [arr[i], arr[j]] = [arr[j], arr[i]];
    }
    changed();
  }

  function moveOut() {
    const p = selected && parentOf(selected);
    const gp = p && parentOf(p);
    if (!gp) return;
    removeFrom(p, selected);
    const k = gp.children.indexOf(p);
    gp.children.splice(k + 1, 0, selected);
    if (Array.isArray(gp.sizes)) gp.sizes.splice(k + 1, 0, 1);
    if (Array.isArray(gp.titles)) gp.titles.splice(k + 1, 0, 'New tab');
    changed();
  }

  function moveInto(target) {
    if (!selected || !target || target === selected || contains(selected, target)) return;
    const p = parentOf(selected);
    if (!p) return;
    removeFrom(p, selected);
    target.children = nodeChildren(target).concat([selected]);
    if (Array.isArray(target.sizes)) target.sizes.push(1);
    if (Array.isArray(target.titles)) target.titles.push('New tab');
    changed();
  }

  function contains(a, b) {
    if (a === b) return true;
    return nodeChildren(a).some((c) => contains(c, b));
  }

  function removeFrom(p, n) {
    const i = p.children.indexOf(n);
    if (i < 0) return;
    p.children.splice(i, 1);
    for (const arr of [p.sizes, p.titles]) if (Array.isArray(arr) && arr.length > i) arr.splice(i, 1);
  }

  function del() {
    if (!selected) return;
    const p = parentOf(selected);
    if (!p) { status = { text: 'the root cannot be deleted', kind: 'error' }; renderPanel(); return; }
    removeFrom(p, selected);
    selected = p;
    changed();
  }

  function containers(node = working.root, out = []) {
    if (!node) return out;
    if (isContainer(node)) out.push(node);
    for (const c of nodeChildren(node)) containers(c, out);
    return out;
  }

  // ---------------------------------------------------------------- attributes

  function attrShown(node, k) {
    if (k === 'fresh') return node.fresh_ms !== undefined ? ms(node.fresh_ms) : scalar(node.fresh);
    if (k === 'window') return node.window_ms !== undefined ? ms(node.window_ms) : scalar(node.window);
    if (node[k] === undefined || node[k] === null) return '';
    return attrValue(node, k);
  }

  function setAttr(node, k, text) {
    const t = text.trim();
    if (k === 'fresh' || k === 'window') {
      const key = `${k}_ms`;
      delete node[k];
      if (!t) delete node[key];
      else node[key] = parseDuration(t, 1000, undefined);
      if (node[key] === undefined) { delete node[key]; if (t) node[k] = t; }
    } else if (!t) {
      delete node[k];
    } else if (BINDS.has(k)) {
      node[k] = parseBind(t);
    } else if (k === 'sizes') {
      node[k] = t.split(/[\s,]+/).map(Number).filter((x) => Number.isFinite(x));
    } else if (k === 'command') {
      node.command = t;
      delete node.field;
    } else if (NUMERIC.has(k)) {
      const v = parseValue(t);
      node[k] = typeof v === 'number' ? v : t;
    } else if (TEXTUAL.has(k)) {
      node[k] = t;
    } else {
      node[k] = parseValue(t);
    }
    status = { text: '', kind: '' };
    ctx.rerender();
    xmlView && (xmlView.textContent = layoutToXml(working, ctx.S.leaseRole));
  }

  let xmlView = null;

  function attrRow(node, k, list) {
    const id = `attr-${k.replace(/\W/g, '_')}`;
    const input = el('input', { id, type: 'text', value: attrShown(node, k), 'data-attr': k, spellcheck: 'false', autocomplete: 'off' });
    if (k === 'bind' || k === 'heading') input.placeholder = 'topic.field';
    if (k === 'command') input.placeholder = 'NAME.FIELD';
    input.addEventListener('change', () => {
      if (k === 'id' && input.value.trim() && allIds().has(input.value.trim()) && input.value.trim() !== String(node.id)) {
        status = { text: `id ${input.value.trim()} is taken`, kind: 'error' };
        renderPanel();
        return;
      }
      setAttr(node, k, input.value);
    });
    list.append(el('label', { for: id, text: k }), input);
  }

  function seriesEditor(node) {
    const box = el('div', {});
    const list = Array.isArray(node.series) ? node.series : null;
    const items = list || nodeChildren(node).filter((c) => c.kind === 'series');
    items.forEach((s, i) => {
      const grid = el('div', { class: 'attr-list' });
      for (const k of SERIES) {
        const id = `series-${i}-${k}`;
        const input = el('input', { id, type: 'text', value: k === 'colour' ? s.colour || s.color || '' : scalar(s[k]) });
        input.addEventListener('change', () => {
          const t = input.value.trim();
          if (!t) delete s[k];
          else s[k] = k === 'bind' ? parseBind(t) : t;
          ctx.rerender();
        });
        grid.append(el('label', { for: id, text: k }), input);
      }
      const rm = el('button', { type: 'button', class: 'btn btn-small', text: `remove series ${i + 1}` });
      rm.addEventListener('click', () => {
        if (list) list.splice(i, 1);
        else node.children.splice(node.children.indexOf(s), 1);
        changed();
      });
      box.append(el('h2', { text: `series ${i + 1}` }), grid, rm);
    });
    const addB = el('button', { type: 'button', class: 'btn btn-small', text: 'add series', 'data-testid': 'add-series' });
    addB.addEventListener('click', () => {
      const s = { kind: 'series', bind: { topic: 'nav.depth', field: 'depth' }, label: 'new series' };
      if (list) { delete s.kind; list.push(s); } else node.children = nodeChildren(node).concat([s]);
      changed();
    });
    box.append(addB);
    return box;
  }

  // ---------------------------------------------------------------- panel

  function renderPanel() {
    if (!editing) return;
    const parts = [];
    parts.push(el('div', {},
      el('h2', { text: `Designing ${working.name}` }),
      el('p', { class: 'hint', text: 'Click a widget or container to select it. New widgets go into the selected container, or after the selected widget.' })));

    const pal = el('div', { class: 'palette', role: 'group', 'aria-label': 'Add a widget' });
    for (const k of [...OUTPUT_KINDS, ...INPUT_KINDS, ...CONTAINER_KINDS]) {
      const b = el('button', { type: 'button', class: 'btn', text: `+ ${k}`, 'data-testid': `add-${k}` });
      b.addEventListener('click', () => add(k));
      pal.append(b);
    }
    parts.push(el('div', {}, el('h2', { text: 'Palette' }), pal));

    if (selected) {
      const n = selected;
      const list = el('div', { class: 'attr-list', 'data-testid': 'attributes' });
      const keys = [...COMMON, ...(ATTRS[n.kind] || [])];
      for (const k of Object.keys(n)) {
        if (['kind', 'children', 'titles', 'series', 'field', 'fresh_ms', 'window_ms'].includes(k)) continue;
        if (!keys.includes(k)) keys.push(k);
      }
      for (const k of keys) attrRow(n, k, list);
      const tools = el('div', { class: 'tools' });
      const tool = (text, fn, testid) => {
        const b = el('button', { type: 'button', class: 'btn btn-small', text, 'data-testid': testid });
        b.addEventListener('click', fn);
        tools.append(b);
      };
      tool('▲ up', () => move(-1), 'move-up');
      tool('▼ down', () => move(1), 'move-down');
      tool('⇱ out of container', moveOut, 'move-out');
      tool('✕ delete', del, 'delete');
      tool('deselect', () => { selected = null; changed(); }, 'deselect');
      const into = el('select', { 'aria-label': 'Move into container', 'data-testid': 'move-into' });
      into.append(el('option', { value: '', text: 'move into…' }));
      const cs = containers().filter((c) => c !== n && !contains(n, c));
      cs.forEach((c, i) => into.append(el('option', { value: String(i), text: `${c.kind} ${c.id ?? ''}` })));
      into.addEventListener('change', () => { if (into.value !== '') moveInto(cs[Number(into.value)]); });
      tools.append(into);
      parts.push(el('div', {}, el('h2', { text: `Selected: <${n.kind}> ${n.id ?? ''}` }), list));
      if (n.kind === 'tabs' && Array.isArray(n.titles)) {
        const tl = el('div', { class: 'attr-list' });
        n.children.forEach((c, i) => {
          const id = `tab-title-${i}`;
          const input = el('input', { id, type: 'text', value: n.titles[i] || '' });
          input.addEventListener('change', () => { n.titles[i] = input.value; ctx.rerender(); });
          tl.append(el('label', { for: id, text: `tab ${i + 1}` }), input);
        });
        parts.push(el('div', {}, el('h2', { text: 'Tab titles' }), tl));
      }
      if (n.kind === 'plot') parts.push(seriesEditor(n));
      parts.push(tools);
    } else {
      parts.push(el('p', { class: 'hint', text: 'Nothing selected.' }));
    }

    const save = el('button', { type: 'button', class: 'btn btn-primary', text: saving ? 'Saving…' : 'Save layout', 'data-testid': 'save-layout' });
    save.disabled = saving;
    save.addEventListener('click', doSave);
    const revert = el('button', { type: 'button', class: 'btn', text: 'Discard changes', 'data-testid': 'discard' });
    revert.addEventListener('click', () => { working = clone(ctx.S.layout); selected = null; status = { text: 'changes discarded', kind: 'ok' }; changed(); });
    const st = el('div', { class: `save-status ${status.kind}`, 'data-testid': 'save-status', role: 'status', text: status.text });
    parts.push(el('div', { class: 'tools' }, save, revert), st);

    xmlView = el('pre', { class: 'log-lines', 'data-testid': 'xml-preview' }, layoutToXml(working, ctx.S.leaseRole));
    parts.push(el('details', {}, el('summary', { text: 'XML' }), xmlView));
    panel.replaceChildren(...parts);
  }

  function doSave() {
    if (saving) return;
    const xml = layoutToXml(working, ctx.S.leaseRole);
    if (!ctx.sendMsg({ type: 'save', layout: working.name, xml })) {
      status = { text: 'not connected', kind: 'error' };
      renderPanel();
      return;
    }
    saving = true;
    status = { text: 'saving…', kind: '' };
    renderPanel();
  }

  return {
    enable(on) {
      enabled = !!on;
      toggle.hidden = !enabled;
      if (!enabled) stop();
    },
    editing: () => editing,
    saving: () => saving,
    tree: () => working && working.root,
    stop,
    nodeElement(e, node) {
      if (!editing) return;
      if (node === selected) e.classList.add('selected');
      e.addEventListener('click', (ev) => {
        if (ev.target instanceof Element && ev.target.closest('.tab-bar')) return;
        ev.stopPropagation();
        ev.preventDefault();
        selected = node;
        status = { text: '', kind: '' };
        changed();
      });
    },
    loaded(L) {
      if (!editing) return;
      if (saving) {
        saving = false;
        working = clone(L);
        selected = null;
        status = { text: `saved ${L.name} at ${new Date().toLocaleTimeString()}`, kind: 'ok' };
        renderPanel();
      } else if (working && L.name !== working.name) {
        stop();
      }
    },
    saveResult(e) {
      if (!saving) return;
      saving = false;
      const where = [e.file, e.line, e.col].filter((x) => x !== undefined && x !== null && x !== '').join(':');
      status = { text: `not saved: ${where ? where + ': ' : ''}${e.message || 'error'}`, kind: 'error' };
      renderPanel();
    },
  };
}
