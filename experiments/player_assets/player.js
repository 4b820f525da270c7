"use strict";
const D = JSON.parse(document.getElementById("data").textContent);
const scene = document.getElementById("scene");
const ctx = scene.getContext("2d");
const timeline = document.getElementById("timeline");
const scrub = document.getElementById("scrub");
const SVG = "http://www.w3.org/2000/svg";
const STATION_HEX = D.station_colours;
const EVENT_HEX = {spawned: "#888", entered_workspace: "#6a6", left_workspace: "#aa6",
  pick_success: "#2a2", placed_in_bin: "#06c", pick_dropped: "#c60", fell_off: "#c00",
  missed: "#c0c", finger_contact: "#999", unintended_contact: "#f80", fault: "#000",
  tcp_overlap_start: "#bbb", tcp_overlap_end: "#bbb", controller_resumed: "#444"};
const PAD = 10;
const state = {t: 0, playing: false, speed: 1, sel: 0, hi: 0, last: null, view: null};

function undelta(a, scale) {
  const out = new Float64Array(a.length);
  let v = 0;
  for (let i = 0; i < a.length; i++) { v += a[i]; out[i] = v * scale; }
  return out;
}
for (const o of D.objects) {
  for (const k of ["x", "y", "z", "vx", "vy", "vz"]) o[k] = undelta(o[k], 1e-3);
  for (const k of ["qx", "qy", "qz", "qw"]) o[k] = undelta(o[k], 1e-4);
  o.f = new Uint8Array(o.n);
  let j = 0;
  for (let k = 0; k < o.n; k++) {
    while (j + 1 < o.flags.length && o.flags[j + 1][0] <= k) j++;
    o.f[k] = o.flags[j][1];
  }
  o.ring = o.outline.map(p => [p[0] * 1e-4, p[1] * 1e-4]);
  o.zlo = o.zspan[0] * 1e-4;
  o.zhi = o.zspan[1] * 1e-4;
  o.events = D.events.filter(e => e.id === o.id);
}
for (const tcp of D.tcp) for (const k of ["x", "y", "z"]) tcp[k] = undelta(tcp[k], 1e-3);
const belt = undelta(D.belt_mm, 1e-3);
const byId = new Map(D.objects.map(o => [o.id, o]));

function frameAt(t) {  // last frame stamped at or before t, -1 before the first
  const f = D.frames;
  let lo = 0, hi = f.length - 1, best = -1;
  while (lo <= hi) {
    const mid = (lo + hi) >> 1;
    if (f[mid] <= t + 1e-6) { best = mid; lo = mid + 1; } else hi = mid - 1;
  }
  return best;
}
function sampleAt(times, t) {
  let lo = 0, hi = times.length - 1, best = -1;
  while (lo <= hi) {
    const mid = (lo + hi) >> 1;
    if (times[mid] <= t + 1e-6) { best = mid; lo = mid + 1; } else hi = mid - 1;
  }
  return best;
}
function pose(o, i) {  // the object's state at frame i, null when it is not there
  const k = i - o.first;
  if (k < 0 || k >= o.n || (o.f[k] & D.absent_bit)) return null;
  const x = o.qx[k], y = o.qy[k], z = o.qz[k], w = o.qw[k];
  const r = [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)];
  return {k: k, x: o.x[k], y: o.y[k], z: o.z[k], q: [x, y, z, w], r: r, flags: o.f[k],
    v: [o.vx[k], o.vy[k], o.vz[k]]};
}
function pieces(o, p) {  // the top view: both end faces of the prism and its sides (world xy)
  const r = p.r;
  const at = z => o.ring.map(([u, v]) => [r[0] * u + r[1] * v + r[2] * z + p.x,
    r[3] * u + r[4] * v + r[5] * z + p.y]);
  const lo = at(o.zlo), hi = at(o.zhi);
  const out = [lo, hi];
  for (let a = 0, b = lo.length - 1; a < lo.length; b = a++) out.push([lo[b], lo[a], hi[a], hi[b]]);
  return out;
}
function screenPieces(o, p) {  // in canvas pixels, every piece counter-clockwise on screen
  return pieces(o, p).map(ring => {
    const q = ring.map(([x, y]) => px(x, y));
    let area = 0;
    for (let a = 0, b = q.length - 1; a < q.length; b = a++) {
      area += (q[b][0] - q[a][0]) * (q[b][1] + q[a][1]);
    }
    return area < 0 ? q.reverse() : q;
  });
}
function fillObject(o, p) {  // one path, non-zero rule: the union of the pieces, no seams
  ctx.beginPath();
  for (const q of screenPieces(o, p)) {
    q.forEach(([a, b], n) => n ? ctx.lineTo(a, b) : ctx.moveTo(a, b));
    ctx.closePath();
  }
  ctx.fill("nonzero");
}

function layout() {
  let v = D.cell ? D.cell.view : null;
  if (!v) {
    const xs = [], ys = [];
    for (const o of D.objects) for (let k = 0; k < o.n; k++) { xs.push(o.x[k]); ys.push(o.y[k]); }
    v = xs.length ? [Math.min(...xs) - 0.3, Math.max(...xs) + 0.3, Math.min(...ys) - 0.3,
      Math.max(...ys) + 0.3] : [-1, 1, -1, 1];
  }
  const width = Math.max(400, Math.floor(document.documentElement.clientWidth - 32));
  const s = (width - 2 * PAD) / (v[1] - v[0]);
  const height = Math.ceil(s * (v[3] - v[2]) + 2 * PAD);
  const dpr = window.devicePixelRatio || 1;
  scene.style.width = width + "px";
  scene.style.height = height + "px";
  scene.width = Math.round(width * dpr);
  scene.height = Math.round(height * dpr);
  state.view = {v: v, s: s, w: width, h: height, dpr: dpr, k: 1, panX: 0, panY: 0};
  timeline.setAttribute("width", width);
  buildTimeline();
}
function writeMapping() {  // page pixel of world (x, y): (originX + s x, originY - s y)
  const V = state.view, rect = scene.getBoundingClientRect();
  const [ax, ay] = px(0, 0);
  scene.dataset.pxPerM = String(V.s * V.k);
  scene.dataset.originX = String(rect.left + window.scrollX + ax);
  scene.dataset.originY = String(rect.top + window.scrollY + ay);
}
function px(x, y) {  // canvas pixel of world (x, y)
  const V = state.view, s = V.s * V.k;
  return [PAD + V.panX + s * (x - V.v[0]), PAD + V.panY + s * (V.v[3] - y)];
}
function zoomAt(cx, cy, factor) {  // zoom about canvas pixel (cx, cy), 1x to 40x
  const V = state.view;
  const k = Math.min(40, Math.max(1, V.k * factor));
  const f = k / V.k;
  V.panX = cx - PAD - f * (cx - PAD - V.panX);
  V.panY = cy - PAD - f * (cy - PAD - V.panY);
  V.k = k;
  if (k === 1) { V.panX = 0; V.panY = 0; }
  draw();
}
function path(points) {
  ctx.beginPath();
  points.forEach(([x, y], n) => {
    const [a, b] = px(x, y);
    n ? ctx.lineTo(a, b) : ctx.moveTo(a, b);
  });
  ctx.closePath();
}
function rect(x0, y0, x1, y1) { path([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]); }

function drawCell(i) {
  const c = D.cell;
  if (!c) return;
  const b = c.belt, V = state.view;
  const y0 = b.y - b.width / 2, y1 = b.y + b.width / 2;
  rect(b.start, y0, b.end, y1);
  ctx.fillStyle = "#cfd4da"; ctx.fill();
  ctx.strokeStyle = "#8a9099"; ctx.lineWidth = 1; ctx.stroke();
  const travelled = i >= 0 && belt.length ? belt[i] : 0;
  const step = 0.1;
  ctx.strokeStyle = "#bcc2ca";
  for (let x = b.start + ((travelled % step) + step) % step; x < b.end; x += step) {
    const [a, p0] = px(x, y0), [, p1] = px(x, y1);
    ctx.beginPath(); ctx.moveTo(a, p0); ctx.lineTo(a, p1); ctx.stroke();
  }
  ctx.setLineDash([4, 4]);
  ctx.strokeStyle = "#777";
  for (const x of c.camera) {
    const [a, p0] = px(x, y0), [, p1] = px(x, y1);
    ctx.beginPath(); ctx.moveTo(a, p0 - 4); ctx.lineTo(a, p1 + 4); ctx.stroke();
  }
  ctx.setLineDash([]);
  ctx.font = "11px sans-serif";
  c.stations.forEach((st, n) => {
    const hue = STATION_HEX[n % STATION_HEX.length];
    rect(st.window[0], y0, st.window[1], y1);
    ctx.fillStyle = hue + "22"; ctx.fill();
    ctx.strokeStyle = hue + "88"; ctx.stroke();
    for (const bin of st.bins) {
      const h = bin.size / 2;
      rect(bin.x - h, bin.y - h, bin.x + h, bin.y + h);
      ctx.fillStyle = D.classes[bin.cls] + "40"; ctx.fill();
      ctx.lineWidth = 3; ctx.strokeStyle = D.classes[bin.cls]; ctx.stroke(); ctx.lineWidth = 1;
      const [a, p] = px(bin.x, bin.y - h);
      ctx.fillStyle = "#333"; ctx.textAlign = "center";
      ctx.fillText(bin.cls, a, p + 12, bin.size * V.s * V.k);
      ctx.textAlign = "start";
    }
    const [a, p] = px(st.base[0], st.base[1]);
    ctx.beginPath(); ctx.arc(a, p, Math.max(4, 0.08 * V.s * V.k), 0, 2 * Math.PI);
    ctx.fillStyle = "#fff"; ctx.fill(); ctx.strokeStyle = hue; ctx.lineWidth = 2; ctx.stroke();
    ctx.lineWidth = 1;
    ctx.fillStyle = hue; ctx.fillText(st.name, a + 8, p + 14);
  });
}

function drawObjects(i) {
  if (i < 0) return [];
  const shown = [];
  for (const o of D.objects) {
    const p = pose(o, i);
    if (p) shown.push([o, p]);
  }
  shown.sort((a, b) => a[1].z - b[1].z);
  for (const [o, p] of shown) {
    if (o.id === state.hi) continue;
    ctx.fillStyle = D.classes[o.cls] || "#999";
    fillObject(o, p);
    ctx.lineWidth = o.id === state.sel ? 3 : 1;
    ctx.strokeStyle = o.id === state.sel ? "#ff0" : "#0009";
    const ends = pieces(o, p);
    path(ends[1]);
    ctx.stroke();
  }
  ctx.lineWidth = 1;
  return shown;
}

function targetAt(n, t) {
  const list = D.targets[n] || [];
  const j = sampleAt(list.map(m => m[0]), t);
  return j < 0 ? null : list[j];
}
function drawStations(t) {
  const names = D.cell ? D.cell.stations.map(s => s.name) : D.tcp.map((_, n) => "station " + n);
  D.tcp.forEach((tcp, n) => {
    const hue = STATION_HEX[n % STATION_HEX.length];
    const j = sampleAt(tcp.t, t);
    if (j < 0) return;
    ctx.beginPath();
    for (let k = Math.max(0, j - 60); k <= j; k++) {
      const [a, b] = px(tcp.x[k], tcp.y[k]);
      k === Math.max(0, j - 60) ? ctx.moveTo(a, b) : ctx.lineTo(a, b);
    }
    ctx.strokeStyle = hue + "99"; ctx.lineWidth = 2; ctx.stroke();
    const [a, b] = px(tcp.x[j], tcp.y[j]);
    ctx.beginPath(); ctx.arc(a, b, 6, 0, 2 * Math.PI);
    ctx.fillStyle = hue; ctx.fill(); ctx.strokeStyle = "#fff"; ctx.stroke();
    ctx.lineWidth = 1;
    const tg = targetAt(n, t);
    if (tg && tg[3] && (tg[4] || tg[5])) {
      const dt = t - tg[0];
      const [c, d] = px((tg[4] + tg[7] * dt) * 1e-3, (tg[5] + tg[8] * dt) * 1e-3);
      ctx.strokeStyle = hue; ctx.lineWidth = 2;
      ctx.beginPath(); ctx.arc(c, d, 9, 0, 2 * Math.PI); ctx.stroke();
      ctx.beginPath(); ctx.moveTo(c - 13, d); ctx.lineTo(c + 13, d);
      ctx.moveTo(c, d - 13); ctx.lineTo(c, d + 13); ctx.stroke();
      ctx.lineWidth = 1;
    }
    ctx.fillStyle = hue;
    ctx.fillText(names[n] + ": " + (tg ? tg[2] : "") + "  z " + tcp.z[j].toFixed(2), a + 9, b - 8);
  });
}

function draw() {
  const V = state.view, t = state.t;
  ctx.setTransform(V.dpr, 0, 0, V.dpr, 0, 0);
  ctx.clearRect(0, 0, V.w, V.h);
  const i = frameAt(t);
  drawCell(i);
  drawObjects(i);
  drawStations(t);
  const o = byId.get(state.hi);
  const p = o ? pose(o, i) : null;
  if (p) { ctx.fillStyle = D.highlight; fillObject(o, p); }
  writeMapping();
  scene.dataset.frame = String(i);
  scene.dataset.frameT = i >= 0 ? String(D.frames[i]) : "";
  document.getElementById("clock").textContent =
    t.toFixed(3) + " / " + D.duration_s.toFixed(1) + " s";
  scrub.value = String(t);
  const cursor = document.getElementById("cursor");
  if (cursor) { const x = tx(t); cursor.setAttribute("x1", x); cursor.setAttribute("x2", x); }
  info(i);
}

const LABEL_W = 120;
function tx(t) {
  const w = Number(timeline.getAttribute("width"));
  return LABEL_W + (w - LABEL_W - PAD) * (D.duration_s > 0 ? t / D.duration_s : 0);
}
function el(name, attrs, parent) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  parent.appendChild(e);
  return e;
}
function buildTimeline() {
  while (timeline.firstChild) timeline.removeChild(timeline.firstChild);
  const types = [...new Set(D.events.map(e => e.type))];
  const row = 13;
  timeline.setAttribute("height", Math.max(row, types.length * row) + 16);
  types.forEach((type, r) => {
    el("text", {x: 4, y: r * row + 10, "font-size": 10, fill: "#333"}, timeline).textContent = type;
    for (const e of D.events.filter(e => e.type === type)) {
      const x = tx(e.t);
      const sel = state.sel && e.id === state.sel;
      const line = el("line", {x1: x, x2: x, y1: r * row + 1, y2: r * row + row - 1,
        stroke: sel ? "#000" : (EVENT_HEX[type] || "#555"), "stroke-width": sel ? 3 : 1.5},
        timeline);
      const where = e.data && e.data.station ? " @" + e.data.station : "";
      el("title", {}, line).textContent = e.t.toFixed(3) + " s " + type +
        (e.id ? " #" + e.id + " " + e.cls : "") + where;
    }
  });
  const h = Math.max(row, types.length * row);
  for (let s = 0; s <= D.duration_s; s += D.duration_s > 60 ? 10 : (D.duration_s > 10 ? 5 : 1)) {
    el("text", {x: tx(s), y: h + 12, "font-size": 9, fill: "#666", "text-anchor": "middle"},
      timeline).textContent = s + " s";
  }
  el("line", {id: "cursor", x1: tx(state.t), x2: tx(state.t), y1: 0, y2: h, stroke: "#d00"},
    timeline);
}

function fmt(v, d) { return Number(v).toFixed(d); }
function rpy(q) {
  const [x, y, z, w] = q;
  const roll = Math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y));
  const pitch = Math.asin(Math.max(-1, Math.min(1, 2 * (w * y - z * x))));
  const yaw = Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
  return [roll, pitch, yaw].map(a => a * 180 / Math.PI);
}
function info(i) {
  const box = document.getElementById("info");
  const o = byId.get(state.sel);
  if (!o) return;
  const p = pose(o, i);
  const rows = [["object", "#" + o.id + " " + o.cls + (o.src ? " (" + o.src + ")" : "")],
    ["footprint from", o.outline_from]];
  for (const [k, v] of Object.entries(o.dims)) rows.push([k, String(v)]);
  if (p) {
    rows.push(["position (m)", [p.x, p.y, p.z].map(v => fmt(v, 3)).join(", ")]);
    rows.push(["roll, pitch, yaw (deg)", rpy(p.q).map(v => fmt(v, 1)).join(", ")]);
    rows.push(["quaternion xyzw", p.q.map(v => fmt(v, 4)).join(", ")]);
    rows.push(["velocity (m/s)", p.v.map(v => fmt(v, 3)).join(", ")]);
    rows.push(["flags", D.flag_bits.filter((_, b) => p.flags & (1 << b)).join(", ") || "none"]);
  } else rows.push(["now", "not in the scene"]);
  let html = "<table id='gt' data-object='" + o.id + "'>";
  for (const [k, v] of rows) html += "<tr><td class='k'>" + k + "</td><td>" + esc(v) + "</td></tr>";
  html += "</table><p>Events of #" + o.id + ":</p><ol id='object-events'>";
  for (const e of o.events) {
    html += "<li data-t='" + e.t + "'>" + fmt(e.t, 3) + " s " + esc(e.type) + " " +
      esc(JSON.stringify(e.data)) + "</li>";
  }
  box.innerHTML = html + "</ol>";
  for (const li of box.querySelectorAll("li")) {
    li.addEventListener("click", () => { pause(); seek(Number(li.dataset.t)); });
  }
}
function esc(s) {
  return String(s).replace(/[&<>'"]/g, c => "&#" + c.charCodeAt(0) + ";");
}

function select(id) {
  state.sel = id;
  if (!byId.get(id)) document.getElementById("info").textContent = "No object there.";
  buildTimeline();
  draw();
}
function hit(cx, cy) {  // topmost object under canvas pixel (cx, cy)
  const i = frameAt(state.t);
  let best = null;
  for (const o of D.objects) {
    const p = pose(o, i);
    if (!p) continue;
    for (const ring of screenPieces(o, p)) {
      let inside = false;
      for (let a = 0, b = ring.length - 1; a < ring.length; b = a++) {
        const [xa, ya] = ring[a], [xb, yb] = ring[b];
        if ((ya > cy) !== (yb > cy) && cx < (xb - xa) * (cy - ya) / (yb - ya) + xa) {
          inside = !inside;
        }
      }
      if (inside && (!best || p.z > best[1])) best = [o.id, p.z];
    }
  }
  return best ? best[0] : 0;
}
const drag = {x: 0, y: 0, moved: false};
scene.addEventListener("click", ev => {
  if (drag.moved) return;
  const r = scene.getBoundingClientRect();
  select(hit(ev.clientX - r.left, ev.clientY - r.top));
});
scene.addEventListener("wheel", ev => {
  ev.preventDefault();
  const r = scene.getBoundingClientRect();
  zoomAt(ev.clientX - r.left, ev.clientY - r.top, Math.exp(-ev.deltaY * 0.0015));
}, {passive: false});
scene.addEventListener("mousedown", ev => { drag.x = ev.clientX; drag.y = ev.clientY;
  drag.moved = false; });
scene.addEventListener("mousemove", ev => {
  if (!(ev.buttons & 1)) return;
  const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
  if (!drag.moved && Math.hypot(dx, dy) < 4) return;
  drag.moved = true;
  state.view.panX += dx; state.view.panY += dy;
  drag.x = ev.clientX; drag.y = ev.clientY;
  draw();
});
scene.addEventListener("dblclick", () => zoomAt(0, 0, 0));

function seek(t) { state.t = Math.min(Math.max(0, t), D.duration_s); draw(); }
function pause() { state.playing = false; document.getElementById("play").textContent = "play"; }
function tick(now) {
  if (!state.playing) return;
  if (state.last !== null) state.t += (now - state.last) / 1000 * state.speed;
  state.last = now;
  if (state.t >= D.duration_s) { state.t = D.duration_s; pause(); }
  draw();
  requestAnimationFrame(tick);
}
function play() {
  if (state.t >= D.duration_s) state.t = 0;
  state.playing = true; state.last = null;
  document.getElementById("play").textContent = "pause";
  requestAnimationFrame(tick);
}
document.getElementById("play").addEventListener("click", () => state.playing ? pause() : play());
document.getElementById("speed").addEventListener("change", e => {
  state.speed = Number(e.target.value);
});
scrub.max = String(D.duration_s);
scrub.addEventListener("input", () => { pause(); seek(Number(scrub.value)); });
timeline.addEventListener("click", ev => {
  const r = timeline.getBoundingClientRect();
  const w = Number(timeline.getAttribute("width"));
  pause();
  seek((ev.clientX - r.left - LABEL_W) / (w - LABEL_W - PAD) * D.duration_s);
});
document.addEventListener("keydown", ev => {
  if (ev.key === " ") { ev.preventDefault(); state.playing ? pause() : play(); }
  if (ev.key === "ArrowRight") { pause(); seek(state.t + 1 / 30); }
  if (ev.key === "ArrowLeft") { pause(); seek(state.t - 1 / 30); }
});

function fromHash() {
  const h = new URLSearchParams(location.hash.slice(1));
  if (h.has("speed")) {
    state.speed = Number(h.get("speed"));
    document.getElementById("speed").value = h.get("speed");
  }
  state.hi = Number(h.get("highlight") || 0);
  if (h.has("t")) { pause(); seek(Number(h.get("t"))); } else draw();
  if (h.has("select")) select(Number(h.get("select")));
  if (h.has("click")) {
    const [x, y] = h.get("click").split(",").map(Number);
    scene.dispatchEvent(new MouseEvent("click", {clientX: x - window.scrollX,
      clientY: y - window.scrollY, bubbles: true}));
  }
  if (h.get("play") === "1") play();
}

document.getElementById("title").textContent = "Episode " + D.episode;
document.getElementById("meta").textContent = [
  D.cell ? "cell " + D.cell.name : "", D.speed_mps != null ? D.speed_mps + " m/s" : "",
  D.seed != null ? "seed " + D.seed : "", D.objects.length + " objects",
  D.dataset ? "dataset " + D.dataset : ""].filter(Boolean).join(" · ");
document.getElementById("notes").textContent = D.notes.join(" · ");
const legend = document.getElementById("legend");
for (const [name, hex] of Object.entries(D.classes)) {
  legend.insertAdjacentHTML("beforeend",
    "<span><span class='sw' style='background:" + hex + "'></span>" + esc(name) + "</span>");
}
(D.cell ? D.cell.stations : []).forEach((st, n) => {
  legend.insertAdjacentHTML("beforeend", "<span><span class='sw' style='background:" +
    STATION_HEX[n % STATION_HEX.length] + "'></span>" + esc(st.name) +
    " (TCP, target, window)</span>");
});
layout();
fromHash();
window.addEventListener("hashchange", fromHash);
window.addEventListener("resize", () => { layout(); draw(); });
