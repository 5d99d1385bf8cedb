// Ready to fly: the state's arming_checks (PX4's arming-check report, or SYS_STATUS's bits)
// as one fixed-size top-bar element, "Ready to fly" / "Not ready", whose popover lists the
// checks in PX4's words: those of the mode flown, those of the mode picked in the mode menu
// when it is another, and those that concern only other modes.

import { $ } from "./ui.js";

const SEVERITY_CLASS = { EMERGENCY: "bad", ALERT: "bad", CRITICAL: "bad", ERROR: "bad", WARNING: "warn" };

const MODE_WORDS = { HOLD: "Hold" };
const modeWord = (mode) => MODE_WORDS[mode] || mode;

/** The element's text, its second line (short, and whole for wide screens) and its badge
 * class for a state, from the server's verdict: "ready" (arm, takeoff and an offboard start
 * would be taken), "arm_switches_mode" (only the flown mode's own checks fail: SkyHelm's Arm
 * switches to a mode PX4 arms in first), "not_ready" (PX4's reasons, or no home or position
 * yet). */
export function readinessLabel(state) {
  const checks = state?.arming_checks;
  if (state?.armed) return ["Armed", "", ""];
  const verdict = checks?.verdict ?? (checks?.ready === true ? "ready" : checks?.ready === false ? "not_ready" : null);
  if (!verdict) return ["Ready ?", "", ""];
  if (verdict === "ready") return ["Ready to fly", "", "ok"];
  if (verdict === "arm_switches_mode") {
    const to = modeWord(checks.arm_switches_to || "HOLD");
    return ["Ready", [`Arm → ${to} first`, `Arm switches to ${to} first`], "warn"];
  }
  return ["Not ready", "", "bad"];
}

/** The badge's words for a reader and a tooltip: "Ready — Arm switches to Hold first". */
export function readinessWords(state) {
  const [text, sub] = readinessLabel(state);
  return sub ? `${text} — ${sub[1]}` : text;
}

/** The checks of a report that concern `mode` (the flown mode's are `reasons`). */
export function checksFor(checks, mode) {
  if (!checks) return [];
  if (mode === checks.mode) return checks.reasons;
  return [...checks.reasons, ...checks.other_reasons].filter((c) => c.modes.includes(mode));
}

function item(check, withModes) {
  const li = document.createElement("li");
  li.className = `sev ${SEVERITY_CLASS[check.severity] || "info"}`;
  const text = document.createElement("span");
  text.textContent = check.text;
  li.append(text);
  const detail = [check.severity];
  if (check.component) detail.push(check.component);
  if (withModes && check.modes.length) detail.push(check.modes.join(", "));
  const small = document.createElement("small");
  small.textContent = detail.join(" · ");
  li.append(small);
  return li;
}

function hint(text) {
  const p = document.createElement("p");
  p.className = "hint";
  p.textContent = text;
  return p;
}

function section(title, checks, withModes, empty) {
  const box = document.createElement("section");
  const h = document.createElement("h3");
  h.textContent = title;
  box.append(h);
  if (!checks.length) {
    const none = document.createElement("p");
    none.className = "hint";
    none.textContent = empty;
    box.append(none);
    return box;
  }
  const list = document.createElement("ul");
  list.append(...checks.map((c) => item(c, withModes)));
  box.append(list);
  return box;
}

export class Readiness {
  constructor(button, popover, modeSelect) {
    this.button = button;
    this.popover = popover;
    this.modeSelect = modeSelect;
    this.state = null;
    button.addEventListener("click", () => this.toggle());
    modeSelect.addEventListener("change", () => this.renderPopover());
    document.addEventListener("keydown", (e) => { if (e.key === "Escape") this.toggle(false); });
    document.addEventListener("pointerdown", (e) => {
      if (!this.popover.contains(e.target) && !this.button.contains(e.target)) this.toggle(false);
    });
  }

  show(state) {
    this.state = state;
    const [text, sub, cls] = readinessLabel(state);
    const words = readinessWords(state);
    if (this.button.dataset.words !== words) {
      this.button.dataset.words = words;
      if (sub) {
        const main = document.createElement("span");
        main.className = "ready-main";
        main.textContent = text;
        const short = document.createElement("small");
        short.className = "ready-sub short";
        short.textContent = sub[0];
        const long = document.createElement("small");
        long.className = "ready-sub long";
        long.textContent = sub[1];
        this.button.replaceChildren(main, short, long);
      } else {
        this.button.textContent = text;
      }
    }
    for (const c of ["ok", "bad", "warn"]) this.button.classList.toggle(c, c === cls); // unchanged: no DOM write
    const checks = state.arming_checks;
    const count = checks ? checks.reasons.filter((c) => SEVERITY_CLASS[c.severity] === "bad").length : 0;
    const waiting = checks?.waiting_for?.length ? ` · waiting for ${checks.waiting_for.join(" and ")}` : "";
    const title = checks?.verdict === "arm_switches_mode"
      ? `${words}: PX4 will not arm in ${checks.mode}, it would in ${checks.arm_switches_to} — click for PX4's reasons`
      : checks?.ready === false && count
        ? `${count} failing check${count > 1 ? "s" : ""} in ${checks.mode}${waiting}: click for PX4's reasons`
        : waiting ? `Not ready${waiting}: click for details` : "PX4's arming checks: click for details";
    if (this.button.title !== title) this.button.title = title;
    if (this.button.getAttribute("aria-label") !== words) this.button.setAttribute("aria-label", words);
    if (!this.popover.classList.contains("hidden")) this.renderPopover();
  }

  toggle(open = this.popover.classList.contains("hidden")) {
    this.popover.classList.toggle("hidden", !open);
    this.button.setAttribute("aria-expanded", String(open));
    if (open) this.renderPopover();
  }

  renderPopover() {
    const checks = this.state?.arming_checks;
    const parts = [];
    if (!checks) {
      const p = document.createElement("p");
      p.className = "hint";
      p.textContent = "The vehicle has not told its arming checks yet.";
      parts.push(p);
    } else {
      const verdict = checks.ready === null ? "not told" : checks.ready ? "can arm" : "cannot arm";
      // PX4 may say it cannot arm (SYS_STATUS's pre-arm bit) before its reasons can be read
      const none = checks.ready !== false ? "No check fails."
        : checks.source === "events" ? `PX4 reports it cannot arm in ${checks.mode} without naming a check.`
          : `PX4 reports it cannot arm in ${checks.mode} (SYS_STATUS's pre-arm check); its reasons come with its arming-check report, once its events are read.`;
      parts.push(section(`In ${checks.mode} (flown): ${verdict}`, checks.reasons, false, none));
      if (checks.verdict === "arm_switches_mode") {
        parts.push(hint(`SkyHelm's Arm (and Takeoff) switch to ${checks.arm_switches_to} first, where PX4 would arm.`));
      }
      if (checks.waiting_for?.length) {
        parts.push(hint(`Not ready to fly until the vehicle reports its ${checks.waiting_for.join(" and ")}: takeoff and offboard need them.`));
      }
      const picked = this.modeSelect.value;
      if (picked && picked !== checks.mode && checks.source === "events") {
        const can = checks.can_arm_modes.includes(picked) ? "can arm" : "cannot arm";
        parts.push(section(`In ${picked} (picked): ${can}`, checksFor(checks, picked), false, "No check fails."));
      }
      if (checks.other_reasons.length) parts.push(section("Other modes", checks.other_reasons, true, ""));
      const source = document.createElement("p");
      source.className = "hint";
      source.textContent = checks.source === "events"
        ? "PX4's arming-check report"
        : "From SYS_STATUS only: the vehicle's events are not decoded";
      parts.push(source);
    }
    this.popover.replaceChildren(...parts);
  }
}

export const readiness = new Readiness($("ready-to-fly"), $("ready-popover"), $("mode-select"));
