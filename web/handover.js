// Who controls the vehicle, and handing control over: this tab's name, taking control (asking
// the holder first, or forcing it after a confirmation), answering another tab's request, and
// what the page shows when control is taken from it.

import {
  CLOSE_NOT_FOUND, ControlSession, callApi, describeError, reconnectDelayMs,
} from "./api.js";
import { setAttr } from "./draw.js";
import { FleetControlSession } from "./fleet-control.js";
import { page, vehiclePath } from "./page.js";
import { $, banner, log, setText } from "./ui.js";

const LABEL_KEY = "skyhelm.clientLabel";
const PROMPT_TICK_MS = 250;
const TAKEN_BANNER_MS = 10000; // then the note beside the holder keeps saying it
// A label a person can tell apart from other tabs: the browser's name (editable, kept for the
// next visit) and a short id of this tab (two tabs of one browser differ by it).
const TAB_ID = Math.floor(Math.random() * 0x10000).toString(16).padStart(4, "0");

// the banner this tab showed when it lost control, until it holds control again
let takenBanner = "";
// this tab answered Hand over: the lease it loses next was given, not taken
let handingOver = false;

const hooks = { onGained: () => {}, onLost: () => {}, onChange: () => {} };

/** Lets the flying side hear of control gained (with the lease answer) and lost, and of
 * every change that enables or disables the controls. */
export function onControl({ gained, lost, change }) {
  Object.assign(hooks, { onGained: gained, onLost: lost, onChange: change });
}

function browserName() {
  const ua = navigator.userAgent;
  const name = /Firefox\//.test(ua) ? "Firefox" : /Edg\//.test(ua) ? "Edge"
    : /Chrom(e|ium)\//.test(ua) ? "Chrome" : /Safari\//.test(ua) ? "Safari" : "Browser";
  return /Headless/.test(ua) ? `${name} (headless)` : name;
}

export function tabId() {
  return TAB_ID;
}

export function clientLabel() {
  return localStorage.getItem(LABEL_KEY) || browserName();
}

/** The client name the server puts after the token's name, e.g. "Chrome tab 7f3a". */
export function clientName() {
  return `${clientLabel()} tab ${TAB_ID}`;
}

/** A new label for this tab: kept for the next visit, and the holder renamed at once when
 * this tab controls the vehicle. */
export async function setClientLabel(text) {
  const label = text.trim().slice(0, 40);
  if (label && label !== browserName()) localStorage.setItem(LABEL_KEY, label);
  else localStorage.removeItem(LABEL_KEY);
  $("client-label").value = clientLabel();
  log("NOTICE", `this tab is called "${clientName()}"`);
  if (!inControl()) return;
  try {
    const lease = await callApi("renew", {
      vehicle: vehiclePath(), body: { client_name: clientName() },
      headers: { "X-Lease-Id": page.control.leaseId },
    });
    page.control.holder = lease.holder;
    renderHolder();
  } catch (err) {
    log("WARNING", `renaming the session: ${err.message}`);
  }
}

export function inControl() {
  return Boolean(page.control && page.control.open);
}

// ---- taking and giving control -------------------------------------------------------------

let retakeAttempt = 0;
let retakeTimer = null;
// the last try was answered "no such vehicle" (a server restarted before its vehicle came
// back): take control again as soon as the vehicle is heard, not at the end of a backoff
let retakeWhenHeard = false;

/** how: "take" (free control), "ask" (ask the holder), "force" (take it at once). */
export function takeControl(how = "take") {
  if (page.vehicleId === null || page.rejected) return;
  clearTimeout(retakeTimer);
  retakeWhenHeard = false;
  page.control?.close();
  page.wantControl = true;
  const asking = how === "ask";
  if (asking) showNote(`asking ${page.state?.lease?.holder || "the holder"} for control…`, "warn");
  const options = {
    takeover: how !== "take",
    force: how === "force",
    clientName: clientName(),
    onLease: (lease) => {
      retakeAttempt = 0;
      showNote("");
      // in control again: "Control taken by …: this tab no longer sends anything" is no
      // longer so, in the banner nor in the alert area
      if ($("banner").textContent === takenBanner) banner("");
      takenBanner = "";
      document.dispatchEvent(new CustomEvent("skyhelm-control-regained"));
      log("NOTICE", `control taken as ${lease.holder}${how === "force" ? " (forced)" : ""}`);
      hooks.onGained(lease);
      updateControls();
    },
    onClosed: (info) => closed(session, info),
    onMessage: (message) => onControlMessage(message),
  };
  // a vehicle of another edge is flown through the fleet server's REST routes
  const session = page.fleetVehicle
    ? new FleetControlSession(page.fleetVehicle, options)
    : new ControlSession(page.vehicleId, options);
  page.control = session;
  updateControls();
}

function closed(session, info) {
  if (page.control === session) page.control = null;
  hooks.onLost();
  const takenBy = info.ended?.by || (info.ended?.state === "taken_over" ? "another pilot" : null);
  const handedOver = handingOver;
  handingOver = false;
  if (info.byUs) {
    log("NOTICE", "control released");
  } else if (takenBy && handedOver) {
    // the pilot answered Hand over: no takeover to warn of, but this tab sends nothing now
    page.wantControl = false;
    const text = `Control handed over to ${takenBy}`;
    showNote(`${text} at ${new Date().toTimeString().slice(0, 8)}`);
    const told = `${text}: this tab no longer sends anything`;
    takenBanner = told;
    banner(told);
    setTimeout(() => { if ($("banner").textContent === told) banner(""); }, TAKEN_BANNER_MS);
    log("NOTICE", text);
  } else if (takenBy) {
    page.wantControl = false;
    const text = `Control taken by ${takenBy}`;
    document.dispatchEvent(new CustomEvent("skyhelm-control-taken", { detail: { by: takenBy } }));
    showNote(`${text} at ${new Date().toTimeString().slice(0, 8)}`, "bad");
    const told = `${text}: this tab no longer sends anything`;
    takenBanner = told;
    banner(told);
    setTimeout(() => { if ($("banner").textContent === told) banner(""); }, TAKEN_BANNER_MS);
    log("WARNING", text);
  } else if (info.code === 4409) {
    page.wantControl = false;
    const reason = info.refusal?.reason || info.reason || "control is held by another pilot";
    showNote(reason, "bad");
    log("WARNING", `control refused: ${reason}`);
  } else if (info.code === 4403 || info.code === 4401) {
    page.wantControl = false;
    log("ERROR", `control refused: ${info.reason || "this token may only observe"}`);
  } else if (info.code === 4408) {
    page.wantControl = false;
    showNote(`control lease ended (${info.ended?.state || info.reason || "expired"})`, "bad");
    log("WARNING", `control lease ended (${info.ended?.state || info.reason || "expired"})`);
  } else if (page.wantControl) {
    // A blip of the control socket alone: retry with backoff while the telemetry socket is
    // up (a server restart is handled when telemetry reconnects); a vehicle not there yet,
    // also as soon as it is heard (vehicleHeard).
    retakeWhenHeard = info.code === CLOSE_NOT_FOUND;
    const delayMs = reconnectDelayMs(retakeAttempt++);
    const inS = `${(delayMs / 1000).toFixed(1)} s`;
    log("WARNING", retakeWhenHeard
      ? `vehicle ${page.vehicleId} not heard yet; taking control once it is, or in ${inS}`
      : `control connection lost; taking control again in ${inS}`);
    retakeTimer = setTimeout(() => {
      if (page.wantControl && !page.control && page.connected) takeControl("take");
    }, delayMs);
  }
  hidePrompt();
  updateControls();
}

/** Telemetry from the current vehicle: the pilot who wanted control and was told the
 * vehicle was not there takes it now. */
export function vehicleHeard() {
  explainDisabled();
  if (retakeWhenHeard && page.wantControl && !page.control && page.connected) {
    retakeAttempt = 0;
    takeControl("take");
  }
}

/** The server answers again after a restart: the next retries start from a short delay. */
export function serverBack() {
  retakeAttempt = 0;
}

export function releaseControl() {
  page.wantControl = false;
  clearTimeout(retakeTimer);
  retakeWhenHeard = false;
  page.control?.close();
  page.control = null;
  hooks.onLost();
  hidePrompt();
  updateControls();
}

// ---- another tab asks for control -----------------------------------------------------------

let prompt = null;

/** A control event, from the telemetry socket or the control socket. */
export function onControlEvent(data) {
  if (data.action === "renamed" && inControl() && data.previous_holder === page.control.holder) {
    page.control.holder = data.holder;
  }
  if (data.action === "takeover_requested") {
    if (inControl() && (!data.holder || data.holder === page.control.holder)) showPrompt(data);
  } else if (prompt && (!data.request_id || data.request_id === prompt.requestId)
             && data.action !== "takeover_requested") {
    if (/takeover|taken|granted|denied|expired/.test(data.action || "")) hidePrompt();
  }
}

// On the control socket the holder hears of a request addressed to it.
function onControlMessage(message) {
  if (message.type === "takeover_requested") onControlEvent({ action: "takeover_requested", ...message });
}

function showPrompt(data) {
  if (prompt && prompt.requestId === data.request_id) return; // heard on both sockets
  hidePrompt();
  const timeoutS = Number(data.timeout_s) || 10;
  prompt = { requestId: data.request_id, deadline: performance.now() + timeoutS * 1000 };
  setText("takeover-by", `${data.by || "another pilot"} asks to take control`);
  $("takeover-prompt").classList.remove("hidden");
  const tick = () => {
    if (!prompt) return;
    const leftS = Math.max(0, (prompt.deadline - performance.now()) / 1000);
    setText("takeover-countdown", `${Math.ceil(leftS)} s`);
    if (leftS <= 0) hidePrompt();
    else prompt.timer = setTimeout(tick, PROMPT_TICK_MS);
  };
  tick();
  log("WARNING", `${data.by || "another pilot"} asks to take control (${timeoutS} s to answer)`);
}

function hidePrompt() {
  if (prompt) clearTimeout(prompt.timer);
  prompt = null;
  $("takeover-prompt").classList.add("hidden");
}

export async function answerPrompt(grant) {
  if (!prompt || !page.control) return;
  const { requestId } = prompt;
  hidePrompt();
  handingOver = grant;
  const answer = await page.control.answerTakeover(requestId, grant);
  if (answer.ok) log("NOTICE", grant ? "control handed over" : "request for control denied");
  else {
    handingOver = false;
    log("WARNING", `answer not taken: ${describeError(answer.status, answer.body)}`);
  }
}

// ---- who controls ---------------------------------------------------------------------------

let shownHolder = { name: undefined, since: 0 };

function showNote(text, cls = "") {
  setText("control-note", text, cls);
  $("control-note").classList.toggle("hidden", !text);
}

/** The holder from a state message's lease ({holder, since_s, session, …}). */
export function renderHolder(lease = page.state?.lease) {
  const holder = lease?.holder || null;
  const mine = inControl();
  if (holder !== shownHolder.name) {
    const sinceS = Number.isFinite(lease?.since_s) ? lease.since_s : 0;
    shownHolder = { name: holder, since: Date.now() - sinceS * 1000, session: lease?.session };
    if (holder && !Number.isFinite(lease?.since_s)) readHolderSince(holder);
  }
  const name = mine ? `you (${page.control.holder || holder || clientName()})` : holder || "nobody";
  // the slot shows a short name ("you", "Firefox tab 01ab"); its tooltip the whole one
  setText("holder", mine ? "you" : shortHolder(holder), mine ? "mine" : holder ? "other" : "");
  if ($("holder").title !== name) $("holder").title = name;
  const time = holder || mine ? clockAt(shownHolder.since) : "";
  const since = holder || mine ? `since ${time.slice(0, 8)}` : "";
  const session = lease?.session || shownHolder.session;
  setText("holder-since", holder || mine ? `· ${time.slice(0, 5)}` : "");
  const whole = `${since}${holder && session ? ` · ${session}` : ""}`;
  setAttr($("holder-since"), "title", whole);
  setAttr($("holder").parentElement, "title", `who controls the vehicle: ${name}${whole ? ` ${whole}` : ""}`);
  const otherHolds = Boolean(holder) && !mine;
  const asking = page.control && !page.control.open;
  $("take-control").classList.toggle("hidden", mine || page.readOnly);
  $("take-control").disabled = Boolean(asking) || !page.connected;
  setText("take-control", otherHolds ? "Ask for control" : "Take control");
  const takeTitle = !page.connected ? "the server is not connected"
    : asking ? `${otherHolds ? "asking the holder" : "taking control"}: waiting for the answer`
      : otherHolds ? "ask the holder to hand control over" : "take control of the vehicle (the control lease)";
  if ($("take-control").title !== takeTitle) $("take-control").title = takeTitle;
  $("force-control").classList.toggle("hidden", !otherHolds || page.readOnly);
  $("force-control").disabled = !page.connected;
  setAttr($("force-control"), "title", page.connected
    ? "take control at once, without asking the holder (a second click confirms)"
    : "the server is not connected");
  $("release").classList.toggle("hidden", !mine);
}

// The clock time the holder took control, formatted once (Date's toTimeString looks up the
// time zone: costly at every state).
let clock = { ms: NaN, text: "" };
function clockAt(ms) {
  if (clock.ms !== ms) clock = { ms, text: new Date(ms).toTimeString() };
  return clock.text;
}

/** "pilot · Chrome (headless) tab 7f3a" -> "Chrome 7f3a": the browser and the tab's id. */
export function shortHolder(holder) {
  if (!holder) return "nobody";
  const client = holder.split(" · ").pop();
  const tab = /^(\S+).*\btab (\w+)$/.exec(client);
  return tab ? `${tab[1]} ${tab[2]}` : client;
}

// The state names the holder; since when, and over which session, the control resource says.
async function readHolderSince(holder) {
  try {
    const status = await callApi("control_status", { vehicle: vehiclePath() });
    if (status.holder !== holder || shownHolder.name !== holder) return;
    if (Number.isFinite(status.since_s)) shownHolder.since = Date.now() - status.since_s * 1000;
    shownHolder.session = status.session;
    renderHolder();
  } catch {
    // the state keeps naming the holder; only the time it took control is missing
  }
}

/** Why the flying controls are greyed out now, in a pilot's words ("" when they are not). */
export function whyNotPilot() {
  if (inControl() && page.connected) return "";
  if (page.rejected) return "this link's token was rejected";
  if (page.readOnly) return "a replay of a recording: observe only";
  if (!page.connected) return "the server is not connected";
  if (page.control && !page.control.open) return "taking control: waiting for the server's answer";
  if (page.vehicleId === null || !page.state) return "vehicle not heard yet";
  return "Take control first";
}

let shownReason = null;

/** Every greyed-out control says why in its tooltip (its own tooltip after the reason). */
export function explainDisabled(force = false) {
  const reason = whyNotPilot();
  if (reason === shownReason && !force) return;
  shownReason = reason;
  for (const el of document.querySelectorAll(".ctl")) {
    if (el.dataset.title === undefined) el.dataset.title = el.title || "";
    const own = el.dataset.title;
    el.title = el.disabled && reason ? (own ? `${reason} — ${own}` : reason) : own;
  }
}

export function updateControls() {
  const pilot = inControl() && page.connected;
  document.body.classList.toggle("observing", !pilot);
  for (const el of document.querySelectorAll(".ctl")) el.disabled = !pilot;
  explainDisabled(true);
  renderHolder();
  hooks.onChange(pilot);
}

/** "Take control" when nobody holds it, "Ask for control" when someone does. */
export function takeControlClicked() {
  const holder = page.state?.lease?.holder;
  takeControl(holder && !inControl() ? "ask" : "take");
}
