"use strict";
// The participant's page, part 3 of 3 (after study-base.js and study-steps.js): the introductions between parts,
// drawing the current step with its renderer, loading it from the server, and resuming with a code.

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
