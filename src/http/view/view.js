"use strict";
// The page's own state, read by the browser check (checks/view_browser.py).
const S = window.viewState = {
  session: null, kind: null, version: 0, events: 0, snapshots: 0, updates: 0,
  tracks: new Map(), trails: new Map(), plots: new Map(), sites: [], radars: [],
  origin: null, layout: [], pairs: new Map(), systemTracks: [], selected: null,
  ended: null, error: null, counters: null, lastT: null, warnings: [],
  confirmedIds() { return [...this.tracks.values()].filter(t => t.status === "confirmed").map(t => t.id).sort((a, b) => a - b); },
};
const $ = id => document.getElementById(id);
const canvas = $("map"), ctx = canvas.getContext("2d");
const KEY = "fusion.apiKey";
const view = { cx: 0, cy: 0, scale: 1 / 200, fitted: false };  // ENU centre (m), px per m
const RADAR_COLOURS = ["#79c0ff", "#ff7b72", "#d2a8ff", "#ffa657", "#7ee787", "#f778ba"];
const TRAIL = 120;
let abort = null, redrawPending = false;

$("key").value = sessionStorage.getItem(KEY) || "";
function headers() {
  const k = sessionStorage.getItem(KEY);
  return k ? { Authorization: "Bearer " + k } : {};
}
function status(text, cls) { const s = $("status"); s.textContent = text; s.className = cls || ""; }

async function listSessions() {
  try {
    const r = await fetch("/v1/sessions", { headers: headers() });
    if (!r.ok) { status(`sessions: ${r.status} ${(await problem(r))}`, "end"); return; }
    const body = await r.json();
    const sel = $("sessions"), keep = sel.value || hashSession();
    sel.innerHTML = '<option value="">–</option>';
    for (const s of body.sessions) {
      const o = document.createElement("option");
      o.value = s.id; o.textContent = `${s.kind} ${s.id.slice(0, 8)}… v${s.version}`;
      sel.appendChild(o);
    }
    if (keep && body.sessions.some(s => s.id === keep)) { sel.value = keep; if (S.session !== keep) watch(keep); }
    if (!S.session) status(`${body.sessions.length} sessions`);
  } catch (e) { status("sessions: " + e.message, "end"); }
}
async function problem(r) { try { const p = await r.json(); return p.detail || p.title || ""; } catch { return ""; } }
function hashSession() { const m = location.hash.match(/session=([0-9a-f]{32})/); return m ? m[1] : ""; }

// ---- the event stream (fetch streaming: EventSource cannot send headers)
async function watch(id, resumeFrom) {
  if (abort) abort.abort();
  const mine = abort = new AbortController();
  if (S.session !== id) reset(id);
  S.ended = null;
  const h = headers();
  if (resumeFrom) h["Last-Event-ID"] = String(resumeFrom);
  status(`connecting to ${id.slice(0, 8)}…`);
  let r;
  try { r = await fetch(`/v1/sessions/${id}/events`, { headers: h, signal: mine.signal }); }
  catch (e) { if (!mine.signal.aborted) retry(id, e.message); return; }
  if (!r.ok) { S.error = `${r.status} ${await problem(r)}`; status(S.error, "end"); return; }
  status(`watching ${id.slice(0, 8)}…`);
  const reader = r.body.getReader(), dec = new TextDecoder();
  let buf = "";
  try {
    for (;;) {
      const { value, done } = await reader.read();
      if (done) break;
      buf += dec.decode(value, { stream: true }).replace(/\r\n?/g, "\n");
      let i;
      while ((i = buf.indexOf("\n\n")) >= 0) { dispatch(buf.slice(0, i)); buf = buf.slice(i + 2); }
    }
  } catch (e) { if (mine.signal.aborted) return; }
  if (mine !== abort) return;
  if (!S.ended || S.ended.reason === "shutdown" || S.ended.reason === "slow") retry(id, S.ended ? S.ended.reason : "stream closed");
}
function retry(id, why) {
  status(`reconnecting (${why})…`, "warn");
  setTimeout(() => { if (S.session === id) watch(id, S.version); }, 1000);
}
function dispatch(block) {
  let event = "message", data = [];
  for (const line of block.split("\n")) {
    if (line.startsWith(":")) continue;              // heartbeat comment
    const c = line.indexOf(":"), f = c < 0 ? line : line.slice(0, c);
    const v = c < 0 ? "" : line.slice(c + 1).replace(/^ /, "");
    if (f === "event") event = v; else if (f === "data") data.push(v);
  }
  if (!data.length) return;
  const body = JSON.parse(data.join("\n"));
  S.events++;
  if (event === "snapshot") snapshot(body);
  else if (event === "update") update(body);
  else if (event === "end") { S.ended = body; status(`ended: ${body.reason} (${body.message})`, "end"); }
  schedule();
}

function reset(id) {
  Object.assign(S, { session: id, kind: null, version: 0, tracks: new Map(), trails: new Map(), plots: new Map(),
    sites: [], radars: [], origin: null, pairs: new Map(), systemTracks: [], selected: null, warnings: [] });
  view.fitted = false;
}
function snapshot(s) {
  S.snapshots++; S.kind = s.kind; S.version = s.version; S.warnings = s.warnings || [];
  if (s.plot_fusion) {
    const p = s.plot_fusion;
    S.layout = p.state_layout; S.radars = p.radars; S.sites = p.sites || []; S.origin = p.origin || null;
    S.counters = p.counters; S.lastT = p.last_frame_t;
    S.tracks = new Map(p.tracks.map(t => [t.id, t]));
    for (const t of p.tracks) trail(t);
  } else {
    S.systemTracks = s.system_tracks || [];
    S.pairs = new Map((s.pairs || []).map(p => [pairKey(p), p]));
    S.lastT = s.last_instant_t;
    for (const t of S.systemTracks) trail(t, "s" + t.id);
  }
  if (!view.fitted) fit();
}
function update(u) {
  S.updates++; S.version = u.version; if (u.warnings && u.warnings.length) S.warnings = u.warnings;
  if (u.plot_fusion) {
    const p = u.plot_fusion;
    S.counters = p.counters;
    for (const c of p.tracks) { S.tracks.set(c.track.id, c.track); trail(c.track); S.lastT = Math.max(S.lastT ?? -Infinity, c.track.t); }
    for (const d of p.deleted) { S.tracks.delete(d.id); S.trails.delete(d.id); }
    for (const id of p.dropped) { S.tracks.delete(id); S.trails.delete(id); }
    if (p.plots && p.plots.length) {
      const by = new Map();
      for (const m of p.plots) { if (!by.has(m.radar)) by.set(m.radar, []); by.get(m.radar).push(m); }
      for (const [r, list] of by) S.plots.set(r, list);   // the radar's latest plots
    }
  } else {
    if (u.system_tracks) { S.systemTracks = u.system_tracks; for (const t of S.systemTracks) trail(t, "s" + t.id); }
    for (const p of u.pairs || []) S.pairs.set(pairKey(p), p);
    if (u.instants && u.instants.length) S.lastT = u.instants[u.instants.length - 1];
  }
  if (!view.fitted) fit();
}
const pairKey = p => `${p.a.node}/${p.a.track}|${p.b.node}/${p.b.track}`;

// ---- geometry
function idx(name) { return S.layout.indexOf(name); }
function posOf(t) {
  if (S.kind === "plot_fusion") return [t.state[idx("x")], t.state[idx("y")]];
  // Correlation sessions: the client's state layout; x, y first and third
  // for the usual [x, vx, y, vy(, z, vz)], else the first two.
  const n = t.state.length;
  return n >= 4 ? [t.state[0], t.state[2]] : [t.state[0], t.state[1]];
}
function velOf(t) {
  if (S.kind === "plot_fusion") return [t.state[idx("vx")], t.state[idx("vy")]];
  return t.state.length >= 4 ? [t.state[1], t.state[3]] : [0, 0];
}
function trail(t, key) {
  key = key ?? t.id;
  const p = posOf(t); if (!p.every(Number.isFinite)) return;
  let tr = S.trails.get(key); if (!tr) S.trails.set(key, tr = []);
  const last = tr[tr.length - 1];
  if (!last || last[0] !== p[0] || last[1] !== p[1]) { tr.push(p); if (tr.length > TRAIL) tr.shift(); }
}
function toPx(e, n) { return [canvas.width / 2 + (e - view.cx) * view.scale, canvas.height / 2 - (n - view.cy) * view.scale]; }
function toEnu(x, y) { return [view.cx + (x - canvas.width / 2) / view.scale, view.cy - (y - canvas.height / 2) / view.scale]; }
// Latitude/longitude <-> ENU for the grid only: the local spherical
// approximation about the origin (R = 6371 km), within a fraction of a
// percent over a radar network's extent. Tracks and sites are drawn from
// the service's own ENU positions.
const R = 6371000, D = Math.PI / 180;
function llToEnu(lat, lon) { const o = S.origin; return [(lon - o.lon_deg) * D * R * Math.cos(o.lat_deg * D), (lat - o.lat_deg) * D * R]; }
function enuToLl(e, n) { const o = S.origin; return [o.lat_deg + n / R / D, o.lon_deg + e / (R * Math.cos(o.lat_deg * D)) / D]; }

function fit() {
  const pts = [];
  for (const s of S.sites) pts.push(s.position_m);
  for (const t of S.tracks.values()) pts.push(posOf(t));
  for (const t of S.systemTracks) pts.push(posOf(t));
  const ok = pts.filter(p => Number.isFinite(p[0]) && Number.isFinite(p[1]));
  if (!ok.length) return;
  const xs = ok.map(p => p[0]), ys = ok.map(p => p[1]);
  const [x0, x1, y0, y1] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  view.cx = (x0 + x1) / 2; view.cy = (y0 + y1) / 2;
  const span = Math.max(x1 - x0, y1 - y0, 20000) * 1.25;
  view.scale = Math.min(canvas.width, canvas.height) / span;
  view.fitted = true;
}
function niceStep(x) { const p = Math.pow(10, Math.floor(Math.log10(x))); for (const m of [1, 2, 5, 10]) if (m * p >= x) return m * p; return 10 * p; }

// ---- drawing
function schedule() { if (!redrawPending) { redrawPending = true; requestAnimationFrame(draw); } }
function resize() {
  const r = canvas.getBoundingClientRect(), d = window.devicePixelRatio || 1;
  canvas.width = Math.max(1, r.width * d); canvas.height = Math.max(1, r.height * d);
  ctx.setTransform(1, 0, 0, 1, 0, 0); schedule();
}
function draw() {
  redrawPending = false;
  const W = canvas.width, H = canvas.height, dpr = window.devicePixelRatio || 1;
  ctx.fillStyle = "#0d1117"; ctx.fillRect(0, 0, W, H);
  ctx.font = `${11 * dpr}px system-ui, sans-serif`;
  grid(W, H, dpr);
  sites(dpr);
  plots(dpr);
  if (S.kind === "plot_fusion") for (const t of S.tracks.values()) track(t, t.id, dpr);
  else for (const t of S.systemTracks) track(t, "s" + t.id, dpr);
  scaleBar(W, H, dpr);
  info(); details(); pairs();
}
function grid(W, H, dpr) {
  ctx.strokeStyle = "#21262d"; ctx.fillStyle = "#6e7681"; ctx.lineWidth = 1;
  const [e0, n1] = toEnu(0, 0), [e1, n0] = toEnu(W, H);
  if (S.origin) {
    const [la0, lo0] = enuToLl(e0, n0), [la1, lo1] = enuToLl(e1, n1);
    const step = niceStep(Math.max(la1 - la0, lo1 - lo0) / 8);
    const digits = Math.max(0, -Math.floor(Math.log10(step)));
    for (let la = Math.ceil(la0 / step) * step; la <= la1; la += step) {
      ctx.beginPath();
      for (let k = 0; k <= 40; k++) { const lo = lo0 + (lo1 - lo0) * k / 40; const [x, y] = toPx(...llToEnu(la, lo)); k ? ctx.lineTo(x, y) : ctx.moveTo(x, y); }
      ctx.stroke(); const [, y] = toPx(...llToEnu(la, lo0)); ctx.fillText(la.toFixed(digits) + "°", 4 * dpr, y - 3 * dpr);
    }
    for (let lo = Math.ceil(lo0 / step) * step; lo <= lo1; lo += step) {
      ctx.beginPath();
      for (let k = 0; k <= 40; k++) { const la = la0 + (la1 - la0) * k / 40; const [x, y] = toPx(...llToEnu(la, lo)); k ? ctx.lineTo(x, y) : ctx.moveTo(x, y); }
      ctx.stroke(); const [x] = toPx(...llToEnu(la0, lo)); ctx.fillText(lo.toFixed(digits) + "°", x + 3 * dpr, H - 6 * dpr);
    }
  } else {
    const step = niceStep((e1 - e0) / 8);
    for (let e = Math.ceil(e0 / step) * step; e <= e1; e += step) { const [x] = toPx(e, 0); ctx.beginPath(); ctx.moveTo(x, 0); ctx.lineTo(x, H); ctx.stroke(); ctx.fillText((e / 1000) + " km E", x + 3 * dpr, H - 6 * dpr); }
    for (let n = Math.ceil(n0 / step) * step; n <= n1; n += step) { const [, y] = toPx(0, n); ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(W, y); ctx.stroke(); ctx.fillText((n / 1000) + " km N", 4 * dpr, y - 3 * dpr); }
  }
}
function sites(dpr) {
  S.sites.forEach((s, i) => {
    const c = RADAR_COLOURS[i % RADAR_COLOURS.length], [x, y] = toPx(s.position_m[0], s.position_m[1]);
    // Coverage rings every 50 km out to the farthest plot seen (at least 100 km).
    let far = 100000;
    for (const m of S.plots.get(i) || []) far = Math.max(far, Math.hypot(m.position_m[0] - s.position_m[0], m.position_m[1] - s.position_m[1]));
    ctx.strokeStyle = c + "55"; ctx.setLineDash([4 * dpr, 4 * dpr]);
    for (let r = 50000; r <= far + 1; r += 50000) { ctx.beginPath(); ctx.arc(x, y, r * view.scale, 0, 2 * Math.PI); ctx.stroke(); }
    ctx.setLineDash([]);
    ctx.fillStyle = c; ctx.beginPath(); ctx.moveTo(x, y - 7 * dpr); ctx.lineTo(x - 6 * dpr, y + 5 * dpr); ctx.lineTo(x + 6 * dpr, y + 5 * dpr); ctx.closePath(); ctx.fill();
    ctx.fillText(`${s.id} (${s.kind}${s.doppler ? ", Doppler" : ""})`, x + 8 * dpr, y + 4 * dpr);
  });
}
function plots(dpr) {
  for (const [r, list] of S.plots) {
    ctx.fillStyle = RADAR_COLOURS[r % RADAR_COLOURS.length] + "aa";
    for (const m of list) { const [x, y] = toPx(m.position_m[0], m.position_m[1]); ctx.fillRect(x - 1.5 * dpr, y - 1.5 * dpr, 3 * dpr, 3 * dpr); }
  }
}
function colour(t) {
  if (S.kind !== "plot_fusion") return t.trial ? "#d29922" : "#3fb950";
  if (t.status === "tentative") return "#d29922";
  return t.consecutive_misses > 0 ? "#8b949e" : "#3fb950";
}
function track(t, key, dpr) {
  const p = posOf(t); if (!p.every(Number.isFinite)) return;
  const c = colour(t);
  const tr = S.trails.get(key) || [];
  if (tr.length > 1) {
    ctx.strokeStyle = c + "66"; ctx.lineWidth = 1.5 * dpr; ctx.beginPath();
    tr.forEach((q, k) => { const [x, y] = toPx(q[0], q[1]); k ? ctx.lineTo(x, y) : ctx.moveTo(x, y); }); ctx.stroke();
  }
  const [x, y] = toPx(p[0], p[1]), v = velOf(t);
  ctx.strokeStyle = c; ctx.lineWidth = 1.5 * dpr;
  if (v.every(Number.isFinite)) { const [vx, vy] = toPx(p[0] + 60 * v[0], p[1] + 60 * v[1]); ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(vx, vy); ctx.stroke(); }
  const sel = S.selected === key, r = (sel ? 6 : 4) * dpr;
  ctx.fillStyle = c; ctx.fillRect(x - r, y - r, 2 * r, 2 * r);
  if (sel) { ctx.strokeStyle = "#58a6ff"; ctx.lineWidth = 2 * dpr; ctx.strokeRect(x - r - 3 * dpr, y - r - 3 * dpr, 2 * r + 6 * dpr, 2 * r + 6 * dpr); }
  ctx.fillStyle = t.identity?.emergency ? "#f85149" : "#e6edf3"; ctx.fillText(label(t), x + 7 * dpr, y - 6 * dpr);
}
// A track's label: its callsign, else its Mode 3/A code, else its id; the
// flight level after it when known (as a radar display shows them).
function label(t) {
  const id = t.identity;
  if (!id) return String(t.id);
  const name = id.callsign?.value ?? (id.mode_3a ? "A" + id.mode_3a.value : String(t.id));
  const fl = id.pressure_altitude ? " FL" + Math.round(id.pressure_altitude.flight_level).toString().padStart(3, "0") : "";
  return name + fl + (id.emergency ? " " + id.emergency : "") + (id.spi ? " SPI" : "");
}
function scaleBar(W, H, dpr) {
  const m = niceStep(120 * dpr / view.scale), px = m * view.scale, x = W - px - 20 * dpr, y = H - 24 * dpr;
  ctx.strokeStyle = "#e6edf3"; ctx.lineWidth = 2 * dpr; ctx.beginPath(); ctx.moveTo(x, y); ctx.lineTo(x + px, y); ctx.moveTo(x, y - 5 * dpr); ctx.lineTo(x, y + 5 * dpr); ctx.moveTo(x + px, y - 5 * dpr); ctx.lineTo(x + px, y + 5 * dpr); ctx.stroke();
  ctx.fillStyle = "#e6edf3"; ctx.fillText(m >= 1000 ? `${m / 1000} km` : `${m} m`, x, y - 8 * dpr);
}
function esc(s) { return String(s).replace(/[&<>"]/g, c => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]); }
function rows(obj) { return Object.entries(obj).map(([k, v]) => `<tr><td>${esc(k)}</td><td>${esc(v)}</td></tr>`).join(""); }
function info() {
  const live = [...S.tracks.values()];
  const o = { session: S.session ? S.session.slice(0, 12) + "…" : "–", kind: S.kind ?? "–", version: S.version,
    "data time": S.lastT != null ? S.lastT.toFixed(2) + " s" : "–", events: `${S.events} (${S.snapshots} snapshots)` };
  if (S.kind === "plot_fusion") { o.confirmed = live.filter(t => t.status === "confirmed").length; o.tentative = live.filter(t => t.status === "tentative").length;
    if (S.counters) { o["plots accepted"] = S.counters.plots ?? "–"; o["frames"] = S.counters.frames ?? "–"; } }
  else if (S.kind) { o["system tracks"] = S.systemTracks.length; o.pairs = S.pairs.size; }
  if (S.ended) o.ended = S.ended.reason;
  $("info").innerHTML = rows(o);
  $("warnings").textContent = (S.warnings || []).join("\n");
}
function fmt(x, d = 1) { return Number.isFinite(x) ? x.toFixed(d) : "–"; }
function details() {
  const el = $("track");
  if (S.selected == null) { el.textContent = "click a track"; return; }
  let t = null;
  if (S.kind === "plot_fusion") t = S.tracks.get(S.selected);
  else t = S.systemTracks.find(s => "s" + s.id === S.selected);
  if (!t) { el.textContent = "the selected track is gone"; return; }
  const p = posOf(t), v = velOf(t), o = { id: t.id };
  if (S.kind === "plot_fusion") {
    const sig = k => Math.sqrt(t.covariance[idx(k)][idx(k)]);
    Object.assign(o, { status: t.status, "time (s)": fmt(t.t, 2), "east, north (m)": `${fmt(p[0], 0)}, ${fmt(p[1], 0)}`,
      "σ east, north (m)": `${fmt(sig("x"))}, ${fmt(sig("y"))}` });
    if (idx("z") >= 0) { o["up (m)"] = fmt(t.state[idx("z")], 0); o["σ up (m)"] = fmt(sig("z")); o["climb (m/s)"] = fmt(t.state[idx("vz")]); }
    o["speed (m/s)"] = fmt(Math.hypot(v[0], v[1])); o["heading (°)"] = fmt((Math.atan2(v[0], v[1]) / D + 360) % 360);
    o["σ vx, vy (m/s)"] = `${fmt(sig("vx"))}, ${fmt(sig("vy"))}`;
    if (t.lat_deg != null) o["lat, lon (°)"] = `${t.lat_deg.toFixed(5)}, ${t.lon_deg.toFixed(5)}`;
    if (t.height_m != null) o["height (m, WGS84)"] = fmt(t.height_m, 0);
    const id = t.identity;
    if (id) {
      if (id.callsign) o.callsign = id.callsign.value;
      if (id.mode_3a) o["Mode 3/A"] = id.mode_3a.value + (id.pending_mode_3a ? ` (→ ${id.pending_mode_3a.value})` : "");
      if (id.mode_s_address) o["Mode S address"] = `${id.mode_s_address.value} (${id.mode_s_address.plots} plots)`;
      if (id.pressure_altitude) { const a = id.pressure_altitude; o["flight level"] = `${fmt(a.flight_level, 2)} ± ${fmt(a.flight_level_sigma, 2)}`; o["climb (ft/min)"] = fmt(a.rate_of_climb_ftpm, 0); }
      if (id.emergency) o.emergency = id.emergency;
    }
    Object.assign(o, { radars: t.radars.join(", ") || "–", "hits / misses": `${t.hits} / ${t.misses}`, "consecutive misses": t.consecutive_misses, age: t.age });
    if (t.modes && t.modes.length) o.modes = t.modes.map(m => `${m.model} ${(100 * m.probability).toFixed(0)}%`).join(", ");
    if (t.turn_rate_dps != null) o["turn rate (°/s)"] = fmt(t.turn_rate_dps, 2);
    if (t.last_plot) o["last plot"] = JSON.stringify(t.last_plot);
    o["bias estimates"] = t.biases ? JSON.stringify(t.biases) : "none (not estimated by this release)";
  } else {
    Object.assign(o, { members: t.members.map(m => `${m.node}/${m.track}`).join(", "), fusion: t.fusion, trial: t.trial,
      "time (s)": fmt(t.t, 2), "x, y": `${fmt(p[0], 0)}, ${fmt(p[1], 0)}`, state: t.state.map(x => fmt(x)).join(", ") });
  }
  el.innerHTML = `<table>${rows(o)}</table>`;
}
function pairs() {
  const show = S.kind === "correlation";
  $("pairsTitle").hidden = !show;
  if (!show) { $("pairs").innerHTML = ""; return; }
  const list = [...S.pairs.values()].sort((a, b) => (a.decision > b.decision) - (a.decision < b.decision)).slice(0, 200);
  $("pairs").innerHTML = list.map(p => `<div><b>${esc(p.a.node)}/${esc(p.a.track)} – ${esc(p.b.node)}/${esc(p.b.track)}</b>: ${esc(p.decision)} (${esc(p.reason)}, m ${p.m}, C ${p.c})</div>`).join("");
}

// ---- interaction: pan, zoom, select
let drag = null;
canvas.addEventListener("mousedown", e => { drag = { x: e.clientX, y: e.clientY, cx: view.cx, cy: view.cy, moved: false }; canvas.style.cursor = "grabbing"; });
window.addEventListener("mouseup", e => {
  canvas.style.cursor = "grab";
  if (drag && !drag.moved) select(e);
  drag = null;
});
window.addEventListener("mousemove", e => {
  if (!drag) return;
  const d = window.devicePixelRatio || 1, dx = (e.clientX - drag.x) * d, dy = (e.clientY - drag.y) * d;
  if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
  view.cx = drag.cx - dx / view.scale; view.cy = drag.cy + dy / view.scale; schedule();
});
canvas.addEventListener("wheel", e => {
  e.preventDefault();
  const d = window.devicePixelRatio || 1, r = canvas.getBoundingClientRect();
  const [x, y] = [(e.clientX - r.left) * d, (e.clientY - r.top) * d], before = toEnu(x, y);
  view.scale *= Math.exp(-e.deltaY * 0.0015);
  const after = toEnu(x, y); view.cx += before[0] - after[0]; view.cy += before[1] - after[1]; schedule();
}, { passive: false });
function select(e) {
  const d = window.devicePixelRatio || 1, r = canvas.getBoundingClientRect(), x = (e.clientX - r.left) * d, y = (e.clientY - r.top) * d;
  let best = null, bestD = 12 * d;
  const cands = S.kind === "plot_fusion" ? [...S.tracks.values()].map(t => [t.id, t]) : S.systemTracks.map(t => ["s" + t.id, t]);
  for (const [k, t] of cands) { const [px, py] = toPx(...posOf(t)); const dd = Math.hypot(px - x, py - y); if (dd < bestD) { bestD = dd; best = k; } }
  S.selected = best; schedule();
}

$("save").onclick = () => { const k = $("key").value.trim(); k ? sessionStorage.setItem(KEY, k) : sessionStorage.removeItem(KEY); listSessions(); };
$("refresh").onclick = listSessions;
$("fit").onclick = () => { fit(); schedule(); };
$("sessions").onchange = e => { const id = e.target.value; if (id) { location.hash = "session=" + id; watch(id); } };
window.addEventListener("resize", resize);
setInterval(() => { if (!S.session) listSessions(); }, 5000);
resize(); listSessions();
