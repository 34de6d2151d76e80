"use strict";
// The participant's page: GET the current step, show it, POST the answer, show the step that comes back.
// Everything shown is built with DOM calls and textContent (no HTML from data). The time per query runs from the
// moment the step's videos play (or the step appears, when it has none) to the answer.
// A Study-2 query of any feedback kind is drawn from its step's `widget` (the kind's StudyPage: a text box, or a
// choice among the shown trajectories), so a kind from a plugin needs no edit here; Study 1 and the language queries
// keep their own page (how the robot read the feedback).

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

function questionField(q) {
  const required = q.required;
  const legend = el("legend", {text: q.text}, required ? null : el("span", {class: "optional", text: " (optional)"}));
  const fs = el("fieldset", {"data-qid": q.id, "data-type": q.type}, legend);
  const name = "q_" + q.id;
  if (q.type === "likert") {
    const row = el("div", {class: "likert"});
    const scale = el("div", {class: "scale", style: `--n: ${q.max - q.min + 1}`});
    for (let v = q.min; v <= q.max; v++) {
      scale.append(el("label", {class: "opt"}, el("input", {type: "radio", name, value: v}), String(v)));
    }
    row.append(scale);
    if (q.labels) {
      row.append(el("div", {class: "ends"}, el("span", {class: "end", text: `${q.min} = ${q.labels[0]}`}),
                    el("span", {class: "end", text: `${q.max} = ${q.labels[1]}`})));
    }
    fs.append(row);
  } else if (q.type === "text") {
    fs.querySelector("legend").setAttribute("id", name + "_l");
    fs.append(el("textarea", {name, rows: 2, maxlength: 2000, "aria-labelledby": name + "_l"}));
  } else {
    const multi = q.type === "multi";
    for (const o of q.options) {
      fs.append(el("label", {class: "opt"}, el("input", {type: multi ? "checkbox" : "radio", name, value: o}), o));
    }
  }
  return fs;
}

function collect(form, qs) {
  const answers = {};
  for (const q of qs) {
    const name = "q_" + q.id;
    if (q.type === "likert") {
      const c = form.querySelector(`input[name="${name}"]:checked`);
      if (c) answers[q.id] = parseInt(c.value, 10);
    } else if (q.type === "text") {
      const t = form.querySelector(`textarea[name="${name}"]`).value;
      if (t.trim()) answers[q.id] = t;
    } else if (q.type === "choice") {
      const c = form.querySelector(`input[name="${name}"]:checked`);
      if (c) answers[q.id] = c.value;
    } else {
      const cs = [...form.querySelectorAll(`input[name="${name}"]:checked`)].map((c) => c.value);
      if (cs.length) answers[q.id] = cs;
    }
  }
  const missing = qs.filter((q) => q.required && !(q.id in answers));
  return {answers, missing};
}

function renderSurvey(main, step) {
  main.append(el("h1", {text: step.title || "Survey"}));
  const form = el("form", {class: "survey", novalidate: true});
  step.questions.forEach((q) => form.append(questionField(q)));
  const send = el("button", {type: "submit", text: "Continue"});
  form.append(errorLine(), el("p", {}, send));
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    const {answers, missing} = collect(form, step.questions);
    if (missing.length) {
      showError("Please answer: " + missing.map((q) => q.text).join(" \u2022 "));
      form.querySelector(`fieldset[data-qid="${missing[0].id}"] input, fieldset[data-qid="${missing[0].id}"] textarea`)?.focus();
      return;
    }
    submit({answers}, [send]);
  });
  main.append(form);
}

function understoodNotice(step) {
  if (!step.understood) return null;
  const box = el("section", {class: "notice understood", role: "status", "aria-label": "your last feedback"},
                 el("h2", {class: "notice-title", text: "About your last feedback"}));
  if (step.understood.text) box.append(el("p", {text: `You said: \u201c${step.understood.text}\u201d`}));
  box.append(el("p", {text: meaning(step.understood)}));
  if (step.unchanged) {
    box.append(el("p", {text: "No trajectory the robot knows matches this feedback better, so it kept the same one. "
                              + "Try saying it differently."}));
  }
  box.append(el("p", {text: "If that is not what you meant, try rephrasing it next time."}));
  return box;
}

function renderLanguage(main, step) {
  const study1 = step.phase === "improve";
  const notice = understoodNotice(step);
  if (notice && !study1) {  // Study 2: the last answer's reading, then clearly apart, a new trajectory
    main.append(notice, el("hr", {class: "separator"}));
    main.append(el("h1", {text: `Query ${step.progress.done + 1}: a new trajectory. How should the robot move `
                                + "differently?"}));
  } else {
    main.append(el("h1", {text: study1 ? "How should the robot change this trajectory?"
                                       : "How should the robot move differently?"}));
    if (notice) main.append(notice);
  }
  main.append(videos(step.videos, [study1 ? "The robot's trajectory" : "A new trajectory"]));
  const form = el("form", {class: "feedback"});
  const label = el("label", {for: "feedback"}, "Your feedback (for example \u201cMove faster.\u201d). ",
                   TOUCH ? null : el("span", {class: "hint", text: "Press Enter to send, Shift+Enter for a new line."}));
  const box = el("textarea", {id: "feedback", name: "feedback", rows: 3, maxlength: MAX_FEEDBACK, autocomplete: "off"});
  const counter = el("span", {class: "counter", "aria-live": "polite", text: `0 / ${MAX_FEEDBACK}`});
  box.addEventListener("input", () => { counter.textContent = `${box.value.length} / ${MAX_FEEDBACK}`; });
  const send = el("button", {type: "submit", text: "Send feedback"});
  box.addEventListener("keydown", (ev) => {
    if (ev.key === "Enter" && !ev.shiftKey) { ev.preventDefault(); form.requestSubmit(); }
  });
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    if (!box.value.trim()) { showError("Please type your feedback before continuing."); box.focus(); return; }
    submit({feedback: box.value, client_ms: clientMs()}, [send]);
  });
  // Study 2: "that's good, no change" is an answer too (the robot learns the trajectory is close to the best)
  const good = study1 ? null : el("button", {type: "button", id: "no-change", class: "secondary",
                                             text: "It\u2019s good as it is (no change)"});
  good?.addEventListener("click", () => submit({feedback: {no_change: true}, client_ms: clientMs()}, [send, good]));
  form.append(label, box, el("div", {}, counter), errorLine(), el("p", {id: "status", class: "thinking", hidden: true}),
              el("p", {}, send, good ? " " : null, good));
  main.append(form);
  box.focus({preventScroll: true});
}

// The `choice` widget (comparisons, and any kind whose answer is one of the shown trajectories): one button per
// trajectory, its position (0-based) sent at the kind's answer field; keys 1..n choose too.
function renderChoice(main, step) {
  const w = step.widget, n = step.videos.length;
  const names = step.videos.map((_, i) => `Trajectory ${i + 1}`);
  main.append(el("h1", {text: w.prompt}));
  const watch = n === 2 ? "Watch both, then choose" : "Watch them all, then choose";
  const keys = n === 2 ? "keys 1 and 2" : `keys 1 to ${n}`;
  main.append(el("p", {text: TOUCH ? `${watch}.` : `${watch} (${keys} work too).`}));
  main.append(videos(step.videos, names));
  const buttons = names.map((_, i) => el("button", {type: "button", text: w.option.replace("{n}", String(i + 1)),
                                                    "data-choice": i}));
  const choose = (c) => submit({[w.answer_key]: c, client_ms: clientMs()}, buttons);
  buttons.forEach((b, i) => b.addEventListener("click", () => choose(i)));
  main.append(el("div", {class: "choices sticky"}, ...buttons), errorLine(),
              el("p", {id: "status", class: "thinking", hidden: true}));
  keyHandler = (ev) => {
    if (ev.target.tagName === "TEXTAREA" || ev.target.tagName === "INPUT") return;
    const c = parseInt(ev.key, 10) - 1;
    if (c >= 0 && c < n) choose(c);
  };
}

// The `text` widget (a kind whose answer is a typed text, other than the paper's language with its own page).
function renderText(main, step) {
  const w = step.widget;
  main.append(el("h1", {text: w.prompt}));
  main.append(videos(step.videos, step.videos.map((_, i) => `Trajectory ${i + 1}`)));
  const form = el("form", {class: "feedback"});
  const box = el("textarea", {id: "feedback", name: w.answer_key, rows: 3, maxlength: MAX_FEEDBACK,
                              autocomplete: "off", "aria-label": w.prompt});
  const send = el("button", {type: "submit", text: "Send"});
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    if (!box.value.trim()) { showError("Please type your answer before continuing."); box.focus(); return; }
    submit({[w.answer_key]: box.value, client_ms: clientMs()}, [send]);
  });
  form.append(box, errorLine(), el("p", {id: "status", class: "thinking", hidden: true}), el("p", {}, send));
  main.append(form);
  box.focus({preventScroll: true});
}
const WIDGETS = {choice: renderChoice, text: renderText};

// Asked when the robot is unsure how to read a typed answer: one click among its top readings, or none of them.
function renderConfirm(main, step) {
  main.append(el("h1", {text: "Which did you mean?"}));
  main.append(el("p", {text: `You said: \u201c${step.said}\u201d. The robot is not sure how to read it.`}));
  const buttons = step.options.map((o) => el("button", {type: "button", class: o.meaning === null ? "secondary" : null,
                                                       text: o.text, "data-meaning": o.meaning === null ? "none" : o.meaning}));
  buttons.forEach((b, i) => b.addEventListener("click", () => submit({meaning: step.options[i].meaning}, buttons)));
  main.append(el("div", {class: "choices confirm", role: "group", "aria-label": "what you meant"}, ...buttons),
              errorLine(), el("p", {id: "status", class: "thinking", hidden: true}));
}

function renderSatisfaction(main, step) {
  main.append(el("h1", {text: "Here is the improved trajectory"}));
  const notice = understoodNotice(step);
  if (notice) main.append(notice);
  if (step.previous_video) {
    main.append(videos([step.previous_video, step.videos[0]], ["Before your feedback", "After: the improved trajectory"]));
  } else {
    main.append(videos(step.videos, ["The improved trajectory"]));
  }
  main.append(el("p", {text: "Are you satisfied with the improved trajectory?"}));
  if (step.last_round) {
    main.append(el("p", {class: "notice last-round", text: "This was the last round: whatever you answer, "
                                                            + "Experiment 1 ends here and a short survey follows."}));
  }
  const yes = el("button", {type: "button", text: "Yes, I am satisfied"});
  const no = el("button", {type: "button", class: "secondary",
                           text: step.last_round ? "No, but end here (last round)" : "No, keep improving"});
  yes.addEventListener("click", () => submit({satisfied: true}, [yes, no]));
  no.addEventListener("click", () => submit({satisfied: false}, [yes, no]));
  main.append(el("div", {class: "choices sticky"}, yes, no), errorLine(),
              el("p", {id: "status", class: "thinking", hidden: true}));
}

function renderRating(main, step) {
  const notice = understoodNotice(step);
  if (notice) main.append(notice, el("hr", {class: "separator"}));
  main.append(el("h1", {text: "The best trajectory under what the robot has learned so far"}));
  main.append(videos(step.videos, ["The robot's best trajectory"]));
  main.append(el("p", {text: "How well does it match your preferences? 1 = not at all, 5 = perfectly."}));
  const buttons = [];
  for (let r = 1; r <= 5; r++) {
    const b = el("button", {type: "button", class: "secondary", text: String(r), "aria-label": `Rate ${r} of 5`});
    b.addEventListener("click", () => submit({rating: r}, buttons));
    buttons.push(b);
  }
  main.append(el("div", {class: "choices rating", role: "group", "aria-label": "rating"}, ...buttons), errorLine(),
              el("p", {id: "status", class: "thinking", hidden: true}));
}

function renderDone(main) {
  main.append(el("h1", {text: "Thank you!"}));
  main.append(el("p", {text: "You have completed the study. Your answers are saved; you can close this page."}));
}

let keyHandler = null;
document.addEventListener("keydown", (ev) => { if (keyHandler && !busy) keyHandler(ev); });

// Introductions between the parts (shown once per part in this tab, before its first step; nothing is sent).
const INTROS = {
  improve: ["Experiment 1: improve a trajectory",
            "The robot shows you a trajectory. Tell it in your own words how it should move differently; it then "
            + "shows you its improved trajectory beside the previous one and asks whether you are satisfied."],
};
const ORDINALS = ["first", "second", "third", "fourth", "fifth", "sixth"];
const COUNTS = ["no", "one way", "two ways", "three ways", "four ways", "five ways", "six ways"];

function introFor(step) {
  if (step.phase === "improve" && step.kind === "language" && step.number === 0) return INTROS.improve;
  if (step.method && step.kind === step.method && step.number === 1) {  // a method's intro is its kind's own
    const w = step.widget, k = step.method_position;
    const part = `Experiment 2, ${ORDINALS[k - 1] || "next"} method`;
    const lead = k > 1 ? "Now the robot learns your preferences again, another way. "
      : `In this experiment the robot learns your preferences in ${COUNTS[step.methods] || "several ways"}, one after `
        + `the other, each with ${step.progress.total} queries; after every few queries you rate its best `
        + "trajectory so far. ";
    return [`${part}: ${w.label.toLowerCase()}`, lead + w.intro];
  }
  return null;
}

function renderIntro(main, step, intro) {
  const key = `langpref-intro-${me.participant_id}-${step.seq}`;
  main.dataset.kind = "intro";
  main.append(el("h1", {text: intro[0]}), el("p", {class: "intro", text: intro[1]}));
  const go = el("button", {type: "button", id: "begin", text: "Begin"});
  go.addEventListener("click", () => { sessionStorage.setItem(key, "1"); render(step); });
  main.append(el("p", {}, go));
  go.focus({preventScroll: true});
}

function showStale(main) {
  if (!staleNotice) return;
  main.append(el("p", {class: "notice stale", role: "alert", text: staleNotice}));
  staleNotice = null;
}

function render(step) {
  const intro = introFor(step);
  if (intro && !sessionStorage.getItem(`langpref-intro-${me.participant_id}-${step.seq}`)) {
    current = step;
    keyHandler = null;
    setHeader(step);
    const main = document.getElementById("main");
    main.replaceChildren();
    main.dataset.phase = step.phase;
    showStale(main);
    renderIntro(main, step, intro);
    return;
  }
  current = step;
  shownAt = null;
  keyHandler = null;
  renderedAt = performance.now();
  setHeader(step);
  const main = document.getElementById("main");
  main.replaceChildren();
  main.dataset.kind = step.kind;
  main.dataset.phase = step.phase;
  showStale(main);
  const own = {survey: renderSurvey, language: renderLanguage, confirm: renderConfirm,
               satisfaction: renderSatisfaction, rating: renderRating, done: renderDone}[step.kind];
  (own || WIDGETS[step.widget.type])(main, step);
  if (!main.querySelector("textarea#feedback")) main.focus({preventScroll: true});
  window.scrollTo(0, 0);
  if (!step.videos.length) shownAt = renderedAt;
}

// The only copy of the session's token lives in this browser: it is never deleted by the page. When the server does
// not know it (restarted on another --db, say), the page says so, retries, and offers the resume code.
async function load() {
  try {
    render(await api("GET", `/api/participants/${encodeURIComponent(me.participant_id)}/step`));
  } catch (e) {
    const main = document.getElementById("main");
    if (e.status === 404 || e.status === 403 || e.status === 401) {
      main.replaceChildren(
        el("p", {class: "error", role: "alert", id: "unknown-session",
                 text: "The study server does not know this browser's session right now. Your answers are not lost: "
                       + "please tell the experimenter. This page tries again by itself."}),
        resumeForm(),
        el("p", {}, el("button", {type: "button", class: "secondary", text: "Try again now", onclick: load})));
      setTimeout(() => { if (document.getElementById("unknown-session")) load(); }, 10000);
      return;
    }
    main.replaceChildren(el("p", {class: "error", role: "alert", text: "Cannot reach the study server. Retrying\u2026"}));
    setTimeout(load, 3000);
  }
}

// A resume code (shown at the top of every step) restores a session in any browser: the server issues a new token.
function resumeForm() {
  const input = el("input", {id: "resume-code", autocomplete: "off", spellcheck: "false", placeholder: "ABCDE-FGH23",
                             "aria-label": "resume code", maxlength: 20});
  const err = el("p", {class: "error", role: "alert", hidden: true});
  const form = el("form", {class: "resume", id: "resume-form"},
                  el("label", {for: "resume-code", text: "Have your resume code? Enter it to continue: "}), input,
                  el("button", {type: "submit", text: "Resume"}), err);
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const res = await fetch("/api/participants/resume", {method: "POST", headers: {"Content-Type": "application/json"},
                                                         body: JSON.stringify({code: input.value})});
    const data = await res.json().catch(() => ({error: "HTTP " + res.status}));
    if (!res.ok) { err.textContent = data.error; err.hidden = false; return; }
    keepPrevious();
    localStorage.setItem(KEY, JSON.stringify(data));
    me = data;
    load();
  });
  return form;
}

document.addEventListener("DOMContentLoaded", () => {
  try { me = JSON.parse(localStorage.getItem(KEY) || "null"); } catch (e) { me = null; }
  if (!me || !me.participant_id || !me.token) {
    const main = document.getElementById("main");
    main.replaceChildren(el("p", {text: "This browser has no study session."}), resumeForm(),
                         el("p", {}, el("a", {href: "/", class: "button secondary", text: "Go to the start page"})));
    return;
  }
  load();
});
