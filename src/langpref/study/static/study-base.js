"use strict";
// The participant's page: GET the current step, show it, POST the answer, show the step that comes back.
// Everything shown is built with DOM calls and textContent (no HTML from data). The time per query runs from the
// moment the step's videos play (or the step appears, when it has none) to the answer.
// A Study-2 query of any feedback kind is drawn from its step's `widget` (the kind's StudyPage: a text box, or a
// choice among the shown trajectories), so a kind from a plugin needs no edit here; Study 1 and the language queries
// keep their own page (how the robot read the feedback).

// The page is three scripts loaded in order (templates/study.html): study-base.js (shared state, DOM and API
// helpers, submitting an answer), study-steps.js (one renderer per kind of step) and study.js (introductions, the
// step loop and resuming).
const MAX_FEEDBACK = 500;
const PHASE_TITLES = {
  pre_survey: "Before we begin",
  improve: "Experiment 1: improve the robot's trajectory",
  improve_survey: "Experiment 1: survey",
  pref_language: "Experiment 2: teach the robot with language",
  pref_comparison: "Experiment 2: teach the robot with comparisons",  // other kinds: "Experiment 2: LABEL"
  pref_survey: "Experiment 2: survey",
  done: "Thank you",
};
const MEANINGS = {
  height: ["move higher", "move lower"],
  speed: ["move faster", "move slower"],
  distance_to_button: ["stay farther from the button", "get closer to the button"],
  distance_to_cube: ["stay farther from the cube", "get closer to the cube"],
  distance_to_bottle: ["stay farther from the bottle", "get closer to the bottle"],
  lift_success: ["lift the cube better", "lift the cube less"],
};

let me = null;
let staleNotice = null;
const TOUCH = window.matchMedia("(hover: none) and (pointer: coarse)").matches;
let current = null;
let shownAt = null;
let busy = false;

function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === null || v === undefined || v === false) continue;
    if (k === "text") node.textContent = v;
    else if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (v === true) node.setAttribute(k, "");
    else node.setAttribute(k, String(v));
  }
  for (const c of children) if (c !== null && c !== undefined) node.append(c);
  return node;
}

async function api(method, path, body) {
  const res = await fetch(path, {
    method,
    headers: {"Content-Type": "application/json", "X-Participant-Token": me.token},
    body: body === undefined ? undefined : JSON.stringify(body),
    cache: "no-store",
  });
  let data = null;
  try { data = await res.json(); } catch (e) { data = {error: "the server sent no JSON (HTTP " + res.status + ")"}; }
  if (!res.ok) {
    const err = new Error(data.error || ("HTTP " + res.status));
    err.status = res.status;
    throw err;
  }
  return data;
}

function meaning(u) {
  if (u.no_change) return "The robot took it as: this trajectory is close to what you want.";
  const pair = MEANINGS[u.feature];
  const text = pair ? pair[u.direction === "increase" ? 0 : 1] : `${u.direction} ${u.feature.replaceAll("_", " ")}`;
  return `The robot understood your feedback as \u201c${text}\u201d (confidence ${Math.round(100 * u.confidence)}%).`;
}

function setHeader(step) {
  document.getElementById("phase-title").textContent = PHASE_TITLES[step.phase]
    || (step.method_label ? `Experiment 2: ${step.method_label}` : step.phase);
  const code = document.getElementById("resume-code-shown");
  if (step.resume_code) {
    code.textContent = `Resume code: ${step.resume_code}`;
    code.title = "Write it down: with it you can continue in any browser if this page loses your session.";
    code.hidden = false;
  }
  const p = step.progress;
  let text = "";
  if (step.phase === "improve") {
    text = step.kind === "language" ? `Round ${p.done + 1} of ${p.total}` : `Round ${p.done} of ${p.total}`;
  } else if (step.kind === step.method || step.kind === "confirm") {  // a Study-2 query, of any kind
    text = `Query ${p.done + 1} of ${p.total}`;
  } else if (step.kind === "rating") {
    text = `After ${p.done} of ${p.total} queries`;
  }
  document.getElementById("progress-text").textContent = text;
  const bar = document.getElementById("progress");
  bar.max = Math.max(1, p.total);
  bar.value = step.kind === "done" ? bar.max : p.done;
}

// A video that is not made yet is answered 503 (Retry-After): the figure says it is being prepared (or, in Study 1
// with generated candidates, that the robot is making the trajectory) and asks again.
async function whenVideoFails(v, url, status) {
  if (!document.body.contains(v)) return;
  let wait = 2;
  let text = "Preparing the video\u2026";
  try {
    const res = await fetch(url, {headers: {Range: "bytes=0-0"}, cache: "no-store"});
    if (res.ok) { v.load(); return; }
    wait = parseInt(res.headers.get("Retry-After") || "2", 10) || 2;
    const data = await res.json().catch(() => ({}));
    const ahead = /\((\d+) ahead/.exec(data.error || "");
    const making = /new trajectory/.test(data.error || "");  // Study 1 with trajectories made in the simulator
    const what = making ? "The robot is making a new trajectory in the simulator" : "Preparing the video";
    text = what + (ahead && ahead[1] !== "0" ? ` (${ahead[1]} before it)` : "") + "\u2026";
  } catch (e) { text = "Waiting for the connection\u2026"; }
  status.textContent = text;
  setTimeout(() => { if (document.body.contains(v)) { v.src = url; v.load(); } }, wait * 1000);
}

function videos(urls, labels) {
  const box = el("div", {class: "videos" + (urls.length > 1 ? " two" : "") + (urls.length > 2 ? " many" : "")});
  const vids = [];
  urls.forEach((url, i) => {
    const v = el("video", {src: url, muted: true, autoplay: true, loop: true, playsinline: true, preload: "auto",
                           "aria-label": labels[i]});
    v.muted = true;
    vids.push(v);
    const replay = el("button", {type: "button", class: "secondary replay", text: "\u21BB Replay",
                                 "aria-label": "Replay " + labels[i],
                                 onclick: () => { v.currentTime = 0; v.play().catch(() => {}); }});
    const status = el("span", {class: "video-status", role: "status", text: "Loading the video\u2026"});
    const frame = el("div", {class: "frame loading"}, v, status);
    v.addEventListener("playing", () => { frame.classList.remove("loading"); });
    v.addEventListener("error", () => { frame.classList.add("loading"); whenVideoFails(v, url, status); });
    box.append(el("figure", {}, frame, el("figcaption", {}, el("span", {text: labels[i]}), replay)));
  });
  // the query's clock starts when every video has started playing
  let playing = 0;
  vids.forEach((v) => v.addEventListener("playing", () => {
    playing += 1;
    if (playing === vids.length && shownAt === null) shownAt = performance.now();
  }, {once: true}));
  return box;
}

function errorLine() { return el("p", {class: "error", role: "alert", hidden: true, id: "answer-error"}); }

function showError(message) {
  const e = document.getElementById("answer-error");
  if (e) { e.textContent = message; e.hidden = false; }
}

function clientMs() {
  return Math.max(0, Math.round(performance.now() - (shownAt === null ? renderedAt : shownAt)));
}
let renderedAt = 0;

async function submit(body, buttons) {
  if (busy) return;
  busy = true;
  buttons.forEach((b) => { b.disabled = true; });
  const status = document.getElementById("status");
  if (status) { status.textContent = "The robot is thinking\u2026"; status.hidden = false; }
  try {
    const next = await api("POST", `/api/participants/${encodeURIComponent(me.participant_id)}/answer`,
                           {...body, seq: current.seq});
    busy = false;
    render(next);
  } catch (e) {
    busy = false;
    buttons.forEach((b) => { b.disabled = false; });
    if (status) status.hidden = true;
    if (e.status === 409) {  // answered meanwhile (another tab or window): say so, then show where they are
      staleNotice = "That step had already been answered (in another tab or window?), so this answer was not "
                    + "recorded. Here is where you are now.";
      load();
      return;
    }
    showError(e.status ? e.message : "The connection was lost; your answer was not sent. Please try again.");
  }
}

let keyHandler = null;
