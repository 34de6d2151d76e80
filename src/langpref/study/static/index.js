"use strict";
const KEY = "langpref-participant";

document.addEventListener("DOMContentLoaded", () => {
  const saved = localStorage.getItem(KEY);
  if (saved) document.getElementById("resume").hidden = false;
  const form = document.getElementById("consent-form");
  const err = document.getElementById("error");
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
      const res = await fetch("/api/participants", {method: "POST", headers: {"Content-Type": "application/json"}, body: "{}"});
      const data = await res.json();
      if (!res.ok) throw new Error(data.error || ("HTTP " + res.status));
      localStorage.setItem(KEY, JSON.stringify(data));
      location.href = "/study";
    } catch (e) {
      err.textContent = "Could not start the study: " + e.message + ". Please try again.";
      err.hidden = false;
      button.disabled = false;
    }
  });
});
