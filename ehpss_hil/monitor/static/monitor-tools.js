// ehpss-hil monitor page, the tools: fault injection with the emulator's answer
// (FAULT_INJECT_ACK: applied, or refused and why), export of the visible data (CSV) and of the
// view (PNG), and the triggered capture (armed here, written by the monitor: candump log + CSV).
"use strict";
const ACK_WAIT_MS = 2000;   // no FAULT_INJECT_ACK within this: the emulator did not answer
let token = "";
let pending = null;         // the injection waiting for its answer: {kind, value, after, t}

function post(path, body) {
  return fetch(path, { method: "POST",
    headers: { "Content-Type": "application/json", "X-Monitor-Token": token },
    body: JSON.stringify(body) });
}

async function inject(kind, value) {
  const out = document.getElementById("inject-result");
  try {
    const r = await post("/api/inject", { kind, value: Number(value) });
    const j = await r.json();
    if (!j.sent) { out.className = "refused"; out.textContent = `refused by the monitor: ${j.error}`; return; }
    pending = { kind, value: Number(value), after: j.ack_after, t: performance.now() };
    out.className = "";
    out.textContent = `sent: ${j.sent} · waiting for the emulator's answer`;
  } catch (e) { out.className = "refused"; out.textContent = `not sent: ${e}`; }
}

function showAcks(acks) {
  if (!pending) return;
  const out = document.getElementById("inject-result");
  const ack = acks.find((a) => a.n > pending.after && a.kind === pending.kind);
  const what = `${pending.kind} = ${pending.value}`;
  if (ack) {
    out.className = ack.status === "APPLIED" ? "applied" : "refused";
    out.textContent = ack.status === "APPLIED"
      ? `applied by the emulator: ${what}` : `REFUSED by the emulator: ${ack.status} (${what})`;
    pending = null;
  } else if (performance.now() - pending.t > ACK_WAIT_MS) {
    out.className = "refused";
    out.textContent = `sent: ${what} · no answer from the emulator (is it running, with FAULT_INJECT_ACK?)`;
    pending = null;
  }
}

function setupInject(c) {
  if (!c.allow_inject) return;
  document.getElementById("inject").hidden = false;
  set("inject-token", c.token);
  const sel = document.getElementById("inject-kind");
  sel.innerHTML = c.kinds.map((k) => `<option>${k}</option>`).join("");
  for (const b of document.querySelectorAll("#inject .buttons button"))
    b.addEventListener("click", () => inject(b.dataset.kind, b.dataset.value));
  document.getElementById("inject-form").addEventListener("submit", (e) => {
    e.preventDefault();
    inject(sel.value, document.getElementById("inject-value").value);
  });
}

function download(name, blob) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.appendChild(a);
  a.click();
  setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 1000);
}

function stamp() { return new Date().toISOString().replace(/[-:]/g, "").slice(0, 15); }

// the rows inside the x range of the plots (what is on screen), SI units, run time first
function visibleCsv() {
  const x = runTime(), sc = plots[0].u.scales.x;
  const lines = [["t_run_s", ...fields].join(",")];
  for (let i = 0; i < x.length; i++) {
    if (x[i] < sc.min || x[i] > sc.max) continue;
    lines.push([x[i].toFixed(6), ...fields.map((f) => (cols[f][i] === null ? "" : cols[f][i]))].join(","));
  }
  return lines.join("\n") + "\n";
}

function exportCsv() { download(`monitor-${stamp()}.csv`, new Blob([visibleCsv()], { type: "text/csv" })); }

function exportPng() {  // the four plots as drawn (shading and events included), with their titles
  const cs = plots.map((p) => p.u.ctx.canvas), head = 24 * devicePixelRatio;
  const w = cs[0].width, h = cs[0].height + head;
  const out = document.createElement("canvas");
  out.width = 2 * w; out.height = 2 * h + head;
  const ctx = out.getContext("2d");
  ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, out.width, out.height);
  ctx.fillStyle = "#222"; ctx.font = `${14 * devicePixelRatio}px system-ui, sans-serif`;
  ctx.fillText(`${document.getElementById("title").textContent} · ${document.getElementById("banner").textContent}`, 8, 17 * devicePixelRatio);
  cs.forEach((c, i) => {
    const x0 = (i % 2) * w, y0 = head + Math.floor(i / 2) * h;
    ctx.fillText(document.querySelectorAll(".plot h3")[i].textContent, x0 + 8, y0 + 17 * devicePixelRatio);
    ctx.drawImage(c, x0, y0 + head);
  });
  out.toBlob((b) => download(`monitor-${stamp()}.png`, b), "image/png");
}

// the capture's threshold field: its unit on the page → SI factor
const CAPTURE_FIELDS = { e_m: ["e", "µm", 1e-6], x_true_m: ["x", "mm", 1e-3], y_s_m: ["y_s", "mm", 1e-3],
  i_cmd_a: ["i commanded", "mA", 1e-3], i_applied_a: ["i applied", "mA", 1e-3] };

async function arm() {
  const out = document.getElementById("capture-state");
  const field = document.getElementById("capture-field").value;
  const body = { trigger: document.getElementById("capture-trigger").value, field,
    level: Number(document.getElementById("capture-level").value) * CAPTURE_FIELDS[field][2],
    before_s: Number(document.getElementById("capture-before").value),
    after_s: Number(document.getElementById("capture-after").value) };
  const r = await post("/api/capture", body);
  const j = await r.json();
  out.textContent = r.ok ? `capture ${j.n}: armed` : `refused: ${j.error}`;
}

function showCapture(c) {
  if (!c) return;
  const out = document.getElementById("capture-state");
  const at = c.fired_run_s === null ? "" : ` at ${Number(c.fired_run_s).toFixed(3)} s (${c.reason})`;
  out.innerHTML = `capture ${c.n}: ${c.state}${at}` + c.files.map((f) =>
    f.startsWith("(") ? ` ${f}` : ` · <a href="/api/capture/${encodeURIComponent(f)}" download>${f}</a>`).join("");
}

function setupCapture(c) {
  if (!c.capture) return;
  document.getElementById("capture").hidden = false;
  document.getElementById("capture-field").innerHTML = Object.entries(CAPTURE_FIELDS)
    .map(([k, [lab, unit]]) => `<option value="${k}">|${lab}| (${unit})</option>`).join("");
  const trig = document.getElementById("capture-trigger");
  const sync = () => { document.getElementById("capture-threshold").hidden = trig.value !== "threshold"; };
  trig.addEventListener("change", sync);
  sync();
  document.getElementById("capture-arm").addEventListener("click", arm);
}

function setupTools(c) {
  token = c.token || "";
  setupInject(c);
  setupCapture(c);
  document.getElementById("export-csv").addEventListener("click", exportCsv);
  document.getElementById("export-png").addEventListener("click", exportPng);
}

window.monitorVisibleCsv = visibleCsv;
