// Small page helpers: element lookup, number formatting, the message log and the banner.

import { page } from "./page.js";

const LOG_LIMIT = 400;
const REPLAY_NOTICE = "Replay of a recording — observe only";

export const $ = (id) => document.getElementById(id);
export { num } from "./format.js"; // never "-0.0"
export const nowS = () => performance.now() / 1000;

export function setText(id, text, cls) {
  const el = $(id);
  if (el.textContent !== text) el.textContent = text;
  if (cls !== undefined && el.dataset.cls !== cls) {
    if (el.dataset.cls) el.classList.remove(el.dataset.cls);
    if (cls) el.classList.add(cls);
    el.dataset.cls = cls;
  }
}

export function log(severity, text, time = new Date()) {
  const box = $("log");
  const line = document.createElement("div");
  line.className = `sev-${severity}`;
  const t = document.createElement("span");
  t.className = "t";
  t.textContent = time.toTimeString().slice(0, 8);
  const sev = document.createElement("span");
  sev.className = "t";
  sev.textContent = severity.padEnd(8);
  line.append(t, sev, document.createTextNode(text));
  const atBottom = box.scrollHeight - box.scrollTop - box.clientHeight < 20;
  box.append(line);
  while (box.childElementCount > LOG_LIMIT) box.firstElementChild.remove();
  if (atBottom) box.scrollTop = box.scrollHeight;
}

/** The banner; once the token is rejected only that (sticky) message shows. */
export function banner(text, ok = false, sticky = false) {
  if (page.rejected && !sticky) return;
  const el = $("banner");
  // A replay keeps saying so whenever no other message is showing.
  const shown = text || (page.readOnly ? REPLAY_NOTICE : "");
  el.textContent = shown;
  el.classList.toggle("ok", ok);
  el.classList.toggle("hidden", !shown);
  clearTimeout(banner.timer);
  if (ok) banner.timer = setTimeout(() => banner(""), 3000);
}
