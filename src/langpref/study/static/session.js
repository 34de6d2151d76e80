"use strict";
// What both participant pages share: where this browser keeps its participant session, and how a replaced session
// is kept under another key, never thrown away.
const KEY = "langpref-participant";

function keepPrevious() {
  const old = localStorage.getItem(KEY);
  if (!old) return;
  let list = [];
  try { list = JSON.parse(localStorage.getItem(KEY + "-previous") || "[]"); } catch (e) { list = []; }
  list.push(old);
  localStorage.setItem(KEY + "-previous", JSON.stringify(list.slice(-10)));
}
