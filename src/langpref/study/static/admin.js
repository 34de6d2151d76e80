"use strict";
// The admin dashboard: participants and their progress, videos, the --on-show robot hook's runs, a JSON download.
// The token stays in this tab (sessionStorage); every value is shown with textContent, so feedback is never HTML.

const TOKEN_KEY = "langpref-admin-token";
let timer = null;

function cell(text) {
  const td = document.createElement("td");
  td.textContent = text === null || text === undefined ? "" : String(text);
  return td;
}

function when(t) { return t ? new Date(t * 1000).toLocaleString() : ""; }

async function post(path, body) {
  const res = await fetch(path, {method: "POST", cache: "no-store", body: JSON.stringify(body),
                                 headers: {Authorization: "Bearer " + sessionStorage.getItem(TOKEN_KEY),
                                           "Content-Type": "application/json"}});
  const data = await res.json().catch(() => ({error: "HTTP " + res.status}));
  if (!res.ok) throw new Error(data.error || ("HTTP " + res.status));
  return data;
}

// Leave a participant out of the analyses (a test run, someone who gave up), or take them back in.
async function toggleExcluded(p) {
  let reason = "";
  if (!p.excluded) {
    reason = prompt(`Exclude participant #${p.number} from the analyses? Why (optional):`, "test participant");
    if (reason === null) return;
  }
  try {
    await post(`/api/admin/participants/${encodeURIComponent(p.participant_id)}/exclude`,
               {excluded: !p.excluded, reason});
    refresh();
  } catch (e) { showError(e.message); }
}

async function get(path) {
  const res = await fetch(path, {headers: {Authorization: "Bearer " + sessionStorage.getItem(TOKEN_KEY)},
                                 cache: "no-store"});
  const data = await res.json().catch(() => ({error: "HTTP " + res.status}));
  if (!res.ok) { const e = new Error(data.error || ("HTTP " + res.status)); e.status = res.status; throw e; }
  return data;
}

function showError(msg) {
  const e = document.getElementById("error");
  e.textContent = msg;
  e.hidden = !msg;
}

async function refresh() {
  try {
    const data = await get("/api/admin/participants");
    showError("");
    document.getElementById("login").hidden = true;
    document.getElementById("dashboard").hidden = false;
    const ps = data.participants;
    const finished = ps.filter((p) => p.finished_at).length;
    const excluded = ps.filter((p) => p.excluded).length;
    document.getElementById("summary").textContent =
      `${ps.length} participants, ${finished} finished, ${excluded} excluded from the analyses. Protocol: ${data.study.pref_queries} queries per method, ` +
      `rating every ${data.study.rating_every}, up to ${data.study.improve_max_iterations} improvement rounds, ` +
      `split ${data.study.split}.`;
    const v = data.videos;
    document.getElementById("video-status").textContent =
      `Videos ready: ${v.done} of ${v.total}${v.running ? " (making\u2026)" : ""}` +
      (Object.keys(v.errors).length ? `; ${Object.keys(v.errors).length} failed` : "");
    showHooks(data.hooks);
    const body = document.querySelector("#participants tbody");
    body.replaceChildren();
    for (const p of ps) {
      const tr = document.createElement("tr");
      if (p.excluded) tr.className = "excluded";
      tr.append(cell(p.number), cell(p.participant_id.slice(0, 8) + "\u2026"), cell(p.resume_code),
                cell(p.method_order.replace(",", " \u2192 ")),
                cell(p.phase), cell(p.kind), cell(`${p.progress.done} / ${p.progress.total}`), cell(p.answers),
                cell(when(p.created_at)), cell(when(p.finished_at)));
      const fb = document.createElement("td");
      const ul = document.createElement("ul");
      for (const f of p.recent_feedback) {
        const li = document.createElement("li");
        li.className = "feedback-text";
        li.dir = "auto";  // each text isolated: right-to-left text never reorders the rest of the line
        const read = f.understood_feature ? `${f.understood_feature}/${f.understood_direction}` : "no change, a button";
        li.textContent = `${f.text}  [${read}]`;
        ul.append(li);
      }
      fb.append(ul);
      tr.append(fb);
      const ex = document.createElement("td");
      const b = document.createElement("button");
      b.type = "button";
      b.className = "secondary exclude";
      b.textContent = p.excluded ? "Include again" : "Exclude";
      b.addEventListener("click", () => toggleExcluded(p));
      ex.append(p.excluded ? `excluded${p.excluded_reason ? ": " + p.excluded_reason : ""} ` : "", b);
      tr.append(ex);
      body.append(tr);
    }
  } catch (e) {
    if (e.status === 401 || e.status === 403) {
      sessionStorage.removeItem(TOKEN_KEY);
      document.getElementById("login").hidden = false;
      document.getElementById("dashboard").hidden = true;
      if (timer) { clearInterval(timer); timer = null; }
    }
    showError(e.message);
  }
}

// The --on-show hook (null when the server runs none): counts per outcome and its last runs, newest first.
function showHooks(h) {
  document.getElementById("hooks").hidden = !h;
  if (!h) return;
  const c = h.counts;
  const failures = c.failed + c.timeout + c.error + c.skipped;
  document.getElementById("hook-summary").textContent =
    `${h.command} (timeout ${h.timeout_s} s): ${c.ok} ok, ${failures} not ok` +
    (failures ? ` (${c.failed} exit non-zero, ${c.timeout} timed out, ${c.error} could not start, ` +
                `${c.skipped} skipped: queue full)` : "") +
    `; ${h.queued} waiting` + (h.waiting_for_generation ? `, ${h.waiting_for_generation} for the simulator` : "") +
    (h.running ? `, running for trajectory ${h.running.trajectory}` : "") + ".";
  const body = document.querySelector("#hook-runs tbody");
  body.replaceChildren();
  for (const r of h.recent) {
    const tr = document.createElement("tr");
    const status = cell(r.status);
    status.className = "hook-" + r.status;
    const output = cell(r.output);
    output.className = "hook-output";
    tr.append(cell(when(r.started_at)), cell(r.participant.slice(0, 8) + "\u2026"), cell(`${r.kind} (#${r.seq})`),
              cell(r.shows > 1 ? `${r.trajectory} (${String.fromCharCode(65 + r.position)})`
                   : r.data ? `generated ${r.trajectory}` : r.trajectory), cell(r.episode), status,
              cell(r.returncode), cell(r.seconds.toFixed(1)), output);
    body.append(tr);
  }
}

async function download() {
  try {
    const data = await get("/api/admin/export");
    const blob = new Blob([JSON.stringify(data, null, 2)], {type: "application/json"});
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = "study-export.json";
    a.click();
    URL.revokeObjectURL(a.href);
  } catch (e) { showError(e.message); }
}

function start() {
  refresh();
  if (!timer) timer = setInterval(refresh, 5000);
}

document.addEventListener("DOMContentLoaded", () => {
  document.getElementById("login").addEventListener("submit", (ev) => {
    ev.preventDefault();
    sessionStorage.setItem(TOKEN_KEY, document.getElementById("token").value.trim());
    start();
  });
  document.getElementById("export").addEventListener("click", download);
  if (sessionStorage.getItem(TOKEN_KEY)) start();
});
