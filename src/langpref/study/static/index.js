"use strict";
// The guidelines page: consent and start, or continue a session this browser already has (the start button is then
// hidden: one browser, one participant, unless the person says they are someone else), or resume with a code.

async function postJson(path, body) {
  const res = await fetch(path, {method: "POST", headers: {"Content-Type": "application/json"}, body: JSON.stringify(body)});
  const data = await res.json().catch(() => ({error: "HTTP " + res.status}));
  if (!res.ok) throw new Error(data.error || ("HTTP " + res.status));
  return data;
}

document.addEventListener("DOMContentLoaded", () => {
  const form = document.getElementById("consent-form");
  const err = document.getElementById("error");
  if (localStorage.getItem(KEY)) {
    document.getElementById("resume").hidden = false;
    form.hidden = true;
  }
  document.getElementById("new-person").addEventListener("click", () => {
    document.getElementById("resume").hidden = true;
    form.hidden = false;
    document.getElementById("consent").focus();
  });
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    err.hidden = true;
    if (!document.getElementById("consent").checked) {
      err.textContent = "Please tick the box to agree before starting.";
      err.hidden = false;
      return;
    }
    const button = document.getElementById("start");
    button.disabled = true;
    try {
      const data = await postJson("/api/participants", {});
      keepPrevious();
      localStorage.setItem(KEY, JSON.stringify(data));
      location.href = "/study";
    } catch (e) {
      err.textContent = "Could not start the study: " + e.message + ". Please try again.";
      err.hidden = false;
      button.disabled = false;
    }
  });
  document.getElementById("resume-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const rerr = document.getElementById("resume-error");
    rerr.hidden = true;
    try {
      const data = await postJson("/api/participants/resume", {code: document.getElementById("resume-code").value});
      keepPrevious();
      localStorage.setItem(KEY, JSON.stringify(data));
      location.href = "/study";
    } catch (e) {
      rerr.textContent = e.message;
      rerr.hidden = false;
    }
  });
});
