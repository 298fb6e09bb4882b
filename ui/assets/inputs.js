// Keyboard and gamepad bindings, and the dead-man loop of commands with a rate.

import { parseBind, parseCommandRef, parseValue, num } from './widgets.js';

const POLL_MS = 20;
const DEFAULT_FROZEN_MS = 1000;

/** The shaped stick value: 0 inside the deadband; outside, rescaled to 0–1, expo, gain. */
export function shapeAxis(raw, deadband, expo, gain) {
  const x = Number(raw) || 0;
  const db = Math.min(0.99, Math.max(0, num(deadband, 0.1)));
  const a = Math.abs(x);
  if (a <= db) return 0;
  const s = Math.sign(x) * Math.min(1, (a - db) / (1 - db));
  const e = Math.min(1, Math.max(0, num(expo, 0)));
  return ((1 - e) * s + e * s * s * s) * num(gain, 1);
}

function editable(t) {
  if (!t || !(t instanceof Element)) return false;
  if (t.isContentEditable) return true;
  const tag = t.tagName;
  if (tag === 'TEXTAREA' || tag === 'SELECT') return true;
  if (tag === 'INPUT') {
    const type = (t.getAttribute('type') || 'text').toLowerCase();
    return !['checkbox', 'radio', 'button', 'submit', 'range'].includes(type);
  }
  return false;
}

export function createInputs(ctx) {
  let layout = null;
  let keys = [];
  let axes = [];
  let buttons = [];
  const active = new Map(); // command → {sources: Map, timer}
  const heldKeys = new Map(); // code → [{binding, restore, hold}]
  let blurred = false;
  let pad = null; // {key, lastSig, lastChange}
  const latched = new Set();
  const axisLast = new Map();
  const buttonDown = new Map();
  let pollTimer = null;
  const warned = new Set();

  function cmdOf(name) { return ctx.command(name); }
  function rateOf(name) {
    const c = cmdOf(name);
    const r = c && Number(c.rate_hz);
    return Number.isFinite(r) && r > 0 ? r : 0;
  }
  function frozenMs(name) {
    const c = cmdOf(name);
    const f = c && Number(c.frozen_ms);
    return Number.isFinite(f) && f > 0 ? f : DEFAULT_FROZEN_MS;
  }


  function ref(b) {
    if (!b) return null;
    if (b.field !== undefined && b.field !== null && b.field !== '') return { name: b.command, field: String(b.field) };
    return parseCommandRef(ctx, b.command);
  }

  // ---------------------------------------------------------------- dead-man

  function drive(name) {
    const a = ctx.access(name);
    const e = active.get(name);
    if (!a.ok || !e) { stop(name, false); return; }
    ctx.sendMsg({ type: 'drive', layout: e.layout, command: name, fields: ctx.fields(name) });
  }

  function activate(name, src, set) {
    const a = ctx.access(name);
    if (!a.ok) {
      if (!warned.has(name)) { warned.add(name); ctx.toast(`${name}: ${a.why}`, 'warn'); setTimeout(() => warned.delete(name), 3000); }
      return false;
    }
    let e = active.get(name);
    ctx.setFields(name, clampAll(name, set));
    if (!e) {
      e = { sources: new Map(), layout: ctx.layoutName() };
      active.set(name, e);
      e.sources.set(src, set);
      drive(name);
      if (active.get(name) === e) e.timer = setInterval(() => drive(name), 1000 / rateOf(name));
    } else {
      e.sources.set(src, set);
    }
    return true;
  }

  function deactivate(name, src) {
    const e = active.get(name);
    if (!e) return;
    e.sources.delete(src);
    if (!e.sources.size) stop(name, true);
  }

  function stop(name, release) {
    const e = active.get(name);
    if (!e) return;
    clearInterval(e.timer);
    active.delete(name);
    if (release) ctx.sendMsg({ type: 'release', layout: e.layout, command: name });
    // the server sends the neutral; the inputs show what it commanded
    ctx.clearFields(name);
  }

  function stopSources(pred, release) {
    for (const [name, e] of [...active]) {
      for (const src of [...e.sources.keys()]) if (pred(src)) e.sources.delete(src);
      if (!e.sources.size) stop(name, release);
    }
  }

  function clampAll(name, set) {
    const out = {};
    for (const [k, v] of Object.entries(set)) out[k] = ctx.clamp(name, k, v);
    return out;
  }

  /** Stops every dead-man command (a release each when `release`) and forgets held keys and holds. */
  function stopAll(release) {
    for (const name of [...active.keys()]) stop(name, release);
    for (const list of heldKeys.values()) for (const h of list) if (h.hold) h.hold.cancel();
    heldKeys.clear();
    for (const [, b] of buttonDown) if (b && b.hold) b.hold.cancel();
    for (const k of buttonDown.keys()) buttonDown.set(k, { pressed: true });
    axes.forEach((_, i) => latched.add(i));
  }

  // ---------------------------------------------------------------- one-shot sends

  function holdOrSend(name, set, text) {
    const c = cmdOf(name);
    if (c && c.confirm === 'hold') {
      const ind = ctx.holdIndicator(text || `Hold to send ${name}`);
      return ctx.hold(name, set, ind);
    }
    ctx.send(name, set);
    return null;
  }

  // ---------------------------------------------------------------- keyboard

  function keyMatches(b, ev) {
    if (b.key === ev.key) return true;
    return typeof b.key === 'string' && b.key.length === 1 && ev.key.length === 1 && b.key.toLowerCase() === ev.key.toLowerCase();
  }

  /** The keys bound to the layout's safe action (a stop); Escape sends it when no key of the
   * layout is bound to Escape. */
  function safeKeys(ev) {
    const safe = keys.filter((b) => keyMatches(b, ev) && isSafe(b));
    if (safe.length || ev.key !== 'Escape' || keys.some((b) => keyMatches(b, ev))) return safe;
    const name = ctx.safeCommand();
    return name ? [{ key: 'Escape', command: name }] : [];
  }
  function isSafe(b) {
    const r = ref(b);
    const c = r && cmdOf(r.name);
    return !!(c && c.safe && !r.field);
  }

  /** The safe action, from every state of the page: a dialog open (it is cancelled), the focus
   * in an input (what was typed is not sent), a slider being dragged (it sends nothing when let
   * go), a held key or stick (released first). */
  function safeAction(ev, list) {
    ev.preventDefault();
    if (ev.repeat) return;
    stopAll(true);
    const open = document.querySelector('dialog[open]');
    if (open) open.close('cancel');
    document.dispatchEvent(new CustomEvent('seabus:safe'));
    for (const b of list) {
      const r = ref(b);
      if (r) ctx.sendSafe(r.name);
    }
  }

  function onKeyDown(ev) {
    if (!layout || ev.ctrlKey || ev.metaKey || ev.altKey) return;
    const safe = safeKeys(ev);
    if (safe.length) { safeAction(ev, safe); return; }
    if (editable(ev.target)) return;
    if ((ev.key === ' ' || ev.key === 'Enter') && ev.target instanceof Element && ev.target.closest('button, a, [role="tab"]')) return;
    if (document.querySelector('dialog[open]')) return;
    const list = keys.filter((b) => keyMatches(b, ev));
    if (!list.length) return;
    ev.preventDefault();
    if (ev.repeat || heldKeys.has(ev.code || ev.key)) return;
    const held = [];
    for (const b of list) {
      const r = ref(b);
      if (!r || !cmdOf(r.name)) continue;
      const a = ctx.access(r.name);
      if (!a.ok) { ctx.toast(`${r.name}: ${a.why}`, 'warn'); continue; }
      if (r.field && b.value !== undefined && b.value !== null) {
        const v = parseValue(typeof b.value === 'string' ? b.value : b.value);
        if (rateOf(r.name)) {
          if (activate(r.name, `key:${ev.code || ev.key}`, { [r.field]: v })) held.push({ b, r, dead: true });
        } else {
          const restore = ctx.fieldValue(r.name, r.field);
          ctx.send(r.name, { [r.field]: v });
          held.push({ b, r, restore });
        }
      } else if (r.field && b.step !== undefined && b.step !== null) {
        const cur = Number(ctx.fieldValue(r.name, r.field));
        if (!Number.isFinite(cur)) {
          // a step from an unknown value would send a value nobody chose
          ctx.toast(`${r.name}: ${r.field} has no known value to step from: set it first`, 'warn');
          continue;
        }
        const v = ctx.clamp(r.name, r.field, +(cur + num(b.step, 0)).toFixed(10));
        ctx.send(r.name, { [r.field]: v });
      } else {
        const hold = holdOrSend(r.name, {}, `Hold ${b.key} to send ${r.name}`);
        if (hold) held.push({ b, r, hold });
      }
    }
    if (held.length) heldKeys.set(ev.code || ev.key, held);
  }

  function onKeyUp(ev) {
    const list = heldKeys.get(ev.code || ev.key);
    if (!list) return;
    heldKeys.delete(ev.code || ev.key);
    for (const h of list) {
      if (h.dead) deactivate(h.r.name, `key:${ev.code || ev.key}`);
      else if (h.hold) h.hold.cancel();
      else if (h.restore !== undefined && ctx.access(h.r.name).ok) ctx.send(h.r.name, { [h.r.field]: h.restore });
    }
  }

  function focusLost() {
    blurred = true;
    stopAll(true);
  }

  window.addEventListener('keydown', onKeyDown);
  window.addEventListener('keyup', onKeyUp);
  window.addEventListener('blur', focusLost);
  window.addEventListener('focus', () => { blurred = false; });
  document.addEventListener('visibilitychange', () => {
    if (document.visibilityState === 'hidden') focusLost();
    else blurred = false;
  });
  window.addEventListener('pagehide', () => stopAll(true));

  // ---------------------------------------------------------------- gamepad

  function offsetValue(o) {
    if (o === undefined || o === null || o === '') return 0;
    if (typeof o === 'number') return o;
    if (typeof o === 'string' && /^\s*[-+]?[\d.]+(e[-+]?\d+)?\s*$/i.test(o)) return parseFloat(o);
    const b = parseBind(o);
    if (!b || !b.field) return undefined;
    const t = ctx.topic(b.topic);
    const v = t && t.fields ? Number(t.fields[b.field]) : NaN;
    return Number.isFinite(v) ? v : undefined;
  }

  function padLost() {
    if (!pad) return;
    pad = null;
    stopSources((s) => s.startsWith('axis:'), true);
    for (const [, b] of buttonDown) if (b && b.hold) b.hold.cancel();
    buttonDown.clear();
    axisLast.clear();
    axes.forEach((_, i) => latched.add(i));
  }

  function pickPad() {
    if (!navigator.getGamepads) return null;
    let list;
    try { list = navigator.getGamepads(); } catch (e) { return null; }
    if (!list) return null;
    for (const p of Array.from(list)) if (p && p.connected !== false) return p;
    return null;
  }

  function poll() {
    if (!layout || (!axes.length && !buttons.length)) return;
    const gp = pickPad();
    const nowMs = performance.now();
    if (!gp) { padLost(); return; }
    const key = `${gp.index}:${gp.id}`;
    if (pad && pad.key !== key) padLost();
    const sig = `${gp.timestamp}|${Array.from(gp.axes || []).join(',')}`;
    if (!pad) pad = { key, lastSig: sig, lastChange: nowMs, frozen: false };
    if (sig !== pad.lastSig) {
      pad.lastSig = sig;
      pad.lastChange = nowMs;
      pad.frozen = false;
    }
    const still = nowMs - pad.lastChange;
    const focusOk = !blurred && document.visibilityState !== 'hidden';

    axes.forEach((b, i) => {
      const r = ref(b);
      if (!r || !r.field || !cmdOf(r.name)) return;
      const raw = Number((gp.axes || [])[num(b.index, 0)]) || 0;
      const db = num(b.deadband, 0.1);
      const deflected = Math.abs(raw) > db;
      const src = `axis:${i}`;
      const driving = active.has(r.name) && active.get(r.name).sources.has(src);
      if (latched.has(i)) {
        if (!deflected) latched.delete(i);
        return;
      }
      if (deflected && still > frozenMs(r.name)) {
        // readings stopped changing while deflected: the pad is gone or stuck
        pad.frozen = true;
        if (driving) deactivate(r.name, src);
        latched.add(i);
        return;
      }
      const off = offsetValue(b.offset);
      const value = off === undefined ? undefined : +(shapeAxis(raw, db, b.expo, b.gain) + off).toFixed(6);
      if (rateOf(r.name)) {
        if (deflected && focusOk && value !== undefined) {
          if (driving) {
            active.get(r.name).sources.set(src, { [r.field]: value });
            ctx.setFields(r.name, clampAll(r.name, { [r.field]: value }));
          } else if (ctx.access(r.name).ok) {
            activate(r.name, src, { [r.field]: value });
          }
        } else if (driving) {
          deactivate(r.name, src);
        }
      } else if (focusOk && value !== undefined && ctx.access(r.name).ok && !(cmdOf(r.name).confirm)) {
        const last = axisLast.get(i);
        const changed = !last || Math.abs(last.v - value) > 1e-3;
        if (deflected ? changed && (!last || nowMs - last.t > 200) : last && last.deflected) {
          ctx.send(r.name, { [r.field]: value });
          axisLast.set(i, { v: value, t: nowMs, deflected });
        }
      }
    });

    buttons.forEach((b, i) => {
      const btn = (gp.buttons || [])[num(b.index, 0)];
      const pressed = !!(btn && (btn.pressed || (typeof btn === 'number' ? btn > 0.5 : Number(btn.value) > 0.5)));
      const prev = buttonDown.get(i);
      if (pressed && !prev) {
        const r = ref(b);
        const entry = { pressed: true };
        if (r && cmdOf(r.name) && focusOk) {
          const a = ctx.access(r.name);
          if (!a.ok) ctx.toast(`${r.name}: ${a.why}`, 'warn');
          else {
            const set = {};
            if (r.field && b.value !== undefined) set[r.field] = parseValue(b.value);
            entry.hold = holdOrSend(r.name, set, `Hold button ${b.index} to send ${r.name}`);
          }
        }
        buttonDown.set(i, entry);
      } else if (!pressed && prev) {
        if (prev.hold) prev.hold.cancel();
        buttonDown.delete(i);
      }
    });
  }

  window.addEventListener('gamepaddisconnected', () => {
    if (!pickPad()) padLost();
    else if (pad) {
      const gp = pickPad();
      if (`${gp.index}:${gp.id}` !== pad.key) padLost();
    }
  });

  // ---------------------------------------------------------------- attach

  return {
    attach(L) {
      if (L === layout) return;
      stopAll(true);
      layout = L;
      keys = L && Array.isArray(L.keys) ? L.keys : [];
      const gpd = (L && L.gamepad) || {};
      axes = Array.isArray(gpd.axes) ? gpd.axes : [];
      buttons = Array.isArray(gpd.buttons) ? gpd.buttons : [];
      latched.clear();
      axes.forEach((_, i) => latched.add(i)); // a stick must pass through neutral before it drives
      axisLast.clear();
      buttonDown.clear();
      pad = null;
      clearInterval(pollTimer);
      pollTimer = (axes.length || buttons.length) ? setInterval(poll, POLL_MS) : null;
    },
    stopAll,
    status() {
      return {
        active: [...active.keys()],
        pad: pad ? pad.key : null,
        frozen: !!(pad && pad.frozen),
        blurred,
      };
    },
  };
}
