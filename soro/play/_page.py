"""The page of ``soro play``: one self-contained HTML document (no JavaScript library, no network beyond this
server), drawn on 2D canvases so it runs in any browser without WebGL.

The page reads ``/scene`` once (sections, obstacles, channels), then frames from the event stream
``/events`` (one JSON frame per message, :mod:`soro.play.backends`), and posts commands to ``/cmd``. It
exposes ``window.soroPlay`` (the last frame, the projection, the measured latencies) for tests and tools.
"""

__all__ = ["PAGE"]

PAGE = r"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>soro play</title>
<style>
 body{font:13px system-ui,sans-serif;margin:0;display:flex;gap:10px;padding:8px;background:#f4f4f2;color:#222}
 #left{display:flex;flex-direction:column;gap:6px}
 #view{background:#fff;border:1px solid #bbb;cursor:grab}
 #panel{width:330px;display:flex;flex-direction:column;gap:6px}
 .box{background:#fff;border:1px solid #ccc;padding:6px}
 .row{display:flex;align-items:center;gap:6px}
 .row label{width:120px;overflow:hidden;text-overflow:ellipsis;white-space:nowrap}
 .row input[type=range]{flex:1}
 .val{width:64px;text-align:right;font-variant-numeric:tabular-nums}
 #rtf.slow{color:#b00;font-weight:bold}
 canvas.plot{background:#fff;border:1px solid #ccc}
 #msg{color:#b00}
 #modesel{max-width:150px}
 h1{font-size:15px;margin:0}
</style></head><body>
<div id="left">
 <div class="row"><h1 id="title">soro play</h1><span id="backend"></span></div>
 <div class="row"><span id="source"></span></div>
 <canvas id="view" width="720" height="520"></canvas>
 <div class="row"><span>t = <b id="time">0</b> s</span><span>real-time factor <b id="rtf">-</b></span>
  <span id="mode"></span><span id="msg"></span></div>
</div>
<div id="panel">
 <div class="box" id="channels"><b>Inputs</b></div>
 <div class="box row">
  <button id="play">play</button><button id="pause">pause</button><button id="reset">reset</button>
  <select id="modesel"><option value="simulate">simulate</option><option value="ik">IK (drag the target)</option>
   <option value="impedance" id="impopt" hidden>impedance (drag the set-point)</option></select>
 </div>
 <div class="box row"><button id="record">record</button><button id="stoprec">stop + save</button>
  <button id="replay">replay</button><span id="recinfo"></span></div>
 <div class="box"><b>Tip position [mm]</b><canvas class="plot" id="plot_tip" width="316" height="110"></canvas>
  <b>Inputs [kPa | N | N m]</b><canvas class="plot" id="plot_u" width="316" height="110"></canvas>
  <b>Energy [mJ]</b><canvas class="plot" id="plot_e" width="316" height="90"></canvas></div>
</div>
<script>
"use strict";
const S = window.soroPlay = {frame: null, scene: null, latencies: [], framesDrawn: 0, pending: [], cmdSeq: 0,
                             history: [], connected: false};
const view = document.getElementById("view"), ctx = view.getContext("2d");
let cam = {az: 0, el: 20, c: [0, 0, 0], scale: 2000};
const COLORS = ["#2a7ab0", "#c0504d", "#5a9e3a", "#8064a2", "#d08a1e", "#2aa198", "#7f7f7f"];
const rad = d => d * Math.PI / 180;
function basis() {
  const a = rad(cam.az), e = rad(cam.el);
  const f = [-Math.sin(a) * Math.cos(e), Math.cos(a) * Math.cos(e), -Math.sin(e)];
  const r = [Math.cos(a), Math.sin(a), 0];
  const u = [-Math.sin(a) * Math.sin(e), Math.cos(a) * Math.sin(e), Math.cos(e)];
  return {f, r, u};
}
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
// world point [m] -> [canvas x, canvas y, depth] (orthographic)
S.project = function (p) {
  const B = basis(), d = sub(p, cam.c);
  return [view.width / 2 + cam.scale * dot(d, B.r), view.height / 2 - cam.scale * dot(d, B.u), dot(d, B.f)];
};
// canvas position of a world point in page (client) coordinates, for tools that drive the mouse
S.clientOf = function (p) {
  const q = S.project(p), R = view.getBoundingClientRect();
  return [R.left + q[0] * R.width / view.width, R.top + q[1] * R.height / view.height];
};
function fit(fr) {
  const pts = [];
  fr.beams.forEach(b => b.p.forEach(p => pts.push(p)));
  if (S.scene) S.scene.obstacles.forEach(o => o.forEach(p => pts.push(p)));
  if (fr.target) pts.push(fr.target);
  (fr.bodies || []).forEach(b => pts.push([b.pose[0][3], b.pose[1][3], b.pose[2][3]]));
  if (!pts.length) return;
  const lo = [1e9, 1e9, 1e9], hi = [-1e9, -1e9, -1e9];
  pts.forEach(p => { for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], p[k]); hi[k] = Math.max(hi[k], p[k]); } });
  cam.c = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2];
  const span = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 0.02);
  cam.scale = 0.55 * Math.min(view.width, view.height) / span;
}
function shade(hex, k) {
  const n = parseInt(hex.slice(1), 16), c = [(n >> 16) & 255, (n >> 8) & 255, n & 255].map(v => Math.round(v * k));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}
function draw(fr) {
  ctx.clearRect(0, 0, view.width, view.height);
  const items = [];       // [depth, function]
  const sc = S.scene;
  if (sc) sc.obstacles.forEach(o => o.forEach(p => {
    const q = S.project(p);
    items.push([q[2], () => { ctx.fillStyle = "rgba(120,120,120,0.45)"; ctx.fillRect(q[0] - 1, q[1] - 1, 2.2, 2.2); }]);
  }));
  fr.beams.forEach((b, i) => {
    const col = COLORS[i % COLORS.length], geo = sc ? sc.beams[i] : null, r = geo ? geo.radius : 0.005;
    const P = b.p.map(S.project);
    for (let k = 0; k + 1 < P.length; k++) {
      const a = P[k], c = P[k + 1], d = (a[2] + c[2]) / 2;
      items.push([d, () => { ctx.strokeStyle = col; ctx.lineCap = "round"; ctx.lineWidth = Math.max(2, 2 * r * cam.scale);
        ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(c[0], c[1]); ctx.stroke(); }]);
    }
    if (geo) b.p.forEach((p, k) => {           // the cross-section at each node, in the body (y, z) plane
      const ey = b.ey[k], ez = b.ez[k];
      const ring = geo.outline.map(o => S.project([p[0] + o[0] * ey[0] + o[1] * ez[0], p[1] + o[0] * ey[1] + o[1] * ez[1],
                                                   p[2] + o[0] * ey[2] + o[1] * ez[2]]));
      items.push([P[k][2] - 1e-6, () => { ctx.strokeStyle = shade(col, 0.55); ctx.lineWidth = 1; ctx.beginPath();
        ring.forEach((q, j) => j ? ctx.lineTo(q[0], q[1]) : ctx.moveTo(q[0], q[1])); ctx.closePath(); ctx.stroke(); }]);
    });
    (b.contacts || []).forEach(c => {          // contact forces: arrows, 20 mm per newton
      const a = S.project(c.slice(0, 3)), e = S.project([c[0] + 0.02 * c[3], c[1] + 0.02 * c[4], c[2] + 0.02 * c[5]]);
      items.push([a[2] - 1, () => { ctx.strokeStyle = "#d00"; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(a[0], a[1]);
        ctx.lineTo(e[0], e[1]); ctx.stroke(); }]);
    });
  });
  (fr.bodies || []).forEach(bd => {
    const g = bd.pose, o = [g[0][3], g[1][3], g[2][3]], O = S.project(o);
    items.push([O[2], () => { ["#d00", "#0a0", "#00d"].forEach((c, k) => {
      const e = S.project([o[0] + 0.02 * g[0][k], o[1] + 0.02 * g[1][k], o[2] + 0.02 * g[2][k]]);
      ctx.strokeStyle = c; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(O[0], O[1]); ctx.lineTo(e[0], e[1]); ctx.stroke(); });
      ctx.fillStyle = "#444"; ctx.beginPath(); ctx.arc(O[0], O[1], 5, 0, 7); ctx.fill(); }]);
  });
  if (fr.target) {
    const T = S.project(fr.target);
    items.push([-1e9, () => { ctx.strokeStyle = "#e08000"; ctx.lineWidth = 2; ctx.beginPath(); ctx.arc(T[0], T[1], 8, 0, 7);
      ctx.moveTo(T[0] - 12, T[1]); ctx.lineTo(T[0] + 12, T[1]); ctx.moveTo(T[0], T[1] - 12); ctx.lineTo(T[0], T[1] + 12); ctx.stroke(); }]);
  }
  items.sort((a, b) => b[0] - a[0]).forEach(it => it[1]());
  // axes triad, bottom left
  const B = basis();
  [[1, 0, 0, "#d00", "x"], [0, 1, 0, "#0a0", "y"], [0, 0, 1, "#00d", "z"]].forEach(a => {
    const v = [a[0], a[1], a[2]], x = 30 + 22 * dot(v, B.r), y = view.height - 30 - 22 * dot(v, B.u);
    ctx.strokeStyle = a[3]; ctx.lineWidth = 2; ctx.beginPath(); ctx.moveTo(30, view.height - 30); ctx.lineTo(x, y); ctx.stroke();
    ctx.fillStyle = a[3]; ctx.fillText(a[4], x + 2, y - 2);
  });
}
function plot(id, series, scale) {
  const c = document.getElementById(id), g = c.getContext("2d"), H = S.history;
  g.clearRect(0, 0, c.width, c.height);
  if (H.length < 2) return;
  let lo = 1e30, hi = -1e30;
  series.forEach(k => H.forEach(h => { const v = h[k]; if (v !== undefined) { lo = Math.min(lo, v * scale(k)); hi = Math.max(hi, v * scale(k)); } }));
  if (!(hi > lo)) { hi = lo + 1; lo -= 1; }
  const fmt = v => Math.abs(v) < 1e-6 * Math.max(Math.abs(hi), Math.abs(lo), 1e-30) ? "0" : v.toPrecision(3);
  const t0 = H[0].t, t1 = H[H.length - 1].t, X = t => 30 + (c.width - 34) * (t - t0) / Math.max(t1 - t0, 1e-9),
        Y = v => c.height - 4 - (c.height - 8) * (v - lo) / (hi - lo);
  g.fillStyle = "#666"; g.fillText(fmt(hi), 0, 10); g.fillText(fmt(lo), 0, c.height - 4);
  series.forEach((k, i) => { g.strokeStyle = COLORS[i % COLORS.length]; g.lineWidth = 1.5; g.beginPath();
    H.forEach((h, j) => { const v = h[k]; if (v === undefined) return; j ? g.lineTo(X(h.t), Y(v * scale(k))) : g.moveTo(X(h.t), Y(v * scale(k))); });
    g.stroke(); });
}
const unitScale = k => k.startsWith("tip_") ? 1e3 : k === "energy" ? 1e3 : k.startsWith("p:") ? 1e-3 :
  k.startsWith("u:") ? (S.units[k] === "Pa" ? 1e-3 : 1) : 1;
S.units = {};
function show(fr) {
  S.frame = fr;
  if (S.framesDrawn === 0) fit(fr);
  draw(fr);
  S.framesDrawn++;
  const now = performance.now();
  S.pending = S.pending.filter(p => { if (p.seq <= fr.input_seq) { S.latencies.push(now - p.t0); return false; } return true; });
  S.history.push(Object.assign({t: fr.t}, fr.signals));
  if (S.history.length > 400) S.history.shift();
  if (S.framesDrawn % 3 === 0) {
    const sig = Object.keys(fr.signals);
    plot("plot_tip", sig.filter(k => k.startsWith("tip_")), unitScale);
    plot("plot_u", sig.filter(k => k.startsWith("u:") || k.startsWith("p:")), unitScale);
    plot("plot_e", sig.filter(k => k === "energy"), unitScale);
  }
  document.getElementById("time").textContent = fr.t.toFixed(2);
  const rtf = document.getElementById("rtf");
  document.getElementById("modesel").value = fr.mode;
  rtf.textContent = fr.paused || fr.mode === "ik" ? "paused" : "x" + fr.rtf.toFixed(2) +
    (fr.rtf < 0.95 ? " (the model cannot keep up: it steps as fast as it can)" : "");
  rtf.className = !fr.paused && fr.mode !== "ik" && fr.rtf < 0.95 ? "slow" : "";
  document.getElementById("backend").textContent = "back end: " + fr.backend;
  document.getElementById("source").textContent = "3D view: " + ({model: "the model, stepping in this server",
    estimate: "the shape estimated from the board's sensors", prediction: "the model's prediction, driven by the measured pressures"})[fr.view_source];
  document.getElementById("mode").textContent = "mode: " + fr.mode + (fr.ik_error !== null && fr.mode === "ik" ? ` (IK error ${(fr.ik_error * 1e3).toFixed(2)} mm)` : "");
  document.getElementById("msg").textContent = fr.message || "";
  document.getElementById("recinfo").textContent = fr.recording ? "recording..." : fr.replaying ? "replaying..." : (fr.last_recording || "");
  if (fr.board) S.board = fr.board;
}
// Commands go to the server one at a time, in the order they were made (parallel requests may arrive out of
// order: the last position of a drag must be the one that stays); a target or slider command still waiting is
// replaced by a newer one of the same kind, so a fast drag never builds a queue.
let chain = Promise.resolve();
const waiting = new Map();
function send(cmd) {
  cmd.seq = ++S.cmdSeq;
  const key = cmd.type === "target" ? "target" : cmd.type === "input" ? "input:" + cmd.name : null;
  if (key && waiting.has(key)) { const w = waiting.get(key); w.cmd = cmd; return w.done; }
  const w = {cmd};
  if (key) waiting.set(key, w);
  w.done = chain.then(async () => {
    if (key) waiting.delete(key);
    const r = await fetch("/cmd", {method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(w.cmd)});
    const a = await r.json();
    if (!a.ok) document.getElementById("msg").textContent = a.error;
    return a;
  });
  chain = w.done.catch(() => {});
  return w.done;
}
S.send = send;
S.setInput = function (name, value) {           // what a slider does (value in SI units)
  const seq = S.cmdSeq + 1;
  S.pending.push({seq, t0: performance.now()});
  return send({type: "input", name, value});
};
function build(scene) {
  S.scene = scene;
  document.getElementById("title").textContent = scene.title;
  cam.az = scene.view[0]; cam.el = scene.view[1];
  document.getElementById("impopt").hidden = !scene.impedance;
  const box = document.getElementById("channels");
  scene.channels.forEach((c, i) => {
    S.units["u:" + c.name] = c.unit;
    const k = c.unit === "Pa" ? 1e-3 : 1, u = c.unit === "Pa" ? "kPa" : c.unit;
    const row = document.createElement("div"); row.className = "row";
    row.innerHTML = `<label title="${c.name}">${c.label}</label><input type="range" id="ch${i}" data-name="${c.name}"
      min="${c.low * k}" max="${c.high * k}" step="${(c.high - c.low) * k / 200}" value="${c.initial * k}">
      <span class="val" id="chv${i}">${(c.initial * k).toFixed(1)} ${u}</span>`;
    box.appendChild(row);
    const s = row.querySelector("input");
    s.addEventListener("input", () => { document.getElementById("chv" + i).textContent = (+s.value).toFixed(1) + " " + u;
      S.setInput(c.name, +s.value / k); });
  });
}
// mouse: drag the target (within 14 px of it), else orbit; wheel zooms
let drag = null;
view.addEventListener("mousedown", ev => {
  const R = view.getBoundingClientRect(), x = (ev.clientX - R.left) * view.width / R.width, y = (ev.clientY - R.top) * view.height / R.height;
  const fr = S.frame;
  if (fr && fr.target) { const T = S.project(fr.target); if (Math.hypot(T[0] - x, T[1] - y) < 14) { drag = {kind: "target", x, y, p0: fr.target.slice()}; return; } }
  drag = {kind: "orbit", x, y, az: cam.az, el: cam.el};
});
window.addEventListener("mousemove", ev => {
  if (!drag) return;
  const R = view.getBoundingClientRect(), x = (ev.clientX - R.left) * view.width / R.width, y = (ev.clientY - R.top) * view.height / R.height;
  if (drag.kind === "orbit") { cam.az = drag.az - 0.4 * (x - drag.x); cam.el = Math.max(-89, Math.min(89, drag.el + 0.4 * (y - drag.y))); if (S.frame) draw(S.frame); return; }
  const B = basis(), dx = (x - drag.x) / cam.scale, dy = (y - drag.y) / cam.scale;
  const p = [0, 1, 2].map(k => drag.p0[k] + dx * B.r[k] - dy * B.u[k]);
  S.dragTarget = p;
  send({type: "target", position: p});
});
window.addEventListener("mouseup", () => { drag = null; });
view.addEventListener("wheel", ev => { ev.preventDefault(); cam.scale *= Math.exp(-ev.deltaY / 500); if (S.frame) draw(S.frame); });
document.getElementById("play").onclick = () => send({type: "play"});
document.getElementById("pause").onclick = () => send({type: "pause"});
document.getElementById("reset").onclick = () => { S.history = []; send({type: "reset"}); };
document.getElementById("modesel").onchange = ev => send({type: "mode", mode: ev.target.value});
document.getElementById("record").onclick = () => send({type: "record"});
document.getElementById("stoprec").onclick = () => send({type: "stop_record"});
document.getElementById("replay").onclick = () => send({type: "replay"});
window.addEventListener("pagehide", () => navigator.sendBeacon("/close", "page closed"));
fetch("/scene").then(r => r.json()).then(scene => {
  build(scene);
  const es = new EventSource("/events");
  es.onopen = () => { S.connected = true; };
  // a slow page (a loaded laptop) draws only the newest frame at its next paint: frames that arrive while it
  // draws replace each other instead of queueing up behind the drawing (and behind the user's input)
  let latest = null;
  es.onmessage = ev => {
    if (latest === null) requestAnimationFrame(() => { const d = latest; latest = null; show(JSON.parse(d)); });
    latest = ev.data;
  };
  es.onerror = () => { S.connected = false; document.getElementById("msg").textContent = "lost the server"; };
});
</script></body></html>
"""
