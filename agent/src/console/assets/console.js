// cellwatch console: the plant's cells and alarms, live, and operators'
// commands signed here, in the browser, with the operator's own key.
//
// Every text from the bus (messages, comments, reasons, names) goes into
// the page as text (textContent, createTextNode), never as HTML; the
// Content-Security-Policy requires Trusted Types, so an HTML sink would
// throw rather than run anything.
'use strict';

const PRIORITY = { critical: 4, high: 3, medium: 2, low: 1 };
const STATE_TEXT = {
  active_unacknowledged: 'Active, unacknowledged',
  active_acknowledged: 'Active, acknowledged',
  cleared_unacknowledged: 'Cleared, unacknowledged',
  normal: 'Normal',
};
const TABLE_ROWS = 500;

const S = {
  cells: new Map(),
  alarms: new Map(),
  areas: [],
  dropped: 0,
  identity: null,
  stream: null,
  started: false,
  key: null,
  live: false,
  synced: false,
  // Occurrences (`cell\u0000id\u0000raised_at`) whose horn an operator
  // silenced on this page.
  silenced: new Set(),
  sort: { col: 'time', dir: -1 },
  filter: { text: '', cell: '', area: '', priority: '', state: '' },
  view: null,
};

// ---- building the page, as text only ----

function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k === 'class') e.className = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? '' : String(v));
  }
  for (const c of children.flat(Infinity)) {
    if (c === undefined || c === null || c === false) continue;
    e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return e;
}

function svg(tag, attrs) {
  const e = document.createElementNS('http://www.w3.org/2000/svg', tag);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, String(v));
  return e;
}

function pad(n, w = 2) { return String(n).padStart(w, '0'); }

function when(iso) {
  if (!iso) return '';
  const d = typeof iso === 'number' ? new Date(iso) : new Date(iso);
  if (isNaN(d)) return String(iso);
  return `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())} ` +
    `${pad(d.getHours())}:${pad(d.getMinutes())}:${pad(d.getSeconds())}`;
}

// Today's local midnight, RFC 3339 with the browser's offset.
function midnight() {
  const d = new Date();
  d.setHours(0, 0, 0, 0);
  const off = -d.getTimezoneOffset();
  const a = Math.abs(off);
  return `${d.getFullYear()}-${pad(d.getMonth() + 1)}-${pad(d.getDate())}T00:00:00${off >= 0 ? '+' : '-'}${pad(Math.floor(a / 60))}:${pad(a % 60)}`;
}

function href(...parts) { return '#/' + parts.map(encodeURIComponent).join('/'); }

function alarmKey(cell, id) { return cell + '\u0000' + id; }

function active(a) { return a.state === 'active_unacknowledged' || a.state === 'active_acknowledged'; }
function unacked(a) { return a.state === 'active_unacknowledged' || a.state === 'cleared_unacknowledged'; }
function suppressed(a) { return !!(a.consequence && a.consequence.suppressed); }
function kept(a) { return !!(a.shelved || a.out_of_service || suppressed(a) || a.suppressed_by_design); }

// A humantime duration as the agent writes it (`5m`, `1h 30m`, `2m 30s`),
// ms; null if it is none.
function durationMs(t) {
  if (!t) return null;
  const unit = { ms: 1, s: 1e3, m: 6e4, h: 36e5, d: 864e5 };
  let ms = 0;
  for (const part of t.trim().split(/\s+/)) {
    const m = /^(\d+)(ms|s|m|h|d)$/.exec(part);
    if (!m) return null;
    ms += Number(m[1]) * unit[m[2]];
  }
  return ms;
}
// Unacknowledged past the response time its rationalisation gives.
function overdue(a) {
  const rt = a.guidance ? durationMs(a.guidance.response_time) : null;
  return rt !== null && unacked(a) && !kept(a) && Date.now() - Date.parse(a.raised_at) > rt;
}
function occurrence(a) { return alarmKey(a.cell, a.id) + '\u0000' + a.raised_at; }
// Rings (ISA-101): a new unacknowledged high or critical alarm to act on,
// until an operator silences it here.
function rings(a) {
  return unacked(a) && !kept(a) && (a.severity === 'high' || a.severity === 'critical') && !S.silenced.has(occurrence(a));
}

function badge(a) {
  const cls = ['badge', 'p-' + a.severity, unacked(a) ? 'unack' : 'ack', kept(a) ? 'kept' : ''].join(' ');
  return el('span', { class: cls }, a.severity);
}

function stateText(a) {
  const parts = [STATE_TEXT[a.state] || a.state];
  if (a.latched) parts.push('latched');
  if (a.shelved) parts.push('shelved');
  if (a.out_of_service) parts.push('out of service');
  if (a.suppressed_by_design) parts.push('suppressed by design in mode ' + a.suppressed_by_design.mode);
  if (overdue(a)) parts.push('OVERDUE (response time ' + a.guidance.response_time + ')');
  if (a.consequence) parts.push((suppressed(a) ? 'suppressed, ' : '') + 'consequence of ' + a.consequence.cause);
  return parts.join(', ');
}

// ---- the live stream ----

function shown(a) { return a.state !== 'normal' || a.shelved || a.out_of_service; }

function take(m) {
  if (m.type === 'snapshot') {
    S.synced = true;
    S.cells = new Map(m.cells.map(c => [c.cell, c]));
    S.alarms = new Map(m.alarms.map(a => [alarmKey(a.cell, a.id), a]));
    S.areas = m.areas;
    S.dropped = m.dropped;
  } else if (m.type === 'alarm') {
    const a = m.alarm;
    const k = alarmKey(a.cell, a.id);
    const known = S.alarms.get(k);
    if (known && known.at > a.at) return;
    if (shown(a)) S.alarms.set(k, a); else S.alarms.delete(k);
  } else if (m.type === 'cell') {
    S.cells.set(m.cell.cell, m.cell);
  }
}

let pending = false;
function schedule() {
  if (pending) return;
  pending = true;
  setTimeout(() => { pending = false; update(); }, 150);
}

// The live stream, for whoever is signed in: opened again when someone
// else signs in (their cells may differ), closed when nobody is.
function connect() {
  if (S.stream) S.stream.close();
  const link = document.getElementById('link');
  const es = new EventSource('/api/events');
  S.stream = es;
  es.onopen = () => { S.live = true; link.textContent = 'live'; link.className = 'up'; };
  es.onerror = () => {
    S.live = false; link.textContent = 'reconnecting…'; link.className = 'down';
    // A stream refused (its session ended) is not tried again by the
    // browser: find out who we are now.
    if (es.readyState === EventSource.CLOSED && S.stream === es) setTimeout(whoAmI, 1000);
  };
  es.onmessage = e => {
    try { take(JSON.parse(e.data)); } catch (err) { console.error('bad event', err); return; }
    schedule();
  };
}

// ---- the operator's key ----

function hexBytes(hex) {
  const b = new Uint8Array(hex.length / 2);
  for (let i = 0; i < b.length; i++) b[i] = parseInt(hex.substr(i * 2, 2), 16);
  return b;
}

function bytesHex(bytes) {
  return Array.from(new Uint8Array(bytes), b => b.toString(16).padStart(2, '0')).join('');
}

function concat(parts) {
  const out = new Uint8Array(parts.reduce((n, p) => n + p.length, 0));
  let at = 0;
  for (const p of parts) { out.set(p, at); at += p.length; }
  return out;
}

// The bytes an operator signs (cellwatch-command-v5): each field as
// `<byte length>:<bytes>\n`, an absent one as `-\n`.
function canonical(cell, c) {
  const enc = new TextEncoder();
  const parts = [enc.encode('cellwatch-command-v5\n')];
  const field = f => {
    if (f === undefined || f === null) { parts.push(enc.encode('-\n')); return; }
    const b = enc.encode(f);
    parts.push(enc.encode(b.length + ':'), b, enc.encode('\n'));
  };
  [cell, c.action, c.alarm, c.operator, c.nonce, String(c.issued_at), c.tag, c.value, c.reason].forEach(field);
  return concat(parts);
}

// PKCS#8 of an Ed25519 private key is this prefix and the 32-byte seed.
const PKCS8_ED25519 = '302e020100300506032b657004220420';

async function loadKey(file) {
  const text = await file.text();
  const op = /^\s*operator\s*=\s*"([A-Za-z0-9_-]+)"\s*$/m.exec(text);
  const pk = /^\s*private_key\s*=\s*"([0-9a-fA-F]{64})"\s*$/m.exec(text);
  if (!op || !pk) throw new Error(`${file.name}: not a cellwatch operator key (operator = "…", private_key = "<64 hex digits>")`);
  const key = await crypto.subtle.importKey('pkcs8', hexBytes(PKCS8_ED25519 + pk[1].toLowerCase()),
    { name: 'Ed25519' }, false, ['sign']);
  const operator = op[1];
  const signedIn = await signIn(operator, key).catch(err => { throw new Error(`${file.name}: ${err.message}`); });
  return { operator, key, allow: new Set(signedIn.allow) };
}

// Signs in to the console as `operator`: the console gives a challenge,
// the key signs it with this page's host here, the console checks the
// signature against the operators file. The key never leaves the page.
async function signIn(operator, key) {
  const post = async (path, body) => {
    const r = await fetch(path, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
    const answer = await r.json();
    if (answer.error) throw new Error(answer.error);
    return answer;
  };
  const { challenge } = await post('/api/sign-in/challenge', {});
  const text = new TextEncoder().encode(`cellwatch-console-sign-in-v1\n${challenge}\n${location.host}\n`);
  const signature = bytesHex(await crypto.subtle.sign({ name: 'Ed25519' }, key, text));
  return post('/api/sign-in', { operator, challenge, signature });
}

// Who the console takes us for (a session, or a client certificate):
// the stream runs while someone is; otherwise the page asks for a key.
async function whoAmI() {
  const before = S.key;
  const r = await fetch('/api/session');
  const identity = r.ok ? await r.json() : null;
  // Someone signed in while this was asked: theirs is the newer answer.
  if (S.key !== before) return;
  S.identity = identity;
  if (!S.identity) {
    if (S.stream) { S.stream.close(); S.stream = null; }
    const was = S.key;
    S.key = null;
    showOperator(was ? 'signed out: load your operator key to sign in again' : null);
    const link = document.getElementById('link');
    link.textContent = 'signed out'; link.className = 'down';
    S.synced = false; S.cells = new Map(); S.alarms = new Map();
    if (S.view) route();
    return;
  }
  if (!S.stream || S.stream.readyState === EventSource.CLOSED) connect();
}

function may(action) { return S.key && S.key.allow.has(action); }

function showOperator(message) {
  const name = document.getElementById('operator-name');
  const forget = document.getElementById('forget-key');
  if (S.key) {
    const allowed = [...S.key.allow].join(', ') || 'no actions';
    name.replaceChildren(`operator ${S.key.operator} `, el('small', {}, `(${allowed})`));
    name.className = 'loaded';
    forget.hidden = false;
  } else {
    const who = !S.identity ? 'sign in: load your operator key'
      : S.identity.by === 'certificate' ? `certificate ${S.identity.identity}: load an operator key to act`
        : `signed in as ${S.identity.identity}: load your key again to act`;
    name.textContent = message || who;
    name.className = message ? 'refused' : '';
    forget.hidden = true;
  }
}

async function sign(cell, fields) {
  const cmd = Object.assign({ alarm: '' }, fields, {
    operator: S.key.operator,
    nonce: bytesHex(crypto.getRandomValues(new Uint8Array(16))),
    issued_at: Date.now(),
  });
  const sig = await crypto.subtle.sign({ name: 'Ed25519' }, S.key.key, canonical(cell, cmd));
  cmd.signature = bytesHex(sig);
  return cmd;
}

async function send(cell, fields, out) {
  out.className = 'answer waiting';
  out.textContent = `${fields.action}: sent, waiting for cell ${cell}'s agent…`;
  try {
    const cmd = await sign(cell, fields);
    const r = await fetch(`/api/cells/${encodeURIComponent(cell)}/command`, {
      method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(cmd),
    });
    const body = await r.json();
    if (body.error) { out.className = 'answer refused'; out.textContent = `${fields.action}: ${body.error}`; return false; }
    out.className = body.accepted ? 'answer accepted' : 'answer refused';
    out.textContent = `${fields.action} ${body.accepted ? 'accepted' : 'refused'}: ${body.detail}`;
    return body.accepted;
  } catch (err) {
    out.className = 'answer refused';
    out.textContent = `${fields.action}: ${err.message}`;
    return false;
  }
}

// ---- views ----

function counts(cell) {
  const n = { critical: 0, high: 0, medium: 0, low: 0, unack: 0 };
  for (const a of S.alarms.values()) {
    if (a.cell !== cell || kept(a)) continue;
    if (active(a)) n[a.severity]++;
    if (unacked(a)) n.unack++;
  }
  return n;
}

function commOf(c) {
  if (!c.agent) return ['no agent', 'bad'];
  if (c.state && c.state.state === 'offline') return ['PLC offline', 'bad'];
  if (c.connected === false) return ['PLC offline', 'bad'];
  return ['connected', 'ok'];
}

const overview = {
  mount(v) { this.root = el('section', { class: 'overview' }); v.append(this.root); },
  update() {
    const groups = new Map();
    for (const area of S.areas) groups.set(area, []);
    for (const c of S.cells.values()) {
      const g = c.area || '';
      if (!groups.has(g)) groups.set(g, []);
      groups.get(g).push(c);
    }
    const sections = [];
    for (const [area, cells] of groups) {
      if (!cells.length) continue;
      sections.push(el('h2', {}, area || (S.areas.length ? 'Other cells' : 'Cells')));
      sections.push(el('div', { class: 'tiles' }, cells.map(tile)));
    }
    if (!sections.length) sections.push(el('p', { class: 'empty' }, S.synced ? 'No cell in the plant trust file, or none you may read.' : !S.identity && !S.key ? 'The console shows the plant to a plant identity only: sign in with your operator key (top right), or present a client certificate from the plant CA.' : 'Waiting for the console\'s first view of the plant…'));
    this.root.replaceChildren(...sections);
  },
};

function tile(c) {
  const n = counts(c.cell);
  const [comm, commClass] = commOf(c);
  const state = c.state ? c.state.state : 'unknown';
  const fault = c.last_fault;
  return el('a', { class: `tile state-${state} ${n.unack ? 'has-unack' : ''}`, href: href('cell', c.cell), 'data-cell': c.cell },
    el('div', { class: 'tile-head' }, el('span', { class: 'cell-name' }, c.cell), el('span', { class: `comm ${commClass}` }, comm)),
    el('div', { class: 'machine-state' }, state, c.state && c.state.fault_type ? ` — ${c.state.fault_type}` : ''),
    el('div', { class: 'counts' },
      ['critical', 'high', 'medium', 'low'].map(p => el('span', { class: `count p-${p} ${n[p] ? 'some' : ''}`, title: `${p} alarms active` }, `${p[0].toUpperCase()} ${n[p]}`))),
    el('div', { class: 'last-fault' }, fault ? `last fault ${when(fault.at)} ${fault.alarm}${fault.message ? ': ' + fault.message : ''}` : 'no fault seen'));
}

function filtered() {
  const f = S.filter;
  const text = f.text.toLowerCase();
  const rows = [];
  for (const a of S.alarms.values()) {
    if (f.cell && a.cell !== f.cell) continue;
    if (f.area && (S.cells.get(a.cell) || {}).area !== f.area) continue;
    if (f.priority && a.severity !== f.priority) continue;
    if (f.state) {
      const ok = { 'active-unack': a.state === 'active_unacknowledged' && !kept(a),
        'active-ack': a.state === 'active_acknowledged' && !kept(a),
        'cleared-unack': a.state === 'cleared_unacknowledged' && !kept(a),
        shelved: !!a.shelved, 'out-of-service': !!a.out_of_service, latched: !!a.latched }[f.state];
      if (!ok) continue;
    }
    if (text && !`${a.cell} ${a.id} ${a.message} ${a.fault_type}`.toLowerCase().includes(text)) continue;
    rows.push(a);
  }
  const { col, dir } = S.sort;
  const key = {
    priority: a => PRIORITY[a.severity] || 0,
    state: a => stateText(a),
    time: a => a.raised_at,
    cell: a => a.cell,
    alarm: a => a.id,
    message: a => a.message,
  }[col];
  rows.sort((x, y) => {
    const a = key(x), b = key(y);
    return (a < b ? -1 : a > b ? 1 : 0) * dir || (x.raised_at < y.raised_at ? 1 : -1);
  });
  return rows;
}

const COLUMNS = [['priority', 'Priority'], ['state', 'State'], ['time', 'Time'], ['cell', 'Cell'], ['alarm', 'Alarm'], ['message', 'Message']];

const alarmsView = {
  mount(v) {
    const f = S.filter;
    const input = (name, attrs) => el('input', Object.assign({ name, value: f[name], oninput: e => { f[name] = e.target.value; this.update(); } }, attrs));
    this.selects = {};
    const select = (name, label, options) => {
      const s = el('select', { name, 'aria-label': label, onchange: e => { f[name] = e.target.value; this.update(); } },
        el('option', { value: '' }, `all ${label}`), options.map(([v, t]) => el('option', { value: v, selected: f[name] === v }, t)));
      this.selects[name] = s;
      return s;
    };
    this.head = el('tr', {});
    this.body = el('tbody', {});
    this.note = el('p', { class: 'note' });
    v.append(
      el('section', { class: 'filters' },
        input('text', { type: 'search', placeholder: 'filter: cell, alarm, message', 'aria-label': 'filter text' }),
        select('cell', 'cells', []), select('area', 'areas', []),
        select('priority', 'priorities', ['critical', 'high', 'medium', 'low'].map(p => [p, p])),
        select('state', 'states', [['active-unack', 'active, unacknowledged'], ['active-ack', 'active, acknowledged'],
          ['cleared-unack', 'cleared, unacknowledged'], ['shelved', 'shelved'], ['out-of-service', 'out of service'], ['latched', 'latched']])),
      el('table', { class: 'alarms', id: 'alarm-table' }, el('thead', {}, this.head), this.body),
      this.note);
  },
  fill(name, values) {
    const s = this.selects[name];
    const have = [...s.options].slice(1).map(o => o.value).join('\u0000');
    if (have === values.join('\u0000')) return;
    s.replaceChildren(s.options[0], ...values.map(v => el('option', { value: v, selected: S.filter[name] === v }, v)));
  },
  update() {
    this.fill('cell', [...S.cells.keys()]);
    this.fill('area', S.areas);
    this.head.replaceChildren(...COLUMNS.map(([col, title]) => el('th', {
      class: S.sort.col === col ? (S.sort.dir > 0 ? 'sorted asc' : 'sorted desc') : '',
      onclick: () => { S.sort = { col, dir: S.sort.col === col ? -S.sort.dir : (col === 'time' || col === 'priority' ? -1 : 1) }; this.update(); },
    }, title)));
    const rows = filtered();
    this.body.replaceChildren(...rows.slice(0, TABLE_ROWS).map(a => el('tr', {
      class: `row p-${a.severity} ${unacked(a) ? 'unack' : ''} ${kept(a) ? 'kept' : ''} ${active(a) ? 'active' : 'cleared'}`,
      'data-cell': a.cell, 'data-alarm': a.id,
      onclick: () => { location.hash = href('alarm', a.cell, a.id); },
    },
      el('td', {}, badge(a)), el('td', {}, stateText(a)), el('td', { class: 'time' }, when(a.raised_at)),
      el('td', {}, el('a', { href: href('cell', a.cell), onclick: e => e.stopPropagation() }, a.cell)),
      el('td', {}, el('a', { href: href('alarm', a.cell, a.id), onclick: e => e.stopPropagation() }, a.id)),
      el('td', { class: 'message' }, a.message))));
    const shownNote = rows.length > TABLE_ROWS ? `Showing ${TABLE_ROWS} of ${rows.length} alarms: filter to narrow.` : `${rows.length} alarm${rows.length === 1 ? '' : 's'}.`;
    this.note.textContent = shownNote + (S.dropped ? ` ${S.dropped} alarms not kept: more than the console's max_alarms.` : '');
  },
};

async function api(path) {
  const r = await fetch(path);
  if (r.status === 401 && (S.key || S.identity)) whoAmI();
  const body = await r.json();
  if (body.error) throw new Error(body.error);
  return body;
}

function table(cls, head, rows) {
  return el('table', { class: cls }, el('thead', {}, el('tr', {}, head.map(h => el('th', {}, h)))),
    el('tbody', {}, rows.map(r => el('tr', {}, r.map(c => el('td', {}, c))))));
}

function valueText(v) { return v === null || v === undefined ? 'unknown' : v === true ? '1' : v === false ? '0' : String(v); }

function alarmDetail(cell, id) {
  return {
    mount(v) {
      this.head = el('section', { class: 'detail-head' });
      this.diagnosis = el('section', { class: 'diagnosis' });
      this.actions = el('section', { class: 'actions' });
      this.values = el('section', { class: 'values' }, el('h3', {}, 'Values at the fault'), el('p', { class: 'note' }, 'asking the agent…'));
      this.events = el('section', { class: 'events' }, el('h3', {}, 'Events'), el('p', { class: 'note' }, 'asking the agent…'));
      this.recording = el('section', { class: 'recording' }, el('h3', {}, 'Flight recording'), el('p', { class: 'note' }, 'asking the agent…'));
      this.commands = el('section', { class: 'commands' }, el('h3', {}, 'Operator actions'));
      this.answer = el('p', { class: 'answer', id: 'answer', 'aria-live': 'polite' });
      v.append(this.head, el('div', { class: 'columns' }, el('div', {}, this.diagnosis, this.values), el('div', {}, this.actions, this.answer)), this.recording, this.events, this.commands);
      this.actionsFor = null;
      this.fetch();
    },
    async fetch() {
      try {
        const [snap, alarms, commands, recordings] = await Promise.all([
          api(`/api/cells/${encodeURIComponent(cell)}/snapshot`),
          api(`/api/cells/${encodeURIComponent(cell)}/history?kind=alarm&since=7d&limit=2000`),
          api(`/api/cells/${encodeURIComponent(cell)}/history?kind=command&since=7d&limit=2000`),
          api(`/api/cells/${encodeURIComponent(cell)}/history?kind=recording&since=7d&limit=100`),
        ]);
        const rec = recordings.rows.filter(r => r.fields.alarm === id).pop();
        this.recording.replaceChildren(el('h3', {}, 'Flight recording'), rec
          ? drawRecording(rec.fields.payload)
          : el('p', { class: 'note' }, 'No recording of this alarm in the last 7 days (one is kept for each raise, complete recorder.after after it).'));
        const fault = snap.last_fault && snap.last_fault.alarm === id ? snap.last_fault : null;
        this.values.replaceChildren(el('h3', {}, 'Values at the fault'), fault
          ? table('values', ['Tag', 'Address', 'Value', 'Quality'], fault.values.map(t => [t.name, t.address, valueText(t.value), t.quality]))
          : el('p', { class: 'note' }, 'The agent keeps the values of its last fault only; this alarm is not it.'));
        const mine = alarms.rows.filter(r => r.fields.alarm === id).reverse();
        this.events.replaceChildren(el('h3', {}, 'Events'), mine.length
          ? table('events', ['Time', 'Transition', 'State', 'By'], mine.map(r => {
            const p = r.fields.payload || {};
            const acked = p.acked_by && r.fields.transition === 'acknowledged' && p.ack_comment ? `${p.acked_by}: ${p.ack_comment}` : p.acked_by;
            const by = acked || (p.shelved && p.shelved.by) || (p.out_of_service && p.out_of_service.by) || '';
            return [when(r.at), r.fields.transition, STATE_TEXT[p.state] || p.state || '', by];
          }))
          : el('p', { class: 'note' }, 'No event of this alarm in the last 7 days.'));
        const acts = commands.rows.filter(r => r.fields.alarm === id).reverse();
        this.commands.replaceChildren(el('h3', {}, 'Operator actions'), acts.length
          ? table('actions-log', ['Time', 'Operator', 'Action', 'Stage', 'Accepted', 'Detail'],
            acts.map(r => [when(r.at), r.fields.operator, r.fields.action, r.fields.stage, r.fields.accepted ? 'yes' : 'no', r.fields.detail]))
          : el('p', { class: 'note' }, 'No operator action on this alarm in the last 7 days.'));
      } catch (err) {
        this.events.replaceChildren(el('h3', {}, 'Events'), el('p', { class: 'refused' }, err.message));
      }
    },
    update() {
      const a = S.alarms.get(alarmKey(cell, id));
      if (!a) {
        this.head.replaceChildren(el('h2', {}, `${cell} / ${id}`), el('p', { class: 'note' }, 'Not active, unacknowledged, shelved or out of service: nothing to act on.'));
        this.diagnosis.replaceChildren();
        this.renderActions(null);
        return;
      }
      const facts = [['Cell', el('a', { href: href('cell', a.cell) }, a.cell)], ['Alarm', a.id], ['Kind', a.kind], ['State', stateText(a)],
        ['Raised', when(a.raised_at)], ['Cleared', a.cleared_at ? when(a.cleared_at) : '—'], ['Acknowledged by', a.acked_by ? a.acked_by + (a.ack_comment ? `: ${a.ack_comment}` : '') : '—']];
      if (a.shelved) facts.push(['Shelved', `by ${a.shelved.by} until ${a.shelved.until ? when(a.shelved.until) : 'it clears'}: ${a.shelved.reason}`]);
      if (a.out_of_service) facts.push(['Out of service', `since ${when(a.out_of_service.at)} by ${a.out_of_service.by}: ${a.out_of_service.reason}`]);
      if (a.guidance) {
        const g = a.guidance;
        if (g.corrective_action) facts.push(['Do', el('span', { class: overdue(a) ? 'guidance overdue' : 'guidance' }, g.corrective_action + (g.response_time ? ` (within ${g.response_time})` : ''))]);
        if (g.consequence_of_inaction) facts.push(['If nobody acts', g.consequence_of_inaction]);
        if (g.class) facts.push(['Class', g.class]);
      }
      if (a.consequence) {
        const c = a.consequence;
        const through = (c.through || []).map(t => `${t.signal} = ${t.value ? 1 : 0} (${t.value ? 0 : 1} without ${c.cause}'s fault)`);
        facts.push(['Consequence of', [el('a', { href: href('alarm', a.cell, c.cause) }, c.cause),
          c.first_out !== c.cause ? ` (first-out ${c.first_out})` : '', through.length ? `: ${through.join(', ')}` : '',
          c.suppressed ? '; suppressed: not annunciated' : '']]);
      }
      this.head.replaceChildren(
        el('h2', {}, badge(a), ' ', el('span', { class: 'message' }, a.message)),
        el('dl', { class: 'facts' }, facts.map(([k, v]) => [el('dt', {}, k), el('dd', {}, v)])));
      this.diagnosis.replaceChildren(
        el('h3', {}, 'Diagnosis'),
        el('p', {}, `${a.fault_type}${a.fault_step !== null && a.fault_step !== undefined ? ` at step ${a.fault_step}` : ''}`),
        a.culprits.length
          ? table('culprits', ['Contact', 'Comment', 'Value', 'Expected', 'Trigger'],
            a.culprits.map(c => [c.address, c.comment || '', c.value ? '1' : '0', c.expected ? '1' : '0', c.trigger ? 'trigger' : '']))
          : el('p', { class: 'note' }, 'No contact named for this alarm.'));
      this.renderActions(a);
    },
    renderActions(a) {
      const sig = a ? [a.state, !!a.shelved, !!a.out_of_service, a.latched, S.key && S.key.operator].join('|') : 'none';
      if (this.actionsFor === sig) return;
      this.actionsFor = sig;
      const box = [el('h3', {}, 'Act')];
      if (!a) { this.actions.replaceChildren(); return; }
      if (!S.key) {
        box.push(el('p', { class: 'note' }, 'Load your operator key (top right) to act on this alarm. It stays in this page and signs each command here; the console never sees it.'));
        this.actions.replaceChildren(...box);
        return;
      }
      const out = this.answer;
      const done = () => this.fetch();
      const button = (label, action, fields, enabled = true) => el('button', {
        type: 'button', 'data-action': action, disabled: !enabled,
        onclick: async () => { await send(cell, Object.assign({ action, alarm: id }, fields ? fields() : {}), out); done(); },
      }, label);
      if (may('ack') && unacked(a)) {
        const comment = el('input', { name: 'ack-comment', placeholder: 'comment (optional, journaled)', maxlength: 120 });
        box.push(el('form', { class: 'form', onsubmit: async e => {
          e.preventDefault();
          const fields = comment.value.trim() ? { reason: comment.value.trim() } : {};
          await send(cell, Object.assign({ action: 'ack', alarm: id }, fields), out); done();
        } }, el('button', { type: 'submit', 'data-action': 'ack' }, 'Acknowledge'), comment));
      }
      const offered = [];
      if (may('reset') && a.latched) offered.push(button('Reset', 'reset'));
      if (may('unshelve') && a.shelved) offered.push(button('Unshelve', 'unshelve'));
      if (may('in-service') && a.out_of_service) offered.push(button('Return to service', 'in-service'));
      if (offered.length) box.push(el('div', { class: 'buttons' }, offered));
      if (may('shelve') && !a.shelved && !a.out_of_service) {
        const reason = el('input', { name: 'shelve-reason', placeholder: 'why (journaled)', required: true, maxlength: 120 });
        const length = el('select', { name: 'shelve-for' }, ['15m', '30m', '1h', '2h', '8h', 'once'].map(d => el('option', { value: d }, d === 'once' ? 'until it clears' : d)));
        box.push(el('form', { class: 'form', onsubmit: async e => {
          e.preventDefault();
          if (!reason.value.trim()) { out.className = 'answer refused'; out.textContent = 'shelve: give a reason'; return; }
          await send(cell, { action: 'shelve', alarm: id, value: length.value, reason: reason.value }, out); done();
        } }, el('span', {}, 'Shelve for '), length, reason, el('button', { type: 'submit', 'data-action': 'shelve' }, 'Shelve')));
      }
      if (may('out-of-service') && !a.out_of_service) {
        const reason = el('input', { name: 'oos-reason', placeholder: 'why (journaled)', maxlength: 120 });
        box.push(el('form', { class: 'form', onsubmit: async e => {
          e.preventDefault();
          if (!reason.value.trim()) { out.className = 'answer refused'; out.textContent = 'out of service: give a reason'; return; }
          await send(cell, { action: 'out-of-service', alarm: id, reason: reason.value }, out); done();
        } }, el('span', {}, 'Take out of service '), reason, el('button', { type: 'submit', 'data-action': 'out-of-service' }, 'Out of service')));
      }
      if (box.length === 1) box.push(el('p', { class: 'note' }, `Operator ${S.key.operator} may take no action on this alarm now.`));
      this.actions.replaceChildren(...box);
    },
  };
}

// An alarm's flight recording as a timing chart: one row per signal the
// check reads, contacts as high/low traces, numbers at their changes,
// unknown hatched, the raise marked.
function drawRecording(r) {
  const LEFT = 240, W = 760, ROW = 22, span = Math.max(1, r.to - r.from);
  const rows = r.signals || [];
  const H = rows.length * ROW + 20;
  const x = t => LEFT + Math.max(0, Math.min(W, (t - r.from) / span * W));
  const chart = svg('svg', { viewBox: `0 0 ${LEFT + W} ${H}`, class: 'recording-chart', role: 'img', 'aria-label': `recording of ${r.alarm}` });
  rows.forEach((s, i) => {
    const top = i * ROW + 3, low = top + ROW - 6, high = top + 2;
    const name = svg('text', { x: 4, y: low, class: 'signal' });
    name.textContent = s.name ? `${s.address} ${s.name}` : s.address;
    chart.append(name);
    const points = [[r.from, s.start === undefined ? null : s.start], ...(s.changes || [])];
    points.forEach(([t, v], k) => {
      const end = k + 1 < points.length ? points[k + 1][0] : r.to;
      const x0 = x(Math.max(t, r.from)), x1 = x(end);
      if (v === null || v === undefined) {
        chart.append(svg('rect', { x: x0, y: high, width: Math.max(1, x1 - x0), height: low - high, class: 'unknown' }));
      } else if (typeof v === 'boolean') {
        const y = v ? high : low;
        chart.append(svg('line', { x1: x0, y1: y, x2: x1, y2: y, class: 'trace' }));
        if (k > 0) chart.append(svg('line', { x1: x0, y1: high, x2: x0, y2: low, class: 'trace' }));
      } else {
        chart.append(svg('line', { x1: x0, y1: low, x2: x1, y2: low, class: 'trace' }));
        if (k > 0) chart.append(svg('line', { x1: x0, y1: high, x2: x0, y2: low, class: 'trace' }));
        const label = svg('text', { x: x0 + 3, y: low - 3, class: 'value' });
        label.textContent = String(v);
        chart.append(label);
      }
    });
  });
  const raise = x(r.raised_at);
  chart.append(svg('line', { x1: raise, y1: 0, x2: raise, y2: H - 16, class: 'raise' }));
  for (const [t, anchor] of [[r.from, 'start'], [r.raised_at, 'middle'], [r.to, 'end']]) {
    const label = svg('text', { x: x(t), y: H - 4, 'text-anchor': anchor });
    const s = (t - r.raised_at) / 1000;
    label.textContent = t === r.raised_at ? `raised ${when(t)}` : `${s > 0 ? '+' : ''}${s} s`;
    chart.append(label);
  }
  const cut = r.truncated || {};
  const notes = [];
  if (cut.start) notes.push(`holds only from ${when(r.holds_from)} (${cut.start})`);
  if (cut.end) notes.push(`holds only until ${when(r.holds_to)} (${cut.end})`);
  return el('div', {}, chart,
    el('p', { class: 'note' }, `The ${rows.length} signals ${r.alarm}'s check reads, from ${(r.from - r.raised_at) / 1000} s to +${(r.to - r.raised_at) / 1000} s around its raise; a grey band: the value was unknown.`),
    notes.length ? el('p', { class: 'note' }, 'Cut short: ' + notes.join('; ')) : null);
}

const PERIODS = [['1h', 'last hour'], ['8h', 'last 8 hours'], ['24h', 'last 24 hours'], ['7d', 'last 7 days']];

function cellPage(cell) {
  return {
    period: '1h',
    mount(v) {
      this.head = el('section', { class: 'detail-head' });
      this.timeline = el('section', { class: 'timeline' });
      this.alarms = el('section', {});
      this.charts = el('section', { class: 'charts' });
      this.timers = el('section', { class: 'timers' });
      this.answer = el('p', { class: 'answer', id: 'answer', 'aria-live': 'polite' });
      this.tags = el('section', { class: 'tags' });
      const period = el('select', { name: 'period', onchange: e => { this.period = e.target.value; this.fetch(); } },
        PERIODS.map(([p, t]) => el('option', { value: p, selected: p === this.period }, t)));
      this.write = el('section', { class: 'write' });
      this.production = el('section', { class: 'production' });
      this.oee = el('section', { class: 'oee' });
      v.append(this.head, el('div', { class: 'period' }, el('span', {}, 'Machine state over the '), period), this.timeline, this.production, this.oee, this.alarms, this.charts, this.timers, this.write, this.answer, this.tags);
      this.drawWrite();
      this.drawn = '';
      this.fetch();
      // The charts and tags live: the cell's snapshot every second while
      // this page is shown.
      const tick = async () => {
        if (S.view !== this) return;
        if (!document.hidden) await this.live();
        setTimeout(tick, 1000);
      };
      setTimeout(tick, 1000);
    },
    async live() {
      try {
        this.snap = await api(`/api/cells/${encodeURIComponent(cell)}/snapshot`);
        this.drawLive();
      } catch (err) {
        this.tags.replaceChildren(el('p', { class: 'refused' }, err.message));
      }
    },
    drawLive() {
      const snap = this.snap;
      if (!snap) return;
      const stuck = new Set([...S.alarms.values()].filter(a => a.cell === cell && a.kind === 'step' && active(a) && !kept(a)).map(a => a.id));
      const drawn = JSON.stringify([snap.charts || [], snap.timers || [], [...stuck], S.key && S.key.operator, snap.tags, snap.oee || null]);
      if (drawn === this.drawn) return;
      this.drawn = drawn;
      this.drawOee(snap.oee);
      const charts = snap.charts || [];
      this.charts.replaceChildren(...(charts.length ? [el('h3', {}, 'Charts')] : []), ...charts.map(c => this.chart(c, stuck)));
      this.drawTimers(snap.timers || []);
      this.tags.replaceChildren(el('h3', {}, 'Tags now'),
        table('values', ['Tag', 'Address', 'Value', 'Quality'], snap.tags.map(t => [t.name, t.address, valueText(t.value), t.quality])));
    },
    drawTimers(timers) {
      if (!timers.length) { this.timers.replaceChildren(); return; }
      const secs = ms => (ms / 1000).toFixed(1);
      this.timers.replaceChildren(el('h3', {}, 'Transition timers: the last measurements against their windows'),
        el('table', { class: 'timers' }, el('thead', {}, el('tr', {}, ['Transition', 'Measures', 'Window (s)', 'Learned (s)', 'Last measurements (s), newest last'].map(h => el('th', {}, h)))),
          el('tbody', {}, timers.map(t => el('tr', { 'data-timer': t.alarm },
            el('td', {}, t.alarm), el('td', {}, t.label), el('td', {}, `${secs(t.window_ms[0])} – ${secs(t.window_ms[1])}`), el('td', {}, secs(t.delta_ms)),
            el('td', { class: 'measured' }, t.recent.length ? t.recent.map(m => {
              const out = m.ms < t.window_ms[0] ? 'early' : m.ms > t.window_ms[1] ? 'late' : 'in';
              return el('span', { class: `m ${out}`, title: `${when(m.at)}: ${m.ms} ms (${out === 'in' ? 'in its window' : out})` }, secs(m.ms));
            }) : 'none yet'))))));
    },
    drawProduction(d) {
      if (d.refused) { this.production.replaceChildren(el('h3', {}, 'Production today'), el('p', { class: 'refused' }, d.refused)); return; }
      const m = d.total;
      const parts = [el('h3', {}, 'Production today')];
      parts.push(el('dl', { class: 'facts' },
        el('dt', {}, 'Parts'), el('dd', { 'data-production': 'parts' }, String(d.production)),
        el('dt', {}, 'Availability'), el('dd', {}, d.availability === null ? '—' : `${d.availability.toFixed(1)} %`),
        el('dt', {}, 'Minutes'), el('dd', {}, `running ${m.running.toFixed(1)}, idle ${m.idle.toFixed(1)}, in fault ${m.fault.toFixed(1)}, offline or no data ${m.offline.toFixed(1)}`)));
      if (d.orders.length) {
        parts.push(table('orders', ['Item', 'Target', 'Parts', 'From', 'Until'], d.orders.map(o => [o.item || '—', o.target === null ? '—' : String(o.target), String(o.parts), when(o.from), when(o.to)])));
      }
      if (d.stop_causes.length) {
        parts.push(table('causes', ['Stop', 'Cause', 'Stops', 'Minutes'], d.stop_causes.map(c => [c.code, c.name, String(c.count), c.minutes.toFixed(1)])));
      }
      this.production.replaceChildren(...parts);
    },
    // The current shift's OEE, as the agent computes it (its snapshot).
    drawOee(o) {
      if (!o) { this.oee.replaceChildren(); return; }
      const pct = v => v === null || v === undefined ? '—' : `${(100 * v).toFixed(1)} %`;
      const min = ms => (ms / 60000).toFixed(1);
      const l = o.losses;
      const parts = [el('h3', {}, `OEE of the ${o.shift} shift, ${when(o.from)} – ${when(o.until)}`),
        el('dl', { class: 'facts' },
          el('dt', {}, 'OEE'), el('dd', { 'data-oee': 'oee' }, pct(o.oee)),
          el('dt', {}, 'Availability'), el('dd', { 'data-oee': 'availability' }, pct(o.availability)),
          el('dt', {}, 'Performance'), el('dd', { 'data-oee': 'performance' }, pct(o.performance)),
          el('dt', {}, 'Quality'), el('dd', { 'data-oee': 'quality' }, pct(o.quality)),
          el('dt', {}, 'Minutes'), el('dd', {}, `planned ${min(o.planned_ms)}, run ${min(o.run_ms)}, breaks and planned stops ${min(o.not_planned_ms)}, not observed ${min(o.unobserved_ms)}`),
          el('dt', {}, 'Parts'), el('dd', { 'data-oee': 'parts' }, `${o.parts}, ${o.rejects} rejected`)),
        table('losses', ['Loss', 'Minutes'], [['Breakdowns', min(l.breakdowns_ms)], ['Setup and adjustment', min(l.setup_ms)],
          ['Small stops', min(l.small_stops_ms)], ['Reduced speed', min(l.reduced_speed_ms)],
          ['Start-up rejects', min(l.startup_rejects_ms)], ['Production rejects', min(l.production_rejects_ms)]])];
      if (o.breakdowns.length) {
        parts.push(table('causes', ['Stop', 'Cause', 'Stops', 'Minutes'], o.breakdowns.map(b => [b.code, b.name, String(b.stops), min(b.ms)])));
      }
      this.oee.replaceChildren(...parts);
    },
    drawWrite() {
      if (!may('write')) { this.write.replaceChildren(); return; }
      const tag = el('input', { name: 'write-tag', placeholder: 'tag address', maxlength: 64 });
      const value = el('input', { name: 'write-value', placeholder: 'value', maxlength: 64 });
      this.write.replaceChildren(el('h3', {}, 'Write to the PLC'), el('form', { class: 'form', onsubmit: async e => {
        e.preventDefault();
        if (!tag.value.trim() || !value.value.trim()) { this.answer.className = 'answer refused'; this.answer.textContent = 'write: give a tag and a value'; return; }
        await send(cell, { action: 'write', tag: tag.value.trim(), value: value.value.trim() }, this.answer);
      } }, tag, el('span', {}, ' = '), value, el('button', { type: 'submit', 'data-action': 'write' }, 'Write')),
      el('p', { class: 'note' }, 'The agent writes only what its cell lets operators write (a legacy unit\'s item code, target or production correction), journals the request before it goes to the PLC, and answers with the PLC\'s answer.'));
    },
    chart(c, stuck) {
      const rows = [];
      const bit = v => v === null || v === undefined ? 'unknown' : v ? '1' : '0';
      c.steps.forEach((st, i) => {
        const full = `${c.name}.${st.name}`;
        const isStuck = stuck.has(st.alarm);
        rows.push(el('div', { class: `sfc-step ${st.active ? 'active' : ''} ${isStuck ? 'stuck' : ''} ${c.initial === st.name ? 'initial' : ''}`, 'data-step': full },
          el('span', { class: 'box' }, st.name),
          el('span', { class: 'what' }, st.comment || ''),
          isStuck ? el('span', { class: 'flag' }, 'STUCK') : st.active ? el('span', { class: 'flag on' }, 'active') : null));
        for (const t of c.transitions.filter(t => t.from[0] === full)) {
          const next = c.steps[i + 1] ? `${c.name}.${c.steps[i + 1].name}` : null;
          const jump = t.to.length !== 1 || t.to[0] !== next;
          const leavesStuck = t.from.some(f => { const s = c.steps.find(x => `${c.name}.${x.name}` === f); return s && stuck.has(s.alarm); });
          const offer = t.forcible && leavesStuck && may('force');
          rows.push(el('div', { class: `sfc-trans ${t.holds === true ? 'holds' : t.holds === false ? 'waits' : 'unknown'}`, 'data-transition': `${c.name}.${t.id}` },
            el('span', { class: 'bar' }),
            el('span', { class: 'tid' }, t.id),
            el('div', { class: 'cond' },
              el('div', {}, el('code', {}, t.condition), t.comment ? ` — ${t.comment}` : '', `: ${t.holds === true ? 'holds' : t.holds === false ? 'does not hold' : 'unknown'}`),
              el('div', { class: 'operands' }, t.operands.map(o => el('span', { class: `operand v${bit(o.value)}` }, `${o.address} = ${bit(o.value)}${o.comment ? ' (' + o.comment + ')' : ''}`))),
              jump ? el('div', { class: 'to' }, `→ ${t.to.join(' + ')}`) : null,
              t.from.length > 1 ? el('div', { class: 'to' }, `leaves ${t.from.join(' + ')}`) : null),
            offer ? el('button', { type: 'button', 'data-action': 'force', onclick: () => send(cell, { action: 'force', value: `${c.name}.${t.id}` }, this.answer) }, `Force ${t.id}`) : null));
        }
      });
      return el('div', { class: 'chart', 'data-chart': c.name }, el('h4', {}, `Chart ${c.name}`), rows);
    },
    async fetch() {
      try {
        const [history, day] = await Promise.all([
          api(`/api/cells/${encodeURIComponent(cell)}/history?kind=state&since=${this.period}&limit=5000`),
          // The production day is the agent's own figure: without the agent,
          // the timeline (from the plant archive) is still drawn.
          api(`/api/cells/${encodeURIComponent(cell)}/history?kind=production&since=${encodeURIComponent(midnight())}`).catch(err => ({ refused: err.message })),
          this.live(),
        ]);
        this.drawTimeline(history.rows);
        if (history.from === 'archive') this.timeline.append(el('p', { class: 'note' }, 'From the plant archive: the agent does not answer.'));
        this.drawProduction(day);
      } catch (err) {
        this.timeline.replaceChildren(el('p', { class: 'refused' }, err.message));
      }
    },
    drawTimeline(rows) {
      const now = Date.now();
      const span = { '1h': 3600e3, '8h': 8 * 3600e3, '24h': 24 * 3600e3, '7d': 7 * 24 * 3600e3 }[this.period];
      const from = now - span;
      const W = 1000, H = 28;
      const chart = svg('svg', { viewBox: `0 0 ${W} ${H + 16}`, class: 'states', role: 'img', 'aria-label': 'machine state timeline' });
      const x = t => Math.max(0, Math.min(W, (t - from) / span * W));
      rows.forEach((r, i) => {
        const end = i + 1 < rows.length ? rows[i + 1].at : now;
        if (end < from) return;
        const rect = svg('rect', { x: x(r.at), y: 0, width: Math.max(1, x(end) - x(r.at)), height: H, class: `k-${r.fields.kind}` });
        const t = svg('title', {});
        t.textContent = `${r.fields.kind} ${r.fields.state || ''} ${r.fields.fault_type || ''} from ${when(r.at)}`;
        rect.append(t);
        chart.append(rect);
      });
      for (let i = 0; i <= 4; i++) {
        const label = svg('text', { x: Math.min(W - 4, Math.max(4, i * W / 4)), y: H + 13, 'text-anchor': i === 0 ? 'start' : i === 4 ? 'end' : 'middle' });
        label.textContent = when(from + i * span / 4).slice(5, 16);
        chart.append(label);
      }
      const legend = el('div', { class: 'legend' }, ['normal', 'fault', 'recovery', 'offline'].map(k => el('span', { class: `key k-${k}` }, k)));
      this.timeline.replaceChildren(chart, legend);
      if (!rows.length) this.timeline.append(el('p', { class: 'note' }, 'No change of state in this period.'));
    },
    update() {
      const c = S.cells.get(cell);
      if (!c) { this.head.replaceChildren(el('h2', {}, cell), el('p', { class: 'refused' }, 'No such cell in the plant trust file.')); return; }
      const [comm, commClass] = commOf(c);
      const s = c.state;
      this.head.replaceChildren(
        el('h2', {}, `Cell ${cell}`, c.area ? el('span', { class: 'area' }, ` — ${c.area}`) : null),
        el('dl', { class: 'facts' },
          el('dt', {}, 'Machine state'), el('dd', { class: `state-${s ? s.state : 'unknown'}` }, s ? `${s.state}${s.fault_type ? ' — ' + s.fault_type : ''}${s.element ? ' (' + s.element + ')' : ''} since ${when(s.since)}` : 'unknown'),
          el('dt', {}, 'Communication'), el('dd', { class: commClass }, comm),
          s && s.item ? [el('dt', {}, 'Order'), el('dd', {}, `${s.item}${s.target ? ', target ' + s.target : ''}`)] : null,
          el('dt', {}, 'Last fault'), el('dd', {}, c.last_fault ? `${when(c.last_fault.at)} ${c.last_fault.alarm}${c.last_fault.message ? ': ' + c.last_fault.message : ''}` : 'none seen')));
      const mine = [...S.alarms.values()].filter(a => a.cell === cell).sort((x, y) => (x.raised_at < y.raised_at ? 1 : -1));
      this.alarms.replaceChildren(el('h3', {}, 'Alarms'), mine.length
        ? el('table', { class: 'alarms' }, el('tbody', {}, mine.map(a => el('tr', { class: `row p-${a.severity} ${unacked(a) ? 'unack' : ''}`, onclick: () => { location.hash = href('alarm', a.cell, a.id); } },
          el('td', {}, badge(a)), el('td', {}, stateText(a)), el('td', { class: 'time' }, when(a.raised_at)),
          el('td', {}, el('a', { href: href('alarm', a.cell, a.id) }, a.id)), el('td', { class: 'message' }, a.message)))))
        : el('p', { class: 'note' }, 'No alarm to show.'));
      this.drawLive();
    },
  };
}


const KPI_PERIODS = [['1h', 'last hour'], ['8h', 'last 8 hours (a shift)'], ['24h', 'last 24 hours'], ['7d', 'last 7 days']];

function fixed(n, d = 2) { return typeof n === 'number' ? n.toFixed(d) : '—'; }

// A duration in ms for people: 60 s, 5 min, 24 h.
function span(ms) {
  if (ms % 3600000 === 0) return `${ms / 3600000} h`;
  if (ms % 60000 === 0 && ms >= 120000) return `${ms / 60000} min`;
  return `${ms / 1000} s`;
}

const kpiView = {
  period: '24h',
  mount(v) {
    const period = el('select', { name: 'kpi-period', onchange: e => { this.period = e.target.value; this.fetch(); } },
      KPI_PERIODS.map(([p, t]) => el('option', { value: p, selected: p === this.period }, t)));
    this.body = el('section', { class: 'kpi' }, el('p', { class: 'note' }, 'asking the agents…'));
    this.standing = el('section', { class: 'standing' });
    v.append(el('h2', {}, 'Alarm performance (ISA-18.2)'), el('div', { class: 'period' }, el('span', {}, 'Over the '), period),
      this.body, this.standing);
    this.fetch();
  },
  async fetch() {
    try {
      const r = await api(`/api/kpi?since=${this.period}`);
      this.draw(r.cells);
    } catch (err) {
      this.body.replaceChildren(el('p', { class: 'refused' }, err.message));
    }
  },
  draw(cells) {
    const ok = cells.filter(c => c.report);
    const failed = cells.filter(c => c.error);
    const raised = ok.reduce((n, c) => n + c.report.raised, 0);
    const rate = ok.reduce((n, c) => n + c.report.average_rate, 0);
    const top = ok.flatMap(c => c.report.top.map(t => ({ cell: c.cell, ...t }))).sort((a, b) => b.raised - a.raised).slice(0, 10);
    const chattering = ok.flatMap(c => c.report.chattering.map(t => ({ cell: c.cell, rules: c.report.rules, ...t })));
    const stale = ok.flatMap(c => c.report.stale.map(t => ({ cell: c.cell, ...t })));
    const met = b => b.met === null || b.met === undefined ? '' : b.met ? 'met' : 'NOT MET';
    this.body.replaceChildren(
      el('dl', { class: 'facts' },
        el('dt', {}, 'Alarms raised'), el('dd', { 'data-kpi': 'raised' }, String(raised)),
        el('dt', {}, 'Alarms per 10 minutes, plant'), el('dd', { 'data-kpi': 'rate' }, fixed(rate)),
        el('dt', {}, 'Cells'), el('dd', {}, `${ok.length} answered${failed.length ? `, ${failed.length} did not: ${failed.map(c => `${c.cell} (${c.error})`).join('; ')}` : ''}`)),
      el('h3', {}, 'Per cell'),
      table('kpi-cells', ['Cell', 'Area', 'Raised', 'Per 10 min', 'Peak / 10 min', 'Flood %', 'Top 10 share %', 'Chattering', 'Stale', 'Shelved', 'Out of service', 'Median ack'],
        ok.map(c => {
          const r = c.report;
          return [el('a', { href: href('cell', c.cell) }, c.cell), c.area || '', String(r.raised), fixed(r.average_rate), String(r.peak_rate),
            fixed(r.flood_percent), fixed(r.top_share, 1), String(r.chattering.length), String(r.stale.length), String(r.shelved), String(r.out_of_service),
            r.ack.median === null ? '—' : `${fixed(r.ack.median, 1)} s`];
        })),
      el('h3', {}, 'Top 10 alarms'),
      top.length ? table('kpi-top', ['Cell', 'Alarm', 'Raised', 'Share of its cell %'], top.map(t => [t.cell, t.id, String(t.raised), fixed(t.share, 1)]))
        : el('p', { class: 'note' }, 'No alarm raised in this period.'),
      el('h3', {}, 'Chattering (by each cell\'s rule; ISA-18.2: 3 or more raises within 60 s)'),
      chattering.length ? table('kpi-chattering', ['Cell', 'Alarm', 'Raises', 'Within'], chattering.map(t => [t.cell, t.id, String(t.raises_in_window), span(t.rules.chatter_window_ms)]))
        : el('p', { class: 'note' }, 'None.'),
      el('h3', {}, 'Stale (by each cell\'s rule; ISA-18.2: active longer than 24 h)'),
      stale.length ? table('kpi-stale', ['Cell', 'Alarm', 'Raised', 'Hours'], stale.map(t => [t.cell, t.id, when(t.raised_at), fixed(t.hours, 1)]))
        : el('p', { class: 'note' }, 'None.'),
      el('h3', {}, 'Against the ISA-18.2 targets'),
      table('kpi-benchmarks', ['Cell', 'Figure', 'Value', 'Target', ''],
        ok.flatMap(c => c.report.benchmarks.filter(b => b.met === false).map(b => [c.cell, b.metric, b.value, b.target, met(b)]))
          .concat(ok.every(c => c.report.benchmarks.every(b => b.met !== false)) ? [['every cell', 'every figure', '', '', 'met']] : [])));
    this.update();
  },
  update() {
    const now = Date.now();
    const standing = [...S.alarms.values()].filter(a => active(a) && !kept(a)).sort((x, y) => (x.raised_at < y.raised_at ? -1 : 1));
    this.standing.replaceChildren(el('h3', {}, 'Standing now (active, oldest first)'), standing.length
      ? table('kpi-standing', ['Cell', 'Alarm', 'Priority', 'Raised', 'Active for'], standing.slice(0, 50).map(a => {
        const mins = Math.max(0, Math.round((now - Date.parse(a.raised_at)) / 60000));
        return [a.cell, el('a', { href: href('alarm', a.cell, a.id) }, a.id), a.severity, when(a.raised_at), mins >= 120 ? `${(mins / 60).toFixed(1)} h` : `${mins} min`];
      }))
      : el('p', { class: 'note' }, 'No alarm active.'));
  },
};

// ---- agents: what each runs, against what the plant deployed ----

const agentsView = {
  mount(v) {
    this.body = el('section', { class: 'agents' }, el('p', { class: 'note' }, 'asking the agents…'));
    v.append(el('h2', {}, 'Agents'),
      el('p', { class: 'note' }, 'Each agent\'s signed answer about itself, judged as ', el('code', {}, 'cellwatch plant check'), ' judges it.'),
      this.body);
    this.fetch();
  },
  async fetch() {
    try {
      this.draw(await api('/api/agents'));
    } catch (err) {
      this.body.replaceChildren(el('p', { class: 'refused' }, err.message));
    }
  },
  draw(r) {
    const wrong = r.cells.filter(c => c.problems.length);
    const d = r.deployed;
    const against = !d ? 'No plant file given (plant.deployed): judged against this console\'s version and the certificates\' ends only.'
      : d.error ? `What the plant deployed cannot be read: ${d.error}` : `Against what the plant deployed (${d.file}).`;
    const cert = a => a && a.bus_certificate ? when(a.bus_certificate.not_after) : '—';
    this.body.replaceChildren(
      el('p', { class: d && d.error ? 'refused' : 'note' }, against),
      el('p', { 'data-agents': 'summary', class: wrong.length ? 'refused' : 'note' },
        wrong.length ? `${wrong.length} of ${r.cells.length} agents wrong` : `${r.cells.length} agent${r.cells.length === 1 ? '' : 's'}, nothing wrong`),
      table('agents', ['Cell', 'Area', 'Version', 'Running since', 'Configuration', 'Operators list', 'Certificate until', 'Judged'],
        r.cells.map(c => {
          const a = c.about;
          const judged = c.problems.length
            ? el('ul', { class: 'problems' }, ...c.problems.map(p => el('li', {}, p)))
            : el('span', { class: 'ok' }, 'ok — ' + c.facts.join(', '));
          return [el('a', { href: href('cell', c.cell) }, c.cell), c.area || '', a ? a.version : '—', a ? when(a.started) : '—',
            a ? el('code', { title: a.config_sha256 }, a.config_sha256.slice(0, 12)) : '—',
            a ? (a.operators_version === null || a.operators_version === undefined ? 'operators file' : `v${a.operators_version}`) : '—',
            cert(a), judged];
        })));
  },
  update() {},
};

// ---- routing ----

function banner() {
  let unack = 0, act = 0, late = 0, ringing = 0;
  for (const a of S.alarms.values()) {
    if (kept(a)) continue;
    if (active(a)) act++;
    if (unacked(a)) unack++;
    if (overdue(a)) late++;
    if (rings(a)) ringing++;
  }
  const b = document.getElementById('banner');
  b.textContent = `${act} active, ${unack} unacknowledged, ${late} overdue`;
  S.late = late;
  b.className = unack ? 'alert' : '';
  document.body.dataset.ringing = ringing ? 'yes' : 'no';
  document.getElementById('silence').hidden = !ringing;
}

// ---- the horn ----
// A tone every 2 s while an alarm rings. Browsers let a page sound only
// after a click on it: the first click anywhere readies the horn.
const horn = {
  ctx: null,
  ready() {
    if (!this.ctx && window.AudioContext) this.ctx = new AudioContext();
    if (this.ctx && this.ctx.state === 'suspended') this.ctx.resume();
  },
  beep() {
    if (!this.ctx || this.ctx.state !== 'running') return;
    const o = this.ctx.createOscillator();
    const g = this.ctx.createGain();
    o.frequency.value = 880;
    g.gain.value = 0.2;
    o.connect(g).connect(this.ctx.destination);
    o.start();
    o.stop(this.ctx.currentTime + 0.4);
  },
};

function silence() {
  for (const a of S.alarms.values()) if (rings(a)) S.silenced.add(occurrence(a));
  banner();
}

function sound() {
  const late = S.late;
  banner();
  // An alarm just became overdue: the page says so where it shows it.
  if (S.late !== late && S.view) S.view.update();
  if (document.body.dataset.ringing === 'yes') horn.beep();
}

function update() {
  banner();
  if (S.view) S.view.update();
}

function route() {
  const parts = location.hash.replace(/^#\/?/, '').split('/').map(decodeURIComponent);
  let view;
  if (parts[0] === 'alarms') view = alarmsView;
  else if (parts[0] === 'kpi') view = kpiView;
  else if (parts[0] === 'agents') view = agentsView;
  else if (parts[0] === 'alarm' && parts.length === 3) view = alarmDetail(parts[1], parts[2]);
  else if (parts[0] === 'cell' && parts.length === 2) view = cellPage(parts[1]);
  else view = overview;
  for (const a of document.querySelectorAll('nav a')) {
    a.classList.toggle('here', a.dataset.route === (parts[0] || 'overview'));
  }
  const main = document.getElementById('view');
  main.replaceChildren();
  main.dataset.view = parts[0] || 'overview';
  S.view = view;
  view.mount(main);
  view.update();
}

async function start() {
  const file = document.getElementById('key-file');
  file.addEventListener('change', async () => {
    const f = file.files[0];
    file.value = '';
    if (!f) return;
    try {
      S.key = await loadKey(f);
      S.identity = { identity: S.key.operator, by: 'operator key' };
      showOperator();
      connect();
    } catch (err) {
      S.key = null;
      showOperator(err.message);
    }
    route();
  });
  document.getElementById('forget-key').addEventListener('click', async () => {
    S.key = null;
    await fetch('/api/sign-out', { method: 'POST' });
    await whoAmI();
    showOperator();
    route();
  });
  window.addEventListener('hashchange', route);
  document.getElementById('silence').addEventListener('click', silence);
  document.addEventListener('click', () => horn.ready());
  // Overdue is a matter of time passing: the banner and the horn follow it.
  setInterval(sound, 2000);
  await whoAmI();
  showOperator();
  route();
  S.started = true;
}

document.addEventListener('DOMContentLoaded', start);
