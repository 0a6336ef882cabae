// ehpss-hil monitor page: rows and status arrive over /ws; uPlot draws the chosen window of run
// time (s). Fail-safe (FAULT) and fallback intervals are shaded in their reason's colour and
// named; fault events (a true gain or the stuck flag changing) are dashed lines with their
// words; k̂ is a gap while the controller is not ACTIVE (no estimate in use). Pause, drag-zoom
// (all plots together) and the cursor read-out are here; export, capture and injection are in
// monitor-tools.js.
"use strict";
const BUFFER_S = 60;      // rows kept in the page (the server keeps 60 s too)
let ACTIVE = 2, FAULT = 3;  // CTRL_STATUS State codes: taken from the DBC's names at start-up
const cols = {};          // field -> array (SI), the last BUFFER_S seconds
const view = { windowS: 10, paused: false, holdY: false, t0: null, intervals: [], events: [], drawn: [], acks: [] };
let cfg = {};
let fields = [];
let plots = [];
let frames = 0, lastRateT = performance.now();

const PLOTS = [
  { id: "plot-position", scale: 1e3, unit: "mm", series: [
    ["x_true_m", "x (truth)", "#1f77b4"], ["y_s_m", "y_s (sensor)", "#999"],
    ["x_d_m", "x_d", "#2ca02c"], ["y_m_m", "y_m", "#d62728"]] },
  { id: "plot-error", scale: 1e6, unit: "µm", series: [["e_m", "e", "#9467bd"]] },
  { id: "plot-current", scale: 1e3, unit: "mA", series: [
    ["i_cmd_a", "commanded", "#ff7f0e"], ["i_applied_a", "applied", "#1f77b4"]] },
  { id: "plot-gains", scale: 1, unit: "", series: [
    ["k_loe_hat", "k̂_LOE", "#1f77b4"], ["k_dft_hat", "k̂_DFT", "#d62728"],
    ["k_loe_true", "k_LOE true", "#1f77b4", [6, 4]], ["k_dft_true", "k_DFT true", "#d62728", [6, 4]]] },
];
const ESTIMATES = new Set(["k_loe_hat", "k_dft_hat"]);

const num = (v) => String(Number(Number(v).toPrecision(3)));
// a fault change in an engineer's words (report/annotate.py describe_changes says the same)
const WORDS = {
  k_loe_true: (v) => (v === 1 ? "LOE cleared" : `LOE ${Math.round((1 - v) * 100)} %`),
  k_dft_true: (v) => (v === 0 ? "sensor failed" : v === 1 ? "drift cleared" : `drift ${num(v)}`),
  k_q_true: (v) => (v === 1 ? "k_Q back to 1" : `k_Q ${num(v)}`),
  stuck: (v) => (v ? "sensor stuck" : "sensor unstuck"),
};
const GAIN_STEP = 5e-5;
// injections the rows cannot show (no true-value column): marked where the emulator applied them
const ACK_WORDS = {
  frame_loss: (v) => `frame loss ${num(v * 100)} %`,
  position_bias_m: (v) => `sensor bias ${num(v * 1e3)} mm`,
  current_limit_a: (v) => `current limit ${num(v * 1e3)} mA`,
};

function reasonName(table, code) {
  const names = (cfg.choices || {})[table] || {};
  return names[code] ?? String(code);
}

function reasonColor(kind, reason) {
  const t = (cfg.reason_colors || {})[kind] || {};
  return t[reason] || (cfg.reason_colors || {}).unknown || "#999";
}

// the FAULT and fallback intervals and the fault events in the buffer, on the run-time axis
function scan(x) {
  const iv = [], ev = [];
  const st = cols.state || [], fr = cols.failsafe_reason || [], fb = cols.fallback || [];
  const fbr = cols.fallback_reason || [];
  let open = null;
  const close = (i) => { if (open) { open.x1 = x[i]; iv.push(open); open = null; } };
  for (let i = 0; i < x.length; i++) {
    let kind = null, reason = "";
    if (st[i] === FAULT) { kind = "FAULT"; reason = reasonName("FailsafeReason", fr[i]); }
    else if (fb[i] === 1) { kind = "fallback"; reason = fbr[i] ? reasonName("FallbackReason", fbr[i]) : ""; }
    if (open && kind === "fallback" && open.kind === kind && (!reason || !open.reason)) {
      // CTRL_STATS (10 Hz) names the reason after CTRL_STATUS (50 Hz) flags the fallback: one interval
      if (!open.reason && reason) { open.reason = reason; open.color = reasonColor(kind, reason); }
      continue;
    }
    if (open && (open.kind !== kind || open.reason !== reason)) close(i);
    if (kind && !open) open = { kind, reason, x0: x[i], x1: x[i], color: reasonColor(kind, reason) };
  }
  if (open) { open.x1 = x[x.length - 1]; open.open = true; iv.push(open); }
  for (const f of Object.keys(WORDS)) {
    const a = cols[f] || [];
    for (let i = 1; i < a.length; i++) {
      if (a[i] === null || a[i - 1] === null || Math.abs(a[i] - a[i - 1]) <= GAIN_STEP) continue;
      ev.push({ x: x[i], words: WORDS[f](a[i]) });
    }
  }
  const t0 = view.t0 ?? ((cols.t_s || [])[0] || 0);
  for (const a of view.acks) {
    if (a.status === "APPLIED" && ACK_WORDS[a.kind] && a.value !== null) ev.push({ x: a.t_s - t0, words: ACK_WORDS[a.kind](a.value) });
  }
  ev.sort((a, b) => a.x - b.x);
  view.intervals = iv;
  view.events = ev;
}

function label(iv) { return iv.reason ? `${iv.kind}: ${iv.reason}` : iv.kind; }

function tag(ctx, text, x, y) {  // a label on a white ground, readable over traces and shading
  const w = ctx.measureText(text).width, h = 12 * devicePixelRatio;
  ctx.fillStyle = "rgba(255,255,255,0.8)";
  ctx.fillRect(x - 2, y - h + 2, w + 4, h + 1);
  ctx.fillStyle = "#222";
  ctx.fillText(text, x, y);
}

// uPlot draw hook: shade the intervals, mark the events (canvas pixels, clipped to the plot)
function drawOverlays(u) {
  const { ctx, bbox } = u;
  const min = u.scales.x.min, max = u.scales.x.max;
  ctx.save();
  ctx.beginPath();
  ctx.rect(bbox.left, bbox.top, bbox.width, bbox.height);
  ctx.clip();
  ctx.font = `${11 * devicePixelRatio}px system-ui, sans-serif`;
  ctx.textAlign = "left";  // uPlot leaves its axis labels' alignment set
  ctx.textBaseline = "alphabetic";
  for (const iv of view.intervals) {
    if (iv.x1 < min || iv.x0 > max) continue;
    const a = u.valToPos(Math.max(iv.x0, min), "x", true), b = u.valToPos(Math.min(iv.x1, max), "x", true);
    ctx.globalAlpha = 0.25;
    ctx.fillStyle = iv.color;
    ctx.fillRect(a, bbox.top, Math.max(b - a, devicePixelRatio), bbox.height);
    ctx.globalAlpha = 1;
    tag(ctx, label(iv), a + 3, bbox.top + 12 * devicePixelRatio);
    view.drawn.push({ plot: u.root.id || u.__id, kind: iv.kind, reason: iv.reason, x0: iv.x0, x1: iv.x1, color: iv.color });
  }
  ctx.setLineDash([5 * devicePixelRatio, 4 * devicePixelRatio]);
  ctx.strokeStyle = "#555";
  for (const [i, e] of view.events.entries()) {
    if (e.x < min || e.x > max) continue;
    const p = u.valToPos(e.x, "x", true);
    ctx.beginPath();
    ctx.moveTo(p, bbox.top);
    ctx.lineTo(p, bbox.top + bbox.height);
    ctx.stroke();
    tag(ctx, e.words, p + 3, bbox.top + (27 + 13 * (i % 2)) * devicePixelRatio);
  }
  ctx.restore();
}

function syncZoom(u) {  // a drag on one plot zooms them all and freezes the view
  if (!u.select || u.select.width <= 0) return;
  const min = u.posToVal(u.select.left, "x"), max = u.posToVal(u.select.left + u.select.width, "x");
  setPaused(true);
  for (const p of plots) if (p.u !== u) p.u.setScale("x", { min, max });
}

function readout(u) {
  const i = u.cursor.idx;
  const out = document.getElementById("readout");
  if (i === null || i === undefined) return;
  const t = u.data[0][i];
  const spec = plots.find((p) => p.u === u).spec;
  const parts = spec.series.map(([, lab], j) => {
    const v = u.data[j + 1][i];
    return `${lab} ${v === null || v === undefined ? "–" : Number(v).toPrecision(4)}${spec.unit ? " " + spec.unit : ""}`;
  });
  out.textContent = `t = ${Number(t).toFixed(3)} s · ${parts.join(" · ")}`;
}

// y range: auto (the data's, padded) or held where it was when "hold y" was pressed
function yRange(u, min, max) {
  if (view.holdY && u.heldY) return u.heldY;
  return uPlot.rangeNum(min ?? 0, max ?? 1, 0.1, true);
}

function setHoldY(on) {
  view.holdY = on;
  for (const p of plots) p.u.heldY = on ? [p.u.scales.y.min, p.u.scales.y.max] : null;
  document.getElementById("hold-y").textContent = on ? "y: held (auto)" : "y: auto (hold)";
}

function makePlots() {
  const w = Math.max(320, Math.floor((document.querySelector(".plots").clientWidth - 40) / 2));
  plots = PLOTS.map((p) => {
    const series = [{ label: "t (s)", value: (u, v) => (v === null ? "–" : v.toFixed(3)) }].concat(
      p.series.map(([, label, stroke, dash]) => ({ label, stroke, width: 1.5, dash, spanGaps: false })));
    const opts = {
      width: w, height: 210, series, legend: { show: true, live: true },
      cursor: { show: true, drag: { x: true, y: false, setScale: true }, sync: { key: "monitor" } },
      axes: [{ label: "run time (s)", labelSize: 16, size: 36 }, { size: 60 }],
      scales: { x: { time: false }, y: { range: yRange } },
      hooks: { draw: [drawOverlays], setSelect: [syncZoom], setCursor: [readout] },
    };
    const data = [[]].concat(p.series.map(() => []));
    const u = new uPlot(opts, data, document.getElementById(p.id));
    u.root.id = p.id + "-u";
    return { spec: p, u };
  });
}

function append(rows) {
  const n = rows.t_s ? rows.t_s.length : 0;
  if (!n) return;
  for (const f of fields) (cols[f] = cols[f] || []).push(...rows[f]);
  const t = cols.t_s, tEnd = t[t.length - 1];
  let cut = 0;
  while (cut < t.length && t[cut] < tEnd - BUFFER_S) cut++;
  if (cut) for (const f of fields) cols[f].splice(0, cut);
}

function runTime() {
  const t = cols.t_s || [];
  const t0 = view.t0 ?? (t.length ? t[0] : 0);
  return t.map((v) => v - t0);
}

function redraw() {
  if (view.paused) return;
  const x = runTime();
  scan(x);
  view.drawn = [];
  const end = x.length ? x[x.length - 1] : 0;
  let i0 = 0;
  while (i0 < x.length && x[i0] < end - view.windowS) i0++;
  const st = (cols.state || []).slice(i0);
  for (const p of plots) {
    const data = [x.slice(i0)];
    for (const [f] of p.spec.series) {
      const a = (cols[f] || []).slice(i0);
      const gap = ESTIMATES.has(f);
      data.push(a.map((v, i) => (v === null || (gap && st[i] !== ACTIVE) ? null : v * p.spec.scale)));
    }
    p.u.setData(data);
  }
  showEvents();
  frames++;
  const now = performance.now();
  if (now - lastRateT >= 1000) {
    document.getElementById("refresh-rate").textContent = (frames * 1000 / (now - lastRateT)).toFixed(1);
    frames = 0; lastRateT = now;
  }
}

function showEvents() {
  const items = view.intervals.map((iv) =>
    `<li><span class="swatch" style="background:${iv.color}"></span>${label(iv)}: ` +
    `${iv.x0.toFixed(3)} – ${iv.open ? "now" : iv.x1.toFixed(3) + " s"}</li>`)
    .concat(view.events.map((e) => `<li>▏${e.words} at ${e.x.toFixed(3)} s</li>`));
  document.getElementById("events").innerHTML = items.join("") || "<li>none in the last 60 s</li>";
}

function setPaused(p) {
  view.paused = p;
  document.getElementById("pause").textContent = p ? "resume (live)" : "pause";
  document.getElementById("paused-note").hidden = !p;
  if (!p) redraw();
}

function setupView() {
  document.getElementById("pause").addEventListener("click", () => setPaused(!view.paused));
  document.getElementById("hold-y").addEventListener("click", () => setHoldY(!view.holdY));
  const sel = document.getElementById("window");
  sel.addEventListener("change", () => { view.windowS = Number(sel.value); view.paused = false; setPaused(false); });
}

const fmt = (v, d) => (v === null || v === undefined ? "–" : Number(v).toFixed(d));
const set = (id, text) => { document.getElementById(id).textContent = text; };

function model(slot, index) {
  if (slot === null || slot === undefined) return "–";
  const m = index.find((r) => r.slot === slot);
  return m ? `M${slot} (θ ${fmt(m.theta, 3)})` : `M${slot}`;
}

function showStatus(s) {
  const b = document.getElementById("banner");
  b.className = "banner " + s.banner.level;
  b.textContent = s.banner.text;
  view.t0 = s.t0_s;
  set("t0-from", s.t0_from ? `run time 0: ${s.t0_from}` : "");
  const v = s.values;
  set("state", s.state || "–");
  set("mode", s.mode || "–");
  set("failsafe-reason", s.failsafe_reason || "–");
  set("fallback", s.fallback === undefined ? "–" : (s.fallback ? "YES: " : "no; last reason ") + (s.fallback_reason || "–"));
  set("active-spool", model(s.active_spool, s.index));
  set("active-position", model(s.active_position, s.index));
  const estimating = s.state === "ACTIVE";
  set("k-loe-hat", estimating ? fmt(v.k_loe_hat, 3) : "– (no estimate)");
  set("k-dft-hat", estimating ? fmt(v.k_dft_hat, 3) : "– (no estimate)");
  set("k-true", `${fmt(v.k_loe_true, 3)} / ${fmt(s.k_q_true, 3)} / ${fmt(v.k_dft_true, 3)}` + (s.stuck ? " · STUCK" : ""));
  set("switches", s.switches ?? "–");
  set("trips", s.failsafe_trips ?? "–");
  set("overruns", s.overruns ?? "–");
  set("cycle-time-max", s.cycle_time_max_s === undefined ? "–" : `${fmt(s.cycle_time_max_s * 1e6, 0)} µs`);
  set("ctrl-rejected", s.ctrl_rejected ?? "–");
  set("bus-load", `${fmt(s.bus_load * 100, 1)} %`);
  set("rates", `${fmt(s.frames_per_s, 0)} · ${fmt(s.rejected_per_s, 1)}`);
  set("nmt", `${s.nmt.controller || "–"} · ${s.nmt.emulator || "–"}`);
  set("emcy", s.emcy.length ? s.emcy.join(", ") : "none on this bus");
  document.getElementById("verdicts").innerHTML = Object.entries(s.verdicts)
    .map(([k, n]) => `<tr><th>${k}</th><td>${n}</td></tr>`).join("");
  const active = [s.active_spool, s.active_position];
  document.querySelector("#index tbody").innerHTML = s.index.map((r) =>
    `<tr class="${active.includes(r.slot) ? "active" : ""}"><td>${r.slot}</td><td>${fmt(r.theta, 3)}</td>` +
    `<td>${r.j === null ? "–" : Number(r.j).toPrecision(3)}</td></tr>`).join("");
  const refNote = { none: " · x_d, y_m: start with --config", "attached late":
    " · x_d, y_m unknown: attached after the controller went ACTIVE", waiting: "", aligned: "" };
  set("ref-note", refNote[s.reference] ?? "");
  document.getElementById("err-title").innerHTML = v.x_true_m === null
    ? "Tracking error y<sub>s</sub> − y<sub>m</sub>, sensor (µm)" : "Tracking error x − y<sub>m</sub> (µm)";
  view.acks = s.inject_acks || [];
  showAcks(view.acks);
  showCapture(s.capture);
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.onopen = () => set("conn", "connected");
  ws.onclose = () => { set("conn", "disconnected, retrying"); setTimeout(connect, 1000); };
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    append(m.rows);
    showStatus(m.status);
    redraw();
  };
}

window.monitorView = view;

(async () => {
  cfg = await (await fetch("/api/config")).json();
  fields = cfg.fields;
  for (const [code, name] of Object.entries(cfg.choices.State || {})) {
    if (name === "ACTIVE") ACTIVE = Number(code);
    if (name === "FAULT") FAULT = Number(code);
  }
  if (cfg.title) set("title", cfg.title);
  setupView();
  setupTools(cfg);
  makePlots();
  connect();
})();
