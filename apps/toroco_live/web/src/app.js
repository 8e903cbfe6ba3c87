// The dashboard page of toroco_live. It lives on one WebSocket (/ws): the
// node pushes "state" frames (every behavior and device with its inputs
// and outputs, see toroco_live_state) and "world" frames (the simulated
// arena, see toroco_live_world_json). The wiring is laid out with elkjs
// when its shape changes and only restyled otherwise. Controls are POSTs
// to /api/control; the page's session cookie (set by the node at the first
// visit with ?token=T, which it then drops from the address) carries the
// right to drive the robot, and the node says on the WebSocket whether
// this page has it ("session" frame).
'use strict';

let controls = false;      // whether the node takes this page's controls
const $ = (sel) => document.querySelector(sel);
const SVG = 'http://www.w3.org/2000/svg';
const elk = new ELK();

let state = null;          // the last state frame
let shapeKey = null;       // what the current layout was made for
let layout = null;         // {wires: Map(id -> {path, label, ...}), ...}
let selected = null;       // the behavior whose inspect/1 is shown

const srcKey = (s) => (s ? s[0] + '.' + s[1] : '');
const same = (a, b) => !!a && !!b && a[0] === b[0] && a[1] === b[1];
function el(tag, attrs, parent) {
  const e = document.createElementNS(SVG, tag);
  for (const k in attrs) e.setAttribute(k, attrs[k]);
  if (parent) parent.appendChild(e);
  return e;
}
function text(s) { return s === null || s === undefined ? '-' : String(s); }
function term(c) { return c ? c.term : '-'; }

// ---------------------------------------------------------------- socket
function connect() {
  const ws = new WebSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`);
  ws.onopen = () => { $('#conn').textContent = 'live'; $('#conn').className = 'good'; };
  ws.onclose = () => {
    $('#conn').textContent = 'disconnected, retrying'; $('#conn').className = 'bad';
    setTimeout(connect, 1000);
  };
  ws.onmessage = (m) => {
    const f = JSON.parse(m.data);
    if (f.type === 'hello') $('#node').textContent = f.node;
    else if (f.type === 'session') { controls = !!f.controls; if (state) renderControls(state); }
    else if (f.type === 'state') onState(f);
    else if (f.type === 'world') onWorld(f);
  };
}

// ---------------------------------------------------------------- state
function onState(s) {
  state = s;
  window.torocoFrames = (window.torocoFrames || 0) + 1;
  const d = s.dashboard || {};
  $('#stats').textContent = `clients ${text(d.clients)} · skipped ${text(d.skipped)}` +
    (d.tap ? '' : ' · no tap') + (s.error ? ' · ' + s.error : '');
  renderNodes(s); renderInputs(s); renderDevices(s); renderControls(s);
  const key = JSON.stringify(s.nodes.map((n) => [n.name, n.kind, n.layer,
    n.inputs.map((i) => [i.input, i.sources.map((x) => x.source)]),
    n.outputs.map((o) => [o.output, o.inhibitors])]));
  if (key !== shapeKey) { shapeKey = key; relayout(s).then(() => restyle(s)); }
  else if (layout) restyle(s);
  if (selected) showDetails(selected, false);
}

function renderNodes(s) {
  const body = $('#nodes tbody');
  body.innerHTML = '';
  const nodes = [...s.nodes].sort((a, b) =>
    (a.kind === b.kind ? (b.layer - a.layer) || a.name.localeCompare(b.name) : a.kind === 'behavior' ? -1 : 1));
  for (const n of nodes) {
    const tr = document.createElement('tr');
    tr.dataset.name = n.name;
    tr.className = n.status + (n.name === selected ? ' selected' : '');
    tr.innerHTML = `<td>${n.name} <small>${n.kind === 'device' ? 'device' : ''}</small></td>` +
      `<td>${n.layer}</td><td class="status">${n.status}</td>` +
      `<td class="mono">${esc(n.state.term === null ? n.state.note : n.state.term)}</td>` +
      `<td class="restarts">${n.restarts}</td><td class="mailbox">${text(n.mailbox)}</td>`;
    tr.onclick = () => select(n.name);
    body.appendChild(tr);
  }
}

function renderInputs(s) {
  const body = $('#inputs tbody');
  body.innerHTML = '';
  for (const n of s.nodes) for (const i of n.inputs) {
    if (!i.sources.length) continue;
    const tr = document.createElement('tr');
    tr.dataset.input = n.name + '/' + i.input;
    tr.innerHTML = `<td>${n.name}.${i.input}</td><td class="winner">${i.winner ? srcKey(i.winner) : 'none'}</td>` +
      `<td class="holds mono">${i.holds.map((h) => srcKey(h.source) + ' ' + h.ms).join('<br>') || '-'}</td>` +
      `<td class="latches mono">${i.latches.map((l) => srcKey(l.source) + '=' + esc(l.term)).join('<br>') || '-'}</td>` +
      `<td class="last mono">${esc(term(i.last))}</td><td class="rate">${i.rate}</td>`;
    body.appendChild(tr);
  }
}

function renderDevices(s) {
  const body = $('#devices tbody');
  body.innerHTML = '';
  for (const n of s.nodes) if (n.device) {
    const tr = document.createElement('tr');
    tr.dataset.device = n.name;
    const c = n.device;
    const cells = typeof c === 'object' && !Array.isArray(c)
      ? Object.keys(c).map((k) => `${k} <b>${esc(JSON.stringify(c[k]))}</b>`).join(' · ') : esc(JSON.stringify(c));
    tr.innerHTML = `<td>${n.name}</td><td class="mono">${cells}</td>`;
    body.appendChild(tr);
  }
}

function renderControls(s) {
  $('#mode').textContent = controls ? 'controls on (session)' : 'read-only: open the URL with ?token=T once for controls';
  $('#controls-note').textContent = controls ? '' : 'read-only without the token: the node will refuse';
  fill($('#control-name'), s.nodes.filter((n) => n.kind === 'behavior').map((n) => n.name));
  fill($('#inject-source'), s.nodes.flatMap((n) => n.outputs.map((o) => n.name + '.' + o.output)));
}
function fill(select, values) {
  const now = [...select.options].map((o) => o.value);
  if (JSON.stringify(now) === JSON.stringify(values)) return;
  const keep = select.value;
  select.innerHTML = values.map((v) => `<option>${v}</option>`).join('');
  if (values.includes(keep)) select.value = keep;
}

function esc(s) {
  return String(s === undefined || s === null ? '-' : s)
    .replace(/&/g, '&amp;').replace(/</g, '&lt;').replace(/>/g, '&gt;');
}

// ---------------------------------------------------------------- wiring
// Nodes: a box per behavior and device; an S node per input with two or
// more sources; an I node per inhibited output. Wires run from a source's
// emitter (or its I node) to the receiver (or the input's S node).
function graph(s) {
  const children = [], edges = [];
  const outFrom = new Map(); // "E.O" -> node id the output's wires start from
  for (const n of s.nodes) {
    children.push({ id: 'n:' + n.name, width: 128, height: 40 });
    for (const o of n.outputs) if (o.inhibitors.length) {
      const id = `i:${n.name}.${o.output}`;
      children.push({ id, width: 22, height: 22 });
      edges.push({ id: `o:${n.name}.${o.output}`, sources: ['n:' + n.name], targets: [id] });
      outFrom.set(n.name + '.' + o.output, id);
      o.inhibitors.forEach((x, k) => edges.push({
        id: `x:${n.name}.${o.output}:${k}`, sources: [from(x)], targets: [id], inhibitor: true }));
    }
  }
  function from(src) { return outFrom.get(srcKey(src)) || 'n:' + src[0]; }
  for (const n of s.nodes) for (const i of n.inputs) {
    if (!i.sources.length) continue;
    const inp = n.name + '/' + i.input;
    let target = 'n:' + n.name;
    if (i.sources.length > 1) {
      target = 's:' + inp;
      children.push({ id: target, width: 22, height: 22 });
      edges.push({ id: 'd:' + inp, sources: [target], targets: ['n:' + n.name] });
    }
    i.sources.forEach((x) => edges.push({ id: `w:${inp}:${x.priority}`, sources: [from(x.source)], targets: [target] }));
  }
  return { children, edges, outFrom };
}

async function relayout(s) {
  const g = graph(s);
  const known = new Set(g.children.map((c) => c.id));
  const edges = g.edges.filter((e) => known.has(e.sources[0]) && known.has(e.targets[0]));
  const res = await elk.layout({
    id: 'root',
    layoutOptions: { 'elk.algorithm': 'layered', 'elk.direction': 'RIGHT',
      'elk.layered.spacing.nodeNodeBetweenLayers': '46', 'elk.spacing.nodeNode': '18',
      'elk.edgeRouting': 'SPLINES' },
    children: g.children, edges: edges.map((e) => ({ id: e.id, sources: e.sources, targets: e.targets })),
  });
  const svg = $('#wiring-svg');
  svg.innerHTML = '';
  // Scaled to the panel's width, so the whole wiring is in view.
  svg.setAttribute('viewBox', `0 0 ${res.width + 20} ${res.height + 20}`);
  svg.setAttribute('width', '100%');
  svg.style.maxHeight = Math.max(320, res.height + 20) + 'px';
  const defs = el('defs', {}, svg);
  const m = el('marker', { id: 'arrow', viewBox: '0 0 8 8', refX: 7, refY: 4, markerWidth: 7, markerHeight: 7, orient: 'auto' }, defs);
  el('path', { d: 'M0,0 L8,4 L0,8 z', fill: '#607d8b' }, m);
  const root = el('g', { transform: 'translate(10,10)' }, svg);
  layout = { wires: new Map(), nodes: new Map() };
  const byId = new Map(g.edges.map((e) => [e.id, e]));
  for (const e of res.edges || []) {
    const pts = [];
    for (const sec of e.sections || []) pts.push(sec.startPoint, ...(sec.bendPoints || []), sec.endPoint);
    if (!pts.length) continue;
    const d = 'M' + pts.map((p) => `${p.x},${p.y}`).join(' L');
    const path = el('path', { d, class: 'wire' + (byId.get(e.id).inhibitor ? ' inhibitor' : ''), 'data-wire': e.id }, root);
    const mid = pts[Math.floor(pts.length / 2)], prev = pts[Math.max(0, Math.floor(pts.length / 2) - 1)];
    const label = el('text', { x: (mid.x + prev.x) / 2 + 2, y: (mid.y + prev.y) / 2 - 3, class: 'wire-label' }, root);
    layout.wires.set(e.id, { path, label });
  }
  const nodeById = new Map(s.nodes.map((n) => ['n:' + n.name, n]));
  for (const c of res.children) {
    const g1 = el('g', { transform: `translate(${c.x},${c.y})` }, root);
    if (c.id.startsWith('n:')) {
      const n = nodeById.get(c.id);
      g1.setAttribute('class', 'node ' + n.kind);
      g1.dataset.node = n.name;
      el('rect', { width: c.width, height: c.height }, g1);
      if (n.kind === 'behavior')
        el('rect', { width: 5, height: c.height, class: 'stripe', fill: layerColour(n.layer) }, g1);
      el('text', { x: 10, y: 15 }, g1).textContent = n.name;
      const sub = el('text', { x: 10, y: 31, class: 'sub' }, g1);
      g1.onclick = () => select(n.name);
      layout.nodes.set(n.name, { g: g1, sub });
    } else {
      const sup = c.id.startsWith('s:');
      g1.setAttribute('class', sup ? 'sup-node' : 'inh-node');
      g1.dataset[sup ? 'suppressor' : 'inhibitor'] = c.id.slice(2);
      el('circle', { cx: 11, cy: 11, r: 11 }, g1);
      el('text', { x: 11, y: 11 }, g1).textContent = sup ? 'S' : 'I';
      el('title', {}, g1);
      layout.nodes.set(c.id, { g: g1 });
    }
  }
}

function restyle(s) {
  if (!layout) return;
  for (const n of s.nodes) {
    const box = layout.nodes.get(n.name);
    if (box) {
      box.g.setAttribute('class', `node ${n.kind} ${n.status}` + (n.name === selected ? ' selected' : ''));
      box.sub.textContent = (n.kind === 'device' ? 'device' : 'layer ' + n.layer) + ' · ' + n.status +
        (n.restarts ? ' · ↻' + n.restarts : '');
    }
    for (const o of n.outputs) {
      const inh = layout.nodes.get(`i:${n.name}.${o.output}`);
      if (inh) {
        inh.g.setAttribute('class', 'inh-node' + (o.inhibited ? ' on' : ''));
        inh.g.querySelector('title').textContent = `${n.name}.${o.output} ${o.inhibited ? 'inhibited' : 'not inhibited'}` +
          ` by ${o.inhibitors.map(srcKey).join(', ')}; latch ${term(o.latch)}`;
      }
    }
    for (const i of n.inputs) {
      const inp = n.name + '/' + i.input;
      const sup = layout.nodes.get('s:' + inp);
      if (sup) sup.g.querySelector('title').textContent =
        `${n.name}.${i.input}: winner ${i.winner ? srcKey(i.winner) : 'none'}; last ${term(i.last)}; ` +
        `latched ${i.latches.map((l) => srcKey(l.source) + '=' + l.term).join(', ') || '-'}`;
      for (const x of i.sources) {
        const w = layout.wires.get(`w:${inp}:${x.priority}`);
        if (!w) continue;
        const win = same(i.winner, x.source);
        const hold = i.holds.find((h) => same(h.source, x.source));
        const latch = i.latches.find((l) => same(l.source, x.source));
        w.path.setAttribute('class', 'wire' + (win ? ' win' : hold ? ' held' : ''));
        let label = (i.sources.length > 1 ? '#' + x.priority + ' ' : '') + (x.rate ? x.rate + '/s ' : '');
        if (hold) label += 'hold ' + (hold.ms === 'infinity' ? '∞' : hold.ms + 'ms') + ' ';
        if (latch) label += '=' + short(latch.term);
        w.label.textContent = label.trim();
        w.label.setAttribute('class', 'wire-label' + (win ? ' win' : ''));
      }
      const d = layout.wires.get('d:' + inp);
      if (d) {
        d.path.setAttribute('class', 'wire' + (i.winner ? ' win' : ''));
        d.label.textContent = i.last ? 'last ' + short(i.last.term) : '';
      }
    }
  }
}
const layerColours = ['#90a4ae', '#66bb6a', '#42a5f5', '#ab47bc', '#ef5350', '#ffa726', '#26c6da'];
function layerColour(l) { return layerColours[l % layerColours.length]; }
function short(t) { return t.length > 18 ? t.slice(0, 17) + '…' : t; }

// ---------------------------------------------------------------- details
function select(name) {
  selected = name;
  $('#control-name').value = name;
  if (state) { renderNodes(state); restyle(state); }
  showDetails(name, true);
}
let detailsBusy = false;
async function showDetails(name, now) {
  if (detailsBusy && !now) return;
  detailsBusy = true;
  try {
    const r = await fetch('/api/state');
    const j = await r.json();
    $('#details-name').textContent = name;
    $('#details').textContent = JSON.stringify(j.nodes[name] || { error: 'no such name now' }, null, 1);
  } finally { detailsBusy = false; }
}

// ---------------------------------------------------------------- controls
async function control(req) {
  const headers = { 'Content-Type': 'application/json' };
  const r = await fetch('/api/control', { method: 'POST', headers, body: JSON.stringify(req),
    credentials: 'same-origin' });
  const j = await r.json();
  const line = document.createElement('div');
  const what = req.action + ' ' + (req.name || (req.source ? req.source.join('.') : '') || req.file || '');
  line.className = j.ok ? 'done' : 'refused';
  line.textContent = j.ok ? `${what}: done` : `${what}: refused (${r.status} ${j.error}): ${j.message}`;
  const log = $('#control-log');
  log.prepend(line);
  while (log.children.length > 6) log.lastChild.remove();
}
document.querySelectorAll('#controls button').forEach((b) => {
  b.onclick = () => {
    const action = b.dataset.action;
    if (action === 'inject') {
      const [e, o] = $('#inject-source').value.split('.');
      const req = { action, source: [e, o], term: $('#inject-term').value };
      if ($('#inject-latch').checked) req.latch = true;
      control(req);
    } else if (action === 'load_wiring') control({ action, file: $('#wiring-file').value });
    else control({ action, name: $('#control-name').value });
  };
});

// ---------------------------------------------------------------- arena
const palette = ['#2e7d32', '#1565c0', '#c62828', '#6a1b9a', '#ef6c00', '#00838f', '#5d4037', '#ad1457'];
const colours = new Map([['none', '#9e9e9e'], ['start', '#9e9e9e']]);
function colour(tag) {
  if (!colours.has(tag)) colours.set(tag, palette[(colours.size - 2) % palette.length]);
  return colours.get(tag);
}
function onWorld(w) {
  $('#arena-panel').hidden = false;
  const svg = $('#arena');
  const [W, H] = w.arena;
  svg.setAttribute('viewBox', `-0.1 -0.1 ${W + 0.2} ${H + 0.2}`);
  svg.innerHTML = '';
  const clip = el('clipPath', { id: 'arena-clip' }, el('defs', {}, svg));
  el('rect', { x: 0, y: 0, width: W, height: H }, clip);
  const g = el('g', { transform: `matrix(1 0 0 -1 0 ${H})`, 'clip-path': 'url(#arena-clip)' }, svg);
  el('rect', { x: 0, y: 0, width: W, height: H, fill: '#fff', stroke: '#263238', 'stroke-width': 0.03 }, g);
  for (const [[x1, y1], [x2, y2]] of w.walls)
    el('line', { x1, y1, x2, y2, stroke: '#263238', 'stroke-width': 0.04, 'stroke-linecap': 'round' }, g);
  for (const o of w.objects)
    el('circle', { cx: o.at[0], cy: o.at[1], r: o.r, fill: o.color === 'red' ? '#e53935' : o.color === 'blue' ? '#1e88e5' : '#777' }, g);
  const caption = [];
  for (const r of w.robots) {
    const tr = r.trajectory;
    for (let k = 1; k < tr.length; k++)
      el('line', { x1: tr[k - 1][0], y1: tr[k - 1][1], x2: tr[k][0], y2: tr[k][1], stroke: colour(String(tr[k][2])), 'stroke-width': 0.025 }, g);
    const [x, y, hd] = r.pose;
    const th = hd * Math.PI / 180;
    const cam = r.camera || {};
    if (cam.fov_deg && cam.range) {
      const a = (cam.fov_deg / 2) * Math.PI / 180, R = cam.range;
      el('path', { d: `M${x},${y} L${x + R * Math.cos(th - a)},${y + R * Math.sin(th - a)} ` +
        `A${R},${R} 0 0 1 ${x + R * Math.cos(th + a)},${y + R * Math.sin(th + a)} Z`,
        fill: 'rgba(255,235,59,0.13)', stroke: 'rgba(249,168,37,0.6)', 'stroke-width': 0.01 }, g);
    }
    for (const ray of r.ir)
      el('line', { x1: ray.from[0], y1: ray.from[1], x2: ray.to[0], y2: ray.to[1],
        stroke: ray.adc >= 240 ? '#d50000' : '#ff8a80', 'stroke-width': 0.015, 'stroke-dasharray': '0.04 0.02' }, g);
    const body = el('g', { class: 'robot', 'data-robot': r.name, 'data-x': x.toFixed(3), 'data-y': y.toFixed(3),
      'data-heading': hd.toFixed(1), 'data-winner': r.winner }, g);
    el('circle', { cx: x, cy: y, r: r.radius, fill: '#eceff1', stroke: colour(String(r.winner)), 'stroke-width': 0.03 }, body);
    el('line', { x1: x, y1: y, x2: x + r.radius * Math.cos(th), y2: y + r.radius * Math.sin(th), stroke: '#263238', 'stroke-width': 0.025 }, body);
    caption.push(`${r.name} at (${x.toFixed(2)}, ${y.toFixed(2)}) ${Math.round(hd)}° · motors: ${r.winner}`);
  }
  $('#arena-caption').textContent = `t ${(w.t_ms / 1000).toFixed(1)} s · ` + caption.join(' · ');
  drawTimeline(w);
  $('#arena-legend').innerHTML = [...colours].filter(([k]) => k !== 'start')
    .map(([k, c]) => `<span><i style="background:${c}"></i>${esc(k)}</span>`).join('');
}

// The run's timeline: its length, now, and each mark the simulator sent
// (a fault of the robustness lab in orange, a violation of its property
// in red), each with its text as a tooltip and a label.
function drawTimeline(w) {
  const svg = $('#timeline');
  const tl = w.timeline;
  if (!tl || !tl.duration_ms) { svg.hidden = true; return; }
  svg.hidden = false;
  svg.innerHTML = '';
  const D = tl.duration_ms, X = (t) => 10 + 980 * Math.min(t, D) / D;
  svg.setAttribute('viewBox', '0 0 1000 70');
  el('line', { x1: 10, y1: 40, x2: 990, y2: 40, stroke: '#90a4ae', 'stroke-width': 2 }, svg);
  el('rect', { x: 10, y: 36, width: X(w.t_ms) - 10, height: 8, fill: '#cfd8dc' }, svg);
  for (let s = 0; s <= D; s += 10000) {
    el('line', { x1: X(s), y1: 36, x2: X(s), y2: 44, stroke: '#607d8b' }, svg);
    el('text', { x: X(s), y: 62, 'text-anchor': 'middle', 'font-size': 11, fill: '#455a64' }, svg).textContent = `${s / 1000} s`;
  }
  for (const m of tl.marks) {
    const x = X(m.t_ms), bad = m.kind === 'violation';
    const g = el('g', { class: `mark ${m.kind}`, 'data-t': m.t_ms }, svg);
    el('title', {}, g).textContent = `${(m.t_ms / 1000).toFixed(3)} s ${m.text}`;
    if (bad) el('path', { d: `M${x},38 l-7,-14 l14,0 z`, fill: '#d50000' }, g);
    else el('line', { x1: x, y1: 28, x2: x, y2: 46, stroke: '#ef6c00', 'stroke-width': 3 }, g);
    el('text', { x, y: bad ? 18 : 24, 'text-anchor': 'middle', 'font-size': 10, fill: bad ? '#d50000' : '#e65100' }, g)
      .textContent = bad ? m.text : m.text.split(' ').slice(0, 2).join(' ');
  }
}

connect();
