// ehpss-hil monitor page: rows and status arrive over /ws; uPlot draws the last WINDOW_S seconds.
"use strict";
const WINDOW_S = 10;
const cols = {};          // field -> array (SI), the last WINDOW_S seconds
let fields = [];
let plots = [];
let frames = 0, lastRateT = performance.now();

const PLOTS = [
  { id: "plot-position", scale: 1e3, series: [
    ["x_true_m", "x (truth)", "#1f77b4"], ["y_s_m", "y_s (sensor)", "#999"],
    ["x_d_m", "x_d", "#2ca02c"], ["y_m_m", "y_m", "#d62728"]] },
  { id: "plot-error", scale: 1e6, series: [["e_m", "e", "#9467bd"]] },
  { id: "plot-current", scale: 1e3, series: [
    ["i_cmd_a", "commanded", "#ff7f0e"], ["i_applied_a", "applied", "#1f77b4"]] },
  { id: "plot-gains", scale: 1, series: [
    ["k_loe_hat", "k̂_LOE", "#1f77b4"], ["k_dft_hat", "k̂_DFT", "#d62728"],
    ["k_loe_true", "k_LOE true", "#1f77b4", [6, 4]], ["k_dft_true", "k_DFT true", "#d62728", [6, 4]]] },
];

function makePlots() {
  const w = Math.max(320, Math.floor((document.querySelector(".plots").clientWidth - 40) / 2));
  plots = PLOTS.map((p) => {
    const series = [{}].concat(p.series.map(([, label, stroke, dash]) => (
      { label, stroke, width: 1.5, dash, spanGaps: false })));
    const opts = { width: w, height: 210, series, legend: { show: true, live: false },
      cursor: { show: false }, axes: [{}, { size: 60 }], scales: { x: { time: true } } };
    const data = [[]].concat(p.series.map(() => []));
    return { spec: p, u: new uPlot(opts, data, document.getElementById(p.id)) };
  });
}

function append(rows) {
  const n = rows.t_s ? rows.t_s.length : 0;
  if (!n) return;
  for (const f of fields) (cols[f] = cols[f] || []).push(...rows[f]);
  const t = cols.t_s, tEnd = t[t.length - 1];
  let cut = 0;
  while (cut < t.length && t[cut] < tEnd - WINDOW_S) cut++;
  if (cut) for (const f of fields) cols[f].splice(0, cut);
}

function redraw() {
  const t = cols.t_s || [];
  for (const p of plots) {
    const data = [t];
    for (const [f] of p.spec.series) data.push((cols[f] || []).map((v) => (v === null ? null : v * p.spec.scale)));
    p.u.setData(data);
  }
  frames++;
  const now = performance.now();
  if (now - lastRateT >= 1000) {
    document.getElementById("refresh-rate").textContent = (frames * 1000 / (now - lastRateT)).toFixed(1);
    frames = 0; lastRateT = now;
  }
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
  const v = s.values;
  set("state", s.state || "–");
  set("mode", s.mode || "–");
  set("failsafe-reason", s.failsafe_reason || "–");
  set("fallback", s.fallback === undefined ? "–" : (s.fallback ? "YES: " : "no; last reason ") + (s.fallback_reason || "–"));
  set("active-spool", model(s.active_spool, s.index));
  set("active-position", model(s.active_position, s.index));
  set("k-loe-hat", fmt(v.k_loe_hat, 3));
  set("k-dft-hat", fmt(v.k_dft_hat, 3));
  set("k-true", `${fmt(v.k_loe_true, 3)} / ${fmt(s.k_q_true, 3)} / ${fmt(v.k_dft_true, 3)}` + (s.stuck ? " · STUCK" : ""));
  set("switches", s.switches ?? "–");
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
}

async function inject(kind, value) {
  const out = document.getElementById("inject-result");
  try {
    const r = await fetch("/api/inject", { method: "POST",
      headers: { "Content-Type": "application/json", "X-Monitor-Token": injectToken },
      body: JSON.stringify({ kind, value: Number(value) }) });
    const j = await r.json();
    out.textContent = j.sent ? `sent: ${j.sent}` : `refused: ${j.error}`;
  } catch (e) { out.textContent = `not sent: ${e}`; }
}

let injectToken = "";

function setupInject(cfg) {
  if (!cfg.allow_inject) return;
  injectToken = cfg.token;
  document.getElementById("inject").hidden = false;
  set("inject-token", cfg.token);
  const sel = document.getElementById("inject-kind");
  sel.innerHTML = cfg.kinds.map((k) => `<option>${k}</option>`).join("");
  for (const b of document.querySelectorAll("#inject .buttons button"))
    b.addEventListener("click", () => inject(b.dataset.kind, b.dataset.value));
  document.getElementById("inject-form").addEventListener("submit", (e) => {
    e.preventDefault();
    inject(sel.value, document.getElementById("inject-value").value);
  });
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

(async () => {
  const cfg = await (await fetch("/api/config")).json();
  fields = cfg.fields;
  if (cfg.title) set("title", cfg.title);
  setupInject(cfg);
  makePlots();
  connect();
})();
