// The operator console: connection, header, layout, commands and control.

import { el, renderNode, fmtFields, fmtTime, fmtValue, parseBind } from './widgets.js';
import { createInputs } from './inputs.js';
import { createDesigner } from './designer.js';

const HOLD_MARGIN_MS = 100; // a held command is sent a little after its hold time, never before
const PENDING_MS = 3000; // a value sent shows until the bus has it, or this long
const MEASURED_FRESH_S = 5; // an older measurement is not a current value (as on the server)
const ARM_TIMEOUT_MS = 5000;

// what the page's content policy blocked (an inline style or script, another origin): counted, so
// that a page the policy breaks is seen, not silently half-drawn
const policyViolations = [];
document.addEventListener('securitypolicyviolation', (e) => {
  policyViolations.push(`${e.violatedDirective}: ${e.blockedURI || 'inline'}`);
});

if (document.body.classList.contains('login-page')) loginPage();
else consolePage();

function loginPage() {
  const params = new URLSearchParams(location.search);
  const error = params.get('error');
  const box = document.getElementById('login-error');
  if (error && box) {
    box.textContent = error;
    box.hidden = false;
  }
  const name = params.get('name');
  if (name) {
    document.getElementById('name').value = name;
    document.getElementById('password').focus();
  }
}

function consolePage() {
  const $ = (id) => document.getElementById(id);
  const ui = {
    root: $('layout-root'), banner: $('banner'), notice: $('notice'),
    select: $('layout-select'), title: $('layout-title'),
    holder: $('lease-holder'), take: $('take-control'), release: $('release-control'),
    controlLabel: $('control-label'),
    conn: $('connection'), userName: $('user-name'), userRoles: $('user-roles'),
    edit: $('edit-toggle'), designer: $('designer'), toasts: $('toasts'),
    dialog: $('confirm-dialog'), dialogTitle: $('confirm-title'), dialogText: $('confirm-text'), dialogFields: $('confirm-fields'),
    holdBox: $('hold-indicator'), kept: $('kept'), stop: $('header-stop'),
  };

  const S = {
    conn: 'connecting',
    user: null, roles: [], layouts: [],
    leaseRole: 'pilot', designerRole: 'designer',
    // the control of the layout's vehicle (or the console's one control), and every vehicle's
    // by name ('' for the console's one)
    lease: { holder: null, session: null, since: null },
    // this page's log-in (control is held by one log-in) and the console's origin on the bus
    session: null, origin: null,
    // who commanded each topic's last values, and since when: {TOPIC: {by, since}}
    commandedBy: {},
    leases: {},
    node: null,
    layoutName: null, layout: null, layoutError: null,
    producers: {}, topics: {}, now: undefined, nowAt: 0,
    // fields: the values the pilot changed and has not sent yet, by command; pending: sent, not
    // yet seen commanded; commanded: the values last commanded, by topic; chosen: the fields the
    // layout's controls let the pilot choose, by command; kept: commands the console keeps, by topic
    fields: {}, pending: {}, commanded: {}, chosen: {}, kept: {}, history: [],
    sentCount: 0, driveCount: 0, releaseCount: 0, lastSent: null, sent: [],
    helloSeen: false,
  };
  let ws = null;
  let attempt = 0;
  let reconnectTimer = null;
  let widgets = [];
  const pendingArms = [];
  const uiState = new Map();

  // ------------------------------------------------------------ context for the widgets

  const ctx = {
    S,
    uiState,
    hasRole: (r) => String(r).split(/\s+/).filter(Boolean).some((x) => S.roles.includes(x)),
    register(w) { widgets.push(w); },
    nodeElement(e, node) { designer.nodeElement(e, node); },
    redrawSoon() { setTimeout(() => widgets.forEach((w) => w.redraw && w.redraw()), 0); },
    topic: (n) => S.topics[n],
    allTopics: () => S.topics,
    producer(n) {
      const p = S.producers[n];
      return p === undefined ? undefined : !!p;
    },
    serverNow() {
      if (S.now === undefined) return Date.now() / 1000;
      return S.now + (performance.now() - S.nowAt) / 1000;
    },
    history: () => S.history,
    /** Who controls `vehicle` ('' for the console's one control): {holder, since}. */
    leaseOf: (vehicle) => S.leases[vehicle || ''] || { holder: null, session: null, since: null },
    /** Whether this log-in holds the open layout's control (not another log-in of the user). */
    inControl: () => inControl(S.lease),
    /** The node the console runs on (a fleet table leaves it out). */
    node: () => S.node,
    /** Opens layout `name` for `vars` (a fleet table's vehicle): the page's address says which. */
    openFor(name, vars) {
      const params = new URLSearchParams();
      for (const [k, v] of Object.entries(vars || {})) params.set(k, v);
      history.replaceState(null, '', `${location.pathname}?${params}`);
      openLayout(name, true);
    },
    command: (n) => (S.layout && S.layout.commands && Object.prototype.hasOwnProperty.call(S.layout.commands, n) ? S.layout.commands[n] : null),
    commandRole(n) {
      const c = ctx.command(n);
      return (c && c.role) || S.leaseRole;
    },
    canCommandAny() {
      const cmds = (S.layout && S.layout.commands) || {};
      return Object.keys(cmds).some((n) => ctx.hasRole(ctx.commandRole(n)));
    },
    access(n) {
      const c = ctx.command(n);
      if (!c) return { ok: false, why: `unknown command ${n}`, hidden: false };
      if (!ctx.canCommandAny()) return { ok: false, why: 'observer', hidden: true };
      const role = ctx.commandRole(n);
      if (!ctx.hasRole(role)) return { ok: false, why: `needs role ${role}`, hidden: false };
      if (c.lease !== false && !inControl(S.lease)) {
        const why = S.lease.holder && S.lease.holder === S.user ? 'you have control in another log-in' : 'take control first';
        return { ok: false, why, hidden: false };
      }
      if (S.conn !== 'connected') return { ok: false, why: 'disconnected', hidden: false };
      return { ok: true, why: '', hidden: false };
    },
    limits(n, f) {
      const c = ctx.command(n);
      const lim = { min: undefined, max: undefined };
      if (!c || !f) return lim;
      if (c.min && typeof c.min[f] === 'number') lim.min = c.min[f];
      if (c.max && typeof c.max[f] === 'number') lim.max = c.max[f];
      return lim;
    },
    holdMs(n) {
      const c = ctx.command(n);
      const h = c && Number(c.hold_ms);
      return Number.isFinite(h) && h > 0 ? h : 1000;
    },
    fieldValue(n, f) { return fieldValue(n, f).value; },
    /** Where a field's value comes from: changed, sending, measured, commanded, layout or unknown. */
    fieldSource(n, f) { return fieldValue(n, f).source; },
    fields(n) { return { ...(S.fields[n] || {}) }; },
    setFields(n, set) {
      S.fields[n] = { ...(S.fields[n] || {}), ...set };
      syncInputs();
    },
    clearFields(n) {
      delete S.fields[n];
      syncInputs();
    },
    clamp(n, f, v) {
      if (typeof v !== 'number') return v;
      const { min, max } = ctx.limits(n, f);
      if (min !== undefined && v < min) v = min;
      if (max !== undefined && v > max) v = max;
      return v;
    },
    send: sendCommand,
    setAndSend(n, f, v) { return sendCommand(n, f ? { [f]: v } : {}); },
    /** The layout's safe action (a command marked `safe`, the stop), or null. */
    safeCommand,
    sendSafe,
    hold: holdCommand,
    sendMsg,
    toast,
    layoutName: () => (S.layout ? S.layout.name : S.layoutName),
    rerender: renderLayout,
  };

  const inputs = createInputs(ctx);
  const designer = createDesigner(ctx, ui.designer, ui.edit);
  ctx.inputs = inputs;
  ctx.designer = designer;

  // ------------------------------------------------------------ socket

  function wsUrl() {
    return `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`;
  }

  function connect() {
    clearTimeout(reconnectTimer);
    setConn('connecting');
    let gotHello = false;
    try {
      ws = new WebSocket(wsUrl());
    } catch (e) {
      scheduleReconnect(false);
      return;
    }
    const sock = ws;
    sock.onopen = () => { if (sock === ws) setConn('connected'); };
    sock.onmessage = (ev) => {
      if (sock !== ws) return;
      let m;
      try { m = JSON.parse(ev.data); } catch (e) { return; }
      if (m && m.type === 'hello') gotHello = true;
      try { handle(m); } catch (e) { console.error('message', m && m.type, e); }
    };
    sock.onclose = () => {
      if (sock !== ws) return;
      ws = null;
      lostConnection();
      scheduleReconnect(gotHello);
    };
    sock.onerror = () => {};
  }

  function scheduleReconnect(hadHello) {
    if (hadHello) attempt = 0;
    const delay = Math.min(10000, 500 * Math.pow(2, attempt)) * (0.8 + Math.random() * 0.4);
    attempt = Math.min(attempt + 1, 10);
    const until = Date.now() + delay;
    setConn('disconnected', until);
    reconnectTimer = setTimeout(connect, delay);
    if (!hadHello && attempt >= 2) checkSession();
  }

  async function checkSession() {
    try {
      const r = await fetch('/', { redirect: 'manual', cache: 'no-store', credentials: 'same-origin' });
      if (r.type === 'opaqueredirect' || (r.redirected && /\/login/.test(r.url))) location.href = '/login';
    } catch (e) { /* the server is away: keep retrying */ }
  }

  function lostConnection() {
    inputs.stopAll(false);
    while (pendingArms.length) {
      const p = pendingArms.shift();
      clearTimeout(p.timer);
      p.reject(new Error('disconnected'));
    }
    updatePermissions();
  }

  function setConn(state, until) {
    S.conn = state;
    ui.conn.dataset.state = state;
    if (state === 'connected') ui.conn.textContent = 'connected';
    else if (state === 'connecting') ui.conn.textContent = 'connecting…';
    else {
      const left = until ? Math.max(0, Math.round((until - Date.now()) / 1000)) : 0;
      ui.conn.textContent = left ? `disconnected · retry in ${left}s` : 'disconnected';
      ui.conn.dataset.until = until || '';
    }
  }
  setInterval(() => {
    if (S.conn === 'disconnected' && ui.conn.dataset.until) setConn('disconnected', Number(ui.conn.dataset.until));
  }, 1000);

  function sendMsg(m) {
    if (!ws || ws.readyState !== WebSocket.OPEN) return false;
    ws.send(JSON.stringify(m));
    S.sentCount++;
    if (m.type === 'drive') S.driveCount++;
    if (m.type === 'release') S.releaseCount++;
    S.lastSent = m;
    S.sent.push(m);
    if (S.sent.length > 200) S.sent.shift();
    return true;
  }

  // ------------------------------------------------------------ messages

  function handle(m) {
    switch (m && m.type) {
      case 'hello': return onHello(m);
      case 'layout': return onLayout(m);
      case 'data': return onData(m);
      case 'lease': return onLease(m);
      case 'leases': return onLeases(m);
      case 'command': return onCommand(m);
      case 'history': return onHistory(m);
      case 'backlog': return onBacklog(m);
      case 'commanded': return onCommanded(m);
      case 'kept': return onKept(m);
      case 'armed': return onArmed(m);
      case 'error': return onError(m);
      default: return undefined;
    }
  }

  function onHello(m) {
    attempt = 0;
    S.helloSeen = true;
    S.user = m.user || null;
    S.session = m.session ?? null;
    S.origin = m.origin || null;
    S.roles = Array.isArray(m.roles) ? m.roles.map(String) : String(m.roles || '').split(/\s+/).filter(Boolean);
    if (m.lease_role) S.leaseRole = String(m.lease_role);
    if (m.designer_role) S.designerRole = String(m.designer_role);
    S.layouts = (Array.isArray(m.layouts) ? m.layouts : []).map((l) => (typeof l === 'string' ? { name: l, title: l } : { name: l.name, title: l.title || l.name }));
    S.node = m.node || null;
    S.leases = {};
    for (const l of Array.isArray(m.leases) ? m.leases : []) rememberLease(l);
    rememberLease(m.lease);
    setLease(ctx.leaseOf(layoutVehicle()));
    ui.userName.textContent = S.user || '';
    ui.userRoles.textContent = S.roles.length ? S.roles.join(' · ') : 'observer';
    ui.select.replaceChildren(...S.layouts.map((l) => el('option', { value: l.name, text: l.title && l.title !== l.name ? `${l.title}` : l.name })));
    ui.select.disabled = S.layouts.length < 2;
    designer.enable(S.roles.includes(S.designerRole));
    const params = new URLSearchParams(location.search);
    const want = params.get('layout');
    const names = S.layouts.map((l) => l.name);
    let pick = names.includes(want) ? want : names.includes(S.layoutName) ? S.layoutName : names[0];
    if (!pick) {
      S.layout = null;
      S.layoutName = null;
      ui.root.replaceChildren(el('p', { class: 'placeholder', text: 'No layout for your roles.' }));
      return;
    }
    openLayout(pick, false);
  }

  function queryVars() {
    const vars = {};
    for (const [k, v] of new URLSearchParams(location.search)) if (k !== 'layout') vars[k] = v;
    return vars;
  }

  function openLayout(name, userChoice) {
    S.layoutName = name;
    ui.select.value = name;
    if (userChoice) {
      const params = new URLSearchParams(location.search);
      params.set('layout', name);
      history.replaceState(null, '', `${location.pathname}?${params}`);
      designer.stop();
    }
    sendMsg({ type: 'open', layout: name, vars: queryVars() });
  }

  function onLayout(m) {
    if (m.error) {
      const e = typeof m.error === 'object' ? m.error : { message: String(m.error) };
      S.layoutError = e;
      showLayoutError(e);
      if (designer.saving()) {
        designer.saveResult(e);
        return;
      }
      designer.stop();
      S.layout = null;
      widgets = [];
      inputs.attach(null);
      ui.title.textContent = `${S.layoutName || ''} — not loaded`;
      ui.root.replaceChildren(el('p', { class: 'placeholder', text: 'The layout did not load.' }));
      return;
    }
    const L = m.layout;
    if (!L || typeof L !== 'object') return;
    const same = S.layout && S.layout.name === L.name;
    S.layoutError = null;
    hideBanner();
    S.layout = L;
    S.layoutName = L.name || S.layoutName;
    S.producers = normaliseProducers(m.producers);
    // values changed and not sent do not outlive the page's view of the layout
    S.fields = {};
    S.pending = {};
    S.chosen = m.chosen && typeof m.chosen === 'object' ? m.chosen : {};
    S.commanded = m.commanded && typeof m.commanded === 'object' ? m.commanded : {};
    S.commandedBy = m.commanded_by && typeof m.commanded_by === 'object' ? m.commanded_by : {};
    S.kept = {};
    for (const k of Array.isArray(m.kept) ? m.kept : []) if (k && k.topic) S.kept[k.topic] = k;
    if (!S.layouts.some((l) => l.name === L.name)) {
      S.layouts.push({ name: L.name, title: L.title || L.name });
      ui.select.append(el('option', { value: L.name, text: L.title || L.name }));
    }
    ui.select.value = S.layoutName;
    ui.title.textContent = L.title || L.name || '';
    setLease(ctx.leaseOf(layoutVehicle()));
    document.title = `${L.title || L.name} · seabus`;
    designer.loaded(L);
    renderLayout();
  }

  function normaliseProducers(p) {
    const out = {};
    if (!p) return out;
    if (Array.isArray(p)) {
      for (const x of p) {
        if (Array.isArray(x)) out[x[0]] = !!x[1];
        else if (x && x.topic) out[x.topic] = !!(x.produced ?? x.producer ?? x.has_producer ?? x.produces ?? true);
        else if (typeof x === 'string') out[x] = true;
      }
    } else if (typeof p === 'object') {
      for (const [k, v] of Object.entries(p)) {
        out[k] = v && typeof v === 'object' ? !!(v.produced ?? v.producer ?? v.has_producer ?? true) : !!v;
      }
    }
    return out;
  }

  function onData(m) {
    if (typeof m.now === 'number') {
      S.now = m.now;
      S.nowAt = performance.now();
    }
    const topics = m.topics || {};
    for (const [name, t] of Object.entries(topics)) {
      if (!t || typeof t !== 'object') continue;
      S.topics[name] = { stamp: Number(t.stamp), fields: t.fields && typeof t.fields === 'object' ? t.fields : {} };
    }
    for (const w of widgets) {
      try { w.update(); } catch (e) { console.error('widget', w.node && w.node.id, e); }
    }
    for (const w of widgets) w.tick();
  }

  /** The vehicle the open layout commands ('' for the console's one control). */
  function layoutVehicle() {
    return (S.layout && S.layout.vehicle) || '';
  }

  /** Keeps a `lease` message's holder under its vehicle. */
  function rememberLease(l) {
    if (!l || typeof l !== 'object') return;
    S.leases[l.vehicle || ''] = { holder: l.holder ?? null, session: l.session ?? null, since: l.since ?? null };
  }

  /** Whether lease `l` is held by this page's log-in. */
  function inControl(l) {
    return !!l.holder && l.holder === S.user && l.session !== null && l.session === S.session;
  }

  function setLease(l) {
    S.lease = { holder: l.holder ?? null, session: l.session ?? null, since: l.since ?? null };
    const h = S.lease.holder;
    const mine = inControl(S.lease);
    ui.holder.textContent = h ? (mine ? `you (${h})` : h === S.user ? `you, in another log-in (${h})` : h) : 'free';
    ui.holder.className = `lease-holder ${h ? (mine ? 'mine' : 'other') : 'none'}`;
    ui.holder.title = h && S.lease.since ? `since ${new Date(Number(S.lease.since) * 1000).toLocaleTimeString()}` : '';
    ui.holder.dataset.holder = h || '';
    const mayTake = S.roles.includes(S.leaseRole);
    // a layout that commands nothing under control (a fleet table) offers none to take
    const controlled = Object.values((S.layout && S.layout.commands) || {}).some((c) => c.lease !== false);
    ui.take.hidden = !mayTake || mine || (S.layout && !controlled);
    ui.take.disabled = !!h || S.conn !== 'connected';
    const vehicle = layoutVehicle();
    ui.take.title = h ? (h === S.user ? 'you hold control in another log-in' : `${h} holds control`) : `take control of ${vehicle || 'the vehicle'}`;
    ui.controlLabel.textContent = vehicle ? `Control of ${vehicle}` : 'Control';
    ui.release.hidden = !mine;
    if (!mine) inputs.stopAll(false);
    updatePermissions();
  }

  function onLease(m) {
    rememberLease(m);
    if ((m.vehicle || '') === layoutVehicle()) setLease(m);
    for (const w of widgets) if (w.onLease) w.onLease();
  }

  /** Who controls what, whole: any holder not in it has released. */
  function onLeases(m) {
    S.leases = {};
    for (const l of Array.isArray(m.held) ? m.held : []) rememberLease(l);
    setLease(ctx.leaseOf(layoutVehicle()));
    for (const w of widgets) if (w.onLease) w.onLease();
  }

  function upsertCommand(c) {
    if (!c) return;
    const i = c.id !== undefined ? S.history.findIndex((x) => x.id === c.id) : -1;
    if (i >= 0) S.history[i] = { ...S.history[i], ...c };
    else S.history.push(c);
    if (S.history.length > 500) S.history.splice(0, S.history.length - 500);
  }

  function onCommand(m) {
    const { type, ...c } = m;
    upsertCommand(c);
    if (c.user === S.user) {
      if (c.state === 'refused' && c.command) { delete S.pending[c.command]; syncInputs(); }
      if (c.state === 'refused') toast(`${c.command || c.topic} refused${c.reason ? `: ${c.reason}` : ''}`, 'error');
      else if (c.state === 'timed-out') toast(`${c.command || c.topic} timed out`, 'warn');
    }
    widgets.forEach((w) => w.onHistory && w.onHistory());
  }

  function onHistory(m) {
    S.history = [];
    for (const c of Array.isArray(m.commands) ? m.commands : []) upsertCommand(c);
    widgets.forEach((w) => w.onHistory && w.onHistory());
  }

  /** The recent samples of the bound topics, `{TOPIC: [{stamp, fields}]}` oldest first: to the plots and tracks. */
  function onBacklog(m) {
    const topics = m.topics && typeof m.topics === 'object' ? m.topics : {};
    for (const w of widgets) {
      if (!w.onBacklog) continue;
      try { w.onBacklog(topics); } catch (e) { console.error('widget', w.node && w.node.id, e); }
    }
  }

  // ------------------------------------------------------------ command values

  /** A field's value and where it comes from: what the pilot changed, what was just sent, what
   * was last commanded, else the variable the layout measures it by, or (for a field no control
   * chooses) the layout's own value. A field the pilot chooses never takes the layout's value. */
  function fieldValue(n, f) {
    const c = ctx.command(n);
    if (!c || !f) return { value: undefined, source: 'unknown' };
    // a field no control chooses is the layout's own (a button's `set`, or the command's
    // declared value): never what was last commanded on the topic, which may be another
    // button's value (a start after a stop)
    const chosen = S.chosen[n] || [];
    if (!chosen.includes(f)) {
      if (c.fields && c.fields[f] !== undefined) return { value: c.fields[f], source: 'layout' };
      return { value: undefined, source: 'unknown' };
    }
    const changed = S.fields[n];
    if (changed && changed[f] !== undefined) return { value: changed[f], source: 'changed' };
    const p = S.pending[n];
    if (p && p.fields[f] !== undefined && performance.now() - p.at < PENDING_MS) return { value: p.fields[f], source: 'sending' };
    const cmd = S.commanded[c.topic];
    if (cmd && cmd[f] !== undefined) return { value: cmd[f], source: 'commanded' };
    const from = c.from && c.from[f];
    if (from) {
      const t = S.topics[from.topic];
      const v = t && t.fields ? t.fields[from.field] : undefined;
      const fresh = t && ctx.serverNow() - Number(t.stamp) <= MEASURED_FRESH_S;
      if (fresh && typeof v === 'number' && Number.isFinite(v)) return { value: ctx.clamp(n, f, v), source: 'measured' };
      return { value: undefined, source: 'unknown' };
    }
    return { value: undefined, source: 'unknown' };
  }

  /** The values `name` would send with `set`: each field with its value and whether the pilot
   * changed it; and the fields the pilot must set first (no known value). */
  function outgoing(name, set) {
    const c = ctx.command(name);
    const values = [];
    const unknown = [];
    const chosen = S.chosen[name] || [];
    for (const f of Object.keys((c && c.fields) || {})) {
      const v = set[f] !== undefined ? set[f] : fieldValue(name, f).value;
      if (v === undefined) unknown.push(f);
      // a button's own value is the layout's, not a change the pilot made
      else values.push({ field: f, value: v, changed: set[f] !== undefined && chosen.includes(f) });
    }
    return { values, unknown };
  }

  function onCommanded(m) {
    if (!m.topic || !m.fields || typeof m.fields !== 'object') return;
    S.commanded[m.topic] = m.fields;
    if (m.by !== undefined) S.commandedBy[m.topic] = { by: m.by, console: m.console, since: m.since };
    for (const [n, c] of Object.entries((S.layout && S.layout.commands) || {})) {
      if (c && c.topic === m.topic) delete S.pending[n];
    }
    syncInputs();
  }

  function onKept(m) {
    if (!m.topic) return;
    S.kept[m.topic] = m;
    showKept();
  }

  /** The kept commands: "holding course since …" with its values and the vehicle's mode, or
   * why it is no longer held, with the command that resumes it. */
  // the rows shown, by topic: rebuilt only when what is kept changes (a hold on the resume button
  // is never cut short by an update of the vehicle's mode)
  const keptRows = new Map();
  function showKept(rebuild) {
    const box = ui.kept;
    if (!box) return;
    if (rebuild) keptRows.clear();
    const state = S.topics['vehicle.state'];
    const mode = state && state.fields ? [state.fields.mode, state.fields.control].filter((x) => x !== undefined && x !== '').join(' · ') : '';
    const kept = Object.values(S.kept).filter((k) => k && ctx.command(k.command));
    for (const t of [...keptRows.keys()]) if (!S.kept[t]) keptRows.delete(t);
    for (const k of kept) {
      const key = JSON.stringify(k);
      let r = keptRows.get(k.topic);
      if (!r || r.key !== key) {
        r = { key, row: keptRow(k), mode: null };
        r.mode = r.row.querySelector('.kept-mode');
        keptRows.set(k.topic, r);
      }
      if (r.mode && r.mode.textContent !== (mode ? `vehicle: ${mode}` : '')) r.mode.textContent = mode ? `vehicle: ${mode}` : '';
    }
    const rows = [...keptRows.values()].map((r) => r.row);
    if (rows.length !== box.childElementCount || rows.some((row, i) => box.children[i] !== row)) box.replaceChildren(...rows);
    box.hidden = rows.length === 0;
  }

  /** A kept command's row: held since when, with what; or why it ended, and the button (the
   * layout's own, with its confirmation) of the command that resumes it. */
  function keptRow(k) {
    const c = ctx.command(k.command);
    if (k.reason === undefined) {
      return el('div', { class: 'kept-row holding', 'data-testid': 'kept', 'data-command': k.command },
        el('strong', { text: `holding ${k.command} since ${fmtTime(k.since)}` }),
        el('span', { class: 'kept-values', text: fmtFields(k.fields || {}) }),
        el('span', { class: 'kept-mode', 'data-testid': 'vehicle-mode' }));
    }
    const row = el('div', { class: 'kept-row ended', 'data-testid': 'kept', 'data-command': k.command },
      el('strong', { text: `${k.command} no longer held` }),
      el('span', { class: 'kept-reason', 'data-testid': 'kept-reason', text: k.reason }));
    if (c.resume && ctx.command(c.resume)) {
      const b = renderNode(ctx, { kind: 'button', id: `resume-${c.resume}`, command: c.resume, label: `Send ${c.resume}` });
      if (b) {
        b.dataset.testid = 'kept-resume';
        row.append(b);
      }
    }
    return row;
  }

  function onArmed(m) {
    let i = pendingArms.findIndex((p) => m.command === undefined || p.command === m.command);
    if (i < 0) return;
    const p = pendingArms.splice(i, 1)[0];
    clearTimeout(p.timer);
    p.resolve(m.arm);
  }

  function onError(m) {
    const msg = m.message || 'request refused';
    if (designer.saving()) designer.saveResult({ message: msg, file: m.file, line: m.line, col: m.col });
    if (pendingArms.length) {
      const p = pendingArms.shift();
      clearTimeout(p.timer);
      p.reject(new Error(msg));
      return;
    }
    toast(msg, 'error');
  }

  // ------------------------------------------------------------ header

  ui.select.addEventListener('change', () => openLayout(ui.select.value, true));
  // the control of the open layout's vehicle, or the console's one control
  const leaseMsg = (action) => {
    const vehicle = layoutVehicle();
    return vehicle ? { type: 'lease', action, vehicle } : { type: 'lease', action };
  };
  ui.take.addEventListener('click', () => takeDialog());
  if (ui.stop) {
    ui.stop.addEventListener('click', () => {
      const name = safeCommand();
      if (name) { inputs.stopAll(true); sendSafe(name); }
    });
  }
  ui.release.addEventListener('click', () => {
    inputs.stopAll(true);
    sendMsg(leaseMsg('release'));
  });

  // ------------------------------------------------------------ rendering

  function showLayoutError(e) {
    const where = [e.file, e.line, e.col].filter((x) => x !== undefined && x !== null && x !== '').join(':');
    ui.banner.replaceChildren(
      el('strong', { text: 'The layout has an error' }),
      where ? el('span', { class: 'where', 'data-testid': 'error-where', text: where }) : null,
      el('span', { 'data-testid': 'error-message', text: e.message || 'unknown error' }),
      e.line !== undefined ? el('div', { text: `line ${e.line}, column ${e.col ?? '?'}` }) : null,
    );
    ui.banner.hidden = false;
  }

  function hideBanner() { ui.banner.hidden = true; }

  function renderLayout() {
    widgets = [];
    const tree = designer.editing() ? designer.tree() : (S.layout && S.layout.root);
    const e = tree ? renderNode(ctx, tree) : null;
    ui.root.replaceChildren(e || el('p', { class: 'placeholder', text: S.layout ? 'This layout shows nothing for your roles.' : 'Waiting for the layout…' }));
    inputs.attach(S.layout);
    // the kept-command bar has its room before anything is kept: nothing moves when it shows
    const keeps = Object.values((S.layout && S.layout.commands) || {}).some((c) => c && c.keep_ms);
    document.body.classList.toggle('has-kept', keeps);
    showKept(true);
    showStop();
    for (const w of widgets) w.tick();
    ctx.redrawSoon();
  }

  function updatePermissions() {
    for (const w of widgets) if (w.permissions) w.permissions();
    if (ui.take) ui.take.disabled = !!S.lease.holder || S.conn !== 'connected';
    showStop();
  }

  /** The header's stop: there whenever the layout has a safe action the user may send, so that
   * it is reachable without scrolling on every layout; off (saying why) while it cannot go. */
  function showStop() {
    if (!ui.stop) return;
    const name = safeCommand();
    const a = name ? ctx.access(name) : null;
    ui.stop.hidden = !name || a.hidden || !ctx.hasRole(ctx.commandRole(name));
    if (ui.stop.hidden) return;
    ui.stop.textContent = `${name} (Esc)`;
    ui.stop.dataset.command = name;
    ui.stop.disabled = !a.ok;
    ui.stop.title = a.ok ? `send ${name} now (Escape sends it too)` : a.why;
  }

  function syncInputs() {
    for (const w of widgets) if (w.sync) w.sync();
  }

  setInterval(() => { for (const w of widgets) w.tick(); showKept(); }, 250);
  // the safe action: an input being changed (a slider dragged) sends nothing when let go
  document.addEventListener('seabus:safe', () => { for (const w of widgets) if (w.onSafe) w.onSafe(); });
  window.addEventListener('resize', () => ctx.redrawSoon());

  // ------------------------------------------------------------ commands

  function arm(name) {
    return new Promise((resolve, reject) => {
      if (!sendMsg({ type: 'arm', layout: ctx.layoutName(), command: name })) {
        reject(new Error('disconnected'));
        return;
      }
      const p = { command: name, resolve, reject };
      p.timer = setTimeout(() => {
        const i = pendingArms.indexOf(p);
        if (i >= 0) pendingArms.splice(i, 1);
        reject(new Error('no answer to arming'));
      }, ARM_TIMEOUT_MS);
      pendingArms.push(p);
    });
  }

  function prepare(name, set) {
    const c = ctx.command(name);
    if (!c) { toast(`unknown command ${name}`, 'error'); return null; }
    const a = ctx.access(name);
    if (!a.ok) { toast(`${name}: ${a.why}`, 'warn'); return null; }
    const fields = { ...(S.fields[name] || {}), ...set };
    for (const [k, v] of Object.entries(fields)) fields[k] = ctx.clamp(name, k, v);
    const { unknown } = outgoing(name, fields);
    if (unknown.length) {
      const names = unknown.join(', ');
      toast(`${name} not sent: ${names} ${unknown.length > 1 ? 'have' : 'has'} no known value (nothing commanded or measured yet): set ${unknown.length > 1 ? 'them' : 'it'}`, 'error');
      return null;
    }
    S.fields[name] = fields;
    syncInputs();
    return { c, fields };
  }

  /** What the pilot changed in `name` and did not send is forgotten (a cancelled or failed send):
   * nothing changed once goes out later with something else. */
  function dropChanges(name) {
    delete S.fields[name];
    syncInputs();
  }

  /** `fields` of `name` went out: they show as sent until the bus has them. */
  function wentOut(name, fields) {
    S.pending[name] = { fields, at: performance.now() };
    delete S.fields[name];
    syncInputs();
  }

  function safeCommand() {
    const cmds = (S.layout && S.layout.commands) || {};
    return Object.keys(cmds).find((n) => cmds[n] && cmds[n].safe) || null;
  }

  /** The safe action, at once and as the layout declares it: nothing the pilot changed and did
   * not send goes with it or after it (every change is forgotten). */
  function sendSafe(name) {
    const a = ctx.access(name);
    if (!a.ok) { toast(`${name}: ${a.why}`, 'warn'); return false; }
    safeEpoch++;
    for (const h of [...holding]) h.cancel();
    if (ui.dialog.open) ui.dialog.close('cancel');
    S.fields = {};
    syncInputs();
    const ok = sendMsg({ type: 'send', layout: ctx.layoutName(), command: name, fields: {} });
    if (ok) wentOut(name, {});
    else toast(`${name} not sent: disconnected`, 'error');
    return ok;
  }

  /** Sends a command with some fields set, asking first when it needs confirmation. */
  function sendCommand(name, set) {
    const p = prepare(name, set || {});
    if (!p) return false;
    const { c, fields } = p;
    if (c.confirm === 'dialog' || c.confirm === 'hold') {
      confirmDialog(name, c, fields);
      return true;
    }
    const ok = sendMsg({ type: 'send', layout: ctx.layoutName(), command: name, fields });
    if (ok) wentOut(name, fields);
    else dropChanges(name);
    return ok;
  }

  async function armAndSend(name, fields) {
    const epoch = safeEpoch;
    try {
      const id = await arm(name);
      // the safe action went while it was being armed: what was confirmed before it does not follow it
      if (epoch !== safeEpoch) throw new Error(`${safeCommand()} sent meanwhile`);
      if (sendMsg({ type: 'send', layout: ctx.layoutName(), command: name, fields, confirmed: id })) wentOut(name, fields);
      else dropChanges(name);
    } catch (e) {
      dropChanges(name);
      toast(`${name} not sent: ${e.message}`, 'error');
    }
  }

  /** Press and hold: arms at once, sends when held for the hold time, nothing when let go early. */
  function holdCommand(name, set, cb) {
    const p = prepare(name, set || {});
    let handle = null;
    const end = () => {
      holding.delete(handle);
      try { cb && cb.end && cb.end(); } catch (e) { /* */ }
    };
    if (!p) { end(); return { cancel() {} }; }
    const holdMs = ctx.holdMs(name) + HOLD_MARGIN_MS;
    const t0 = performance.now();
    let armId = null, armErr = null, done = false, cancelled = false, ticking;
    arm(name).then((id) => { armId = id; finish(); }, (e) => { armErr = e; finish(); });
    const progress = () => {
      const f = Math.min(1, (performance.now() - t0) / holdMs);
      if (cb && cb.progress) cb.progress(f);
      if (f >= 1) { clearInterval(ticking); finish(); }
    };
    ticking = setInterval(progress, 25);
    progress();
    function finish() {
      if (done || cancelled) return;
      if (armErr) {
        done = true; clearInterval(ticking); end();
        dropChanges(name);
        toast(`${name} not sent: ${armErr.message}`, 'error');
        return;
      }
      if (performance.now() - t0 < holdMs || armId === null) return;
      done = true;
      clearInterval(ticking);
      const fields = S.fields[name] || p.fields;
      if (sendMsg({ type: 'send', layout: ctx.layoutName(), command: name, fields, confirmed: armId })) wentOut(name, fields);
      else dropChanges(name);
      end();
    }
    handle = {
      cancel() {
        if (done || cancelled) return;
        cancelled = true;
        clearInterval(ticking);
        dropChanges(name);
        end();
      },
      get done() { return done; },
    };
    holding.add(handle);
    return handle;
  }
  ctx.holdIndicator = (text) => {
    ui.holdBox.querySelector('.hold-text').textContent = text;
    ui.holdBox.hidden = false;
    const fill = ui.holdBox.querySelector('.hold-fill');
    return {
      progress(f) { fill.style.width = `${(f * 100).toFixed(1)}%`; },
      end() { ui.holdBox.hidden = true; fill.style.width = '0'; },
    };
  };

  // the holds under way (a button or key held to send): the safe action cancels them
  const holding = new Set();
  // counts the safe actions sent: a confirmed command armed before one is not sent after it
  let safeEpoch = 0;

  let dialogBusy = false;
  function confirmDialog(name, c, fields) {
    if (dialogBusy) return;
    dialogBusy = true;
    const d = ui.dialog;
    const okBtn = d.querySelector('[value="ok"]');
    const hold = c.confirm === 'hold';
    ui.dialogTitle.textContent = `Send ${name}?`;
    ui.dialogText.textContent = hold
      ? `Press and hold Send for ${(ctx.holdMs(name) / 1000).toFixed(1)} s to send ${c.topic || name}.`
      : `This sends ${c.topic || name} to the vehicle.`;
    // exactly what goes out: every field, the ones the pilot changed marked; what is confirmed
    // is sent whole, so nothing changed meanwhile on the bus slips in
    const out = outgoing(name, fields);
    const full = Object.fromEntries(out.values.map((v) => [v.field, v.value]));
    ui.dialogFields.textContent = out.values
      .map((v) => `${v.field} = ${fmtValue(v.value)}${v.changed ? '   (changed)' : ''}`)
      .join('\n');
    okBtn.textContent = hold ? 'Hold to send' : 'Send';
    let h = null;
    const fill = el('span', { class: 'fill' });
    okBtn.classList.add('cmd-button');
    okBtn.prepend(fill);
    const down = (ev) => {
      if (!hold || h) return;
      ev.preventDefault();
      h = holdCommand(name, full, {
        progress(f) { fill.style.width = `${(f * 100).toFixed(1)}%`; },
        end() { fill.style.width = '0'; if (h && h.done) d.close('held'); h = null; },
      });
    };
    const up = () => { if (h && !h.done) { h.cancel(); } };
    const click = (ev) => { if (hold) ev.preventDefault(); };
    okBtn.addEventListener('pointerdown', down);
    okBtn.addEventListener('pointerup', up);
    okBtn.addEventListener('pointerleave', up);
    okBtn.addEventListener('click', click);
    const onKey = (ev) => { if (hold && (ev.key === ' ' || ev.key === 'Enter') && !ev.repeat && ev.target === okBtn) down(ev); };
    const onKeyUp = (ev) => { if (hold && (ev.key === ' ' || ev.key === 'Enter')) up(); };
    okBtn.addEventListener('keydown', onKey);
    okBtn.addEventListener('keyup', onKeyUp);
    d.addEventListener('close', function closed() {
      d.removeEventListener('close', closed);
      okBtn.removeEventListener('pointerdown', down);
      okBtn.removeEventListener('pointerup', up);
      okBtn.removeEventListener('pointerleave', up);
      okBtn.removeEventListener('click', click);
      okBtn.removeEventListener('keydown', onKey);
      okBtn.removeEventListener('keyup', onKeyUp);
      fill.remove();
      if (h) h.cancel();
      dialogBusy = false;
      if (d.returnValue === 'ok' && !hold) armAndSend(name, full);
      else if (d.returnValue !== 'held') dropChanges(name);
    });
    d.returnValue = '';
    d.showModal();
    d.querySelector('[value="cancel"]').focus();
  }

  /** What taking control keeps, for each kept command of the layout: the values the vehicle
   * was last commanded (as the server would build them: the layout's own value for a field no
   * control chooses), who commanded them and since when; `fields` null when nothing (or not
   * every field) was commanded. */
  function keptOnTake() {
    const out = [];
    for (const [n, c] of Object.entries((S.layout && S.layout.commands) || {})) {
      if (!c || !c.keep_ms || c.lease === false) continue;
      const chosen = S.chosen[n] || [];
      const cmd = S.commanded[c.topic];
      let fields = cmd ? {} : null;
      for (const f of Object.keys(c.fields || {})) {
        if (!fields) break;
        const v = chosen.includes(f) ? cmd[f] : c.fields[f];
        if (v === undefined) fields = null;
        else fields[f] = v;
      }
      out.push({ name: n, topic: c.topic, fields, by: S.commandedBy[c.topic] || null, everyMs: c.keep_ms });
    }
    return out;
  }

  /** Asks before control is taken, saying what the vehicle will do: each kept command goes on
   * with the course it was last commanded (by whom, since when), held by the console; with
   * nothing commanded, the vehicle does what it does without commands until one is sent. The
   * server takes control only if those are still the vehicle's last commanded values. */
  function takeDialog() {
    if (dialogBusy) return;
    dialogBusy = true;
    const d = ui.dialog;
    const okBtn = d.querySelector('[value="ok"]');
    const vehicle = layoutVehicle() || 'the vehicle';
    const kept = keptOnTake();
    const keep = {};
    const lines = [];
    for (const k of kept) {
      if (!k.fields) {
        lines.push(`${k.name}: nothing commanded on ${k.topic} yet, so nothing is kept.`);
        continue;
      }
      keep[k.name] = k.fields;
      const by = k.by && k.by.by ? (k.by.console ? 'this console' : k.by.by) : 'an earlier command';
      const since = k.by && k.by.since ? ` at ${new Date(Number(k.by.since) * 1000).toLocaleTimeString()}` : '';
      const values = Object.entries(k.fields).map(([f, v]) => `${f} = ${fmtValue(v)}`).join(', ');
      lines.push(`${k.name} kept: ${values}\n   (commanded by ${by}${since}; sent again every ${(k.everyMs / 1000).toFixed(1)} s until you change it or release control)`);
    }
    ui.dialogTitle.textContent = `Take control of ${vehicle}?`;
    ui.dialogText.textContent = Object.keys(keep).length
      ? `Whatever commands ${vehicle} now may step back: the console goes on with its last course.`
      : `Whatever commands ${vehicle} now may step back, and nothing is kept: ${vehicle} goes on as it does without commands (its own timeout and safe action) until you send one.`;
    ui.dialogFields.textContent = lines.join('\n');
    okBtn.textContent = 'Take control';
    d.addEventListener('close', function closed() {
      d.removeEventListener('close', closed);
      dialogBusy = false;
      if (d.returnValue === 'ok') sendMsg({ ...leaseMsg('take'), keep });
    });
    d.returnValue = '';
    d.showModal();
    d.querySelector('[value="cancel"]').focus();
  }

  // ------------------------------------------------------------ toasts

  function toast(text, kind) {
    const t = el('div', { class: `toast ${kind || ''}`, role: kind === 'error' ? 'alert' : 'status', text });
    ui.toasts.append(t);
    while (ui.toasts.childElementCount > 5) ui.toasts.firstElementChild.remove();
    setTimeout(() => t.remove(), kind === 'error' ? 8000 : 5000);
  }

  // ------------------------------------------------------------ test hook

  window.seabusConsole = {
    state() {
      return {
        layout: S.layout ? S.layout.name : S.layoutName,
        lease: S.lease.holder,
        inControl: inControl(S.lease),
        session: S.session,
        origin: S.origin,
        vehicle: layoutVehicle(),
        // the vehicles someone controls ('' for the console's one control), with who
        leases: Object.fromEntries(Object.entries(S.leases).filter(([, v]) => v.holder).map(([k, v]) => [k, v.holder])),
        connection: S.conn,
        drives: S.driveCount,
        releases: S.releaseCount,
        sentCount: S.sentCount,
        lastSent: S.lastSent,
        user: S.user,
        roles: S.roles.slice(),
        editing: designer.editing(),
        error: S.layoutError,
        inputs: inputs.status(),
      };
    },
    sent: () => S.sent.slice(),
    topic: (n) => S.topics[n] || null,
    policyViolations: () => policyViolations.slice(),
    // what the plot labelled `label` last drew: its area, axes and lines in canvas pixels (a
    // track: the points of each vehicle's trail; a fleet table: its rows)
    plot(label) {
      const w = widgets.find((x) => x.drawn && x.node.label === label);
      return w ? w.drawn() : null;
    },
    // a message handled as if the server had sent it
    receive: (m) => handle(m),
  };

  connect();
}
