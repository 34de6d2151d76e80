"use strict";
// The participant's page, part 2 of 3 (after study-base.js): one renderer per kind of step (survey, language,
// a kind's widget, confirm, satisfaction, rating, done). Each builds its step into `main` and submits its answer.

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
