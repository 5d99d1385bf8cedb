// The parameter editor: every parameter of the selected vehicle, with what its component
// metadata says (group, description, unit, range, default), as QGroundControl's parameter
// screen shows them. Search and a group filter narrow the list; a value that differs from
// its default is marked; an edit is held to the metadata's range, confirmed, and what the
// vehicle echoed is shown. Observers read: the edit controls are `.ctl`, enabled only for
// the tab in control (handover.js).

import { callApi } from "./api.js";
import { confirmAction } from "./confirm.js";
import { updateControls } from "./handover.js";
import { page, vehiclePath } from "./page.js";
import { log } from "./ui.js";

const NO_GROUP = "Not described";
const ROW_LIMIT = 400; // rows drawn at once; the search narrows the rest

/** "12", "0.5": the value as the metadata's decimals would show it, never "-0". */
export function formatValue(value, info) {
  if (value === null || value === undefined) return "–";
  if (Number.isInteger(value) && (!info || info.type !== "Float")) return String(value);
  const places = info?.decimal_places;
  const text = Number.isInteger(places) ? Number(value).toFixed(Math.max(places, 0)) : String(Number(Number(value).toPrecision(7)));
  return text === "-0" || /^-0\.0*$/.test(text) ? text.slice(1) : text;
}

/** Whether value differs from the metadata's default (float32 rounding is not a change). */
export function changedFromDefault(value, info) {
  if (!info || info.default === null || info.default === undefined || value === null || value === undefined) return false;
  const a = Number(value);
  const b = Number(info.default);
  return Math.abs(a - b) > 1e-6 * Math.max(1, Math.abs(b));
}

/** The range as words ("0 … 20 m/s"), or "" without one. */
export function rangeText(info) {
  if (!info) return "";
  const unit = info.units ? ` ${info.units}` : "";
  const lo = info.min ?? null;
  const hi = info.max ?? null;
  if (lo !== null && hi !== null) return `${lo} … ${hi}${unit}`;
  if (lo !== null) return `≥ ${lo}${unit}`;
  if (hi !== null) return `≤ ${hi}${unit}`;
  return "";
}

/** Why value may not be set (the same words as the server's 422), or null. */
export function outOfRange(name, value, info) {
  if (!Number.isFinite(value)) return `${name}: enter a number`;
  if (info?.type === "Int32" && !Number.isInteger(value)) return `${name}: an integer parameter`;
  if (!info) return null;
  const below = info.min !== null && info.min !== undefined && value < info.min;
  const above = info.max !== null && info.max !== undefined && value > info.max;
  if (!below && !above) return null;
  const words = info.short_desc ? ` (${info.short_desc})` : "";
  return `${name}: ${value} is outside ${rangeText(info)}${words}`;
}

function el(tag, className, text) {
  const node = document.createElement(tag);
  if (className) node.className = className;
  if (text !== undefined) node.textContent = text;
  return node;
}

export class ParamEditor {
  constructor(root) {
    this.root = root;
    this.values = {}; // name → value, as the vehicle said
    this.metadata = {}; // name → ParamInfoOut
    this.metadataNote = "";
    this.vehicleKey = null; // whose metadata is held
    this.selected = null;
    this.loading = null;
    this.build();
  }

  build() {
    const bar = el("div", "row params-filter");
    this.search = el("input", "grow");
    this.search.type = "search";
    this.search.id = "params-search";
    this.search.placeholder = "search name or description";
    this.search.setAttribute("aria-label", "search parameters");
    this.group = el("select");
    this.group.id = "params-group";
    this.group.setAttribute("aria-label", "parameter group");
    bar.append(this.search, this.group);
    const options = el("div", "row small");
    const changed = el("label");
    this.changedOnly = el("input");
    this.changedOnly.type = "checkbox";
    this.changedOnly.id = "params-changed-only";
    changed.append(this.changedOnly, document.createTextNode(" changed only"));
    this.summary = el("span", "params-summary");
    this.summary.id = "params-summary";
    options.append(changed, this.summary);
    this.list = el("div", "params-list");
    this.list.id = "params-list";
    this.list.setAttribute("role", "listbox");
    this.list.setAttribute("aria-label", "parameters");
    this.detail = el("div", "params-detail hidden");
    this.detail.id = "params-detail";
    this.answer = el("div", "result params-answer", "–");
    this.answer.id = "params-answer";
    this.answer.setAttribute("aria-live", "polite");
    this.root.replaceChildren(bar, options, this.list, this.detail, this.answer);
    this.search.addEventListener("input", () => this.render());
    this.group.addEventListener("change", () => this.render());
    this.changedOnly.addEventListener("change", () => this.render());
  }

  /** Every value, and the metadata once per vehicle (it is the firmware's: it does not change). */
  async load() {
    if (page.vehicleId === null || page.rejected) return;
    const key = JSON.stringify(page.fleetVehicle ?? page.vehicleId);
    if (key !== this.vehicleKey) {
      this.vehicleKey = key;
      this.metadata = {};
      this.metadataNote = "";
      this.values = {};
      this.selected = null;
    }
    this.summary.textContent = "reading parameters…";
    const needMetadata = Object.keys(this.metadata).length === 0;
    const [values, metadata] = await Promise.allSettled([
      callApi("params", { vehicle: vehiclePath() }),
      needMetadata ? callApi("param_metadata", { vehicle: vehiclePath() }) : Promise.resolve(null),
    ]);
    if (key !== this.vehicleKey) return; // another vehicle was chosen meanwhile
    if (values.status === "fulfilled") {
      this.values = values.value?.params || {};
    } else {
      log("WARNING", `parameters: ${values.reason.message}`);
    }
    if (metadata.status === "fulfilled" && metadata.value) {
      this.metadata = metadata.value.parameters || {};
      this.metadataNote = metadata.value.available ? "" : `no metadata: ${metadata.value.error}`;
    } else if (metadata.status === "rejected") {
      this.metadataNote = `no metadata: ${metadata.reason.message}`;
    }
    this.fillGroups();
    this.render();
  }

  fillGroups() {
    const current = this.group.value;
    const groups = new Set();
    for (const name of Object.keys(this.values)) groups.add(this.metadata[name]?.group || NO_GROUP);
    const all = el("option", "", "All groups");
    all.value = "";
    this.group.replaceChildren(all, ...[...groups].sort().map((g) => {
      const option = el("option", "", g);
      option.value = g;
      return option;
    }));
    this.group.value = groups.has(current) ? current : "";
  }

  /** The names the search, the group and "changed only" let through, sorted. */
  shownNames() {
    const words = this.search.value.trim().toLowerCase();
    const group = this.group.value;
    return Object.keys(this.values).sort().filter((name) => {
      const info = this.metadata[name];
      if (group && (info?.group || NO_GROUP) !== group) return false;
      if (this.changedOnly.checked && !changedFromDefault(this.values[name], info)) return false;
      if (!words) return true;
      return name.toLowerCase().includes(words) || (info?.short_desc || "").toLowerCase().includes(words);
    });
  }

  render() {
    const names = this.shownNames();
    const total = Object.keys(this.values).length;
    const changed = Object.keys(this.values).filter((n) => changedFromDefault(this.values[n], this.metadata[n])).length;
    const note = this.metadataNote ? ` · ${this.metadataNote}` : "";
    this.summary.textContent = `${names.length} of ${total} · ${changed} changed${note}`;
    this.list.replaceChildren(...names.slice(0, ROW_LIMIT).map((name) => this.row(name)));
    if (names.length > ROW_LIMIT) this.list.append(el("div", "hint", `${names.length - ROW_LIMIT} more: search to narrow`));
    this.showDetail();
  }

  row(name) {
    const info = this.metadata[name];
    const value = this.values[name];
    const changed = changedFromDefault(value, info);
    const row = el("div", `param-row${changed ? " changed" : ""}${name === this.selected ? " selected" : ""}`);
    row.id = `param-row-${name}`;
    row.setAttribute("role", "option");
    row.setAttribute("aria-selected", String(name === this.selected));
    row.tabIndex = 0;
    row.title = info?.short_desc || "no description in the vehicle's metadata";
    const label = el("span", "param-name", name);
    const shown = el("span", "param-value", `${formatValue(value, info)}${info?.units ? ` ${info.units}` : ""}`);
    shown.id = `param-value-${name}`;
    const mark = el("span", "param-mark", changed ? "●" : "");
    if (changed) mark.title = `changed from the default ${formatValue(info.default, info)}`;
    row.append(label, shown, mark);
    const pick = () => { this.selected = name; this.render(); };
    row.addEventListener("click", pick);
    row.addEventListener("keydown", (e) => { if (e.key === "Enter") pick(); });
    return row;
  }

  showDetail() {
    const name = this.selected;
    if (!name || !(name in this.values)) {
      this.detail.classList.add("hidden");
      return;
    }
    const info = this.metadata[name];
    const value = this.values[name];
    const title = el("div", "param-title");
    title.append(el("b", "", name), document.createTextNode(info?.group ? ` · ${info.group}` : ""));
    const parts = [title];
    parts.push(el("div", "param-desc", info?.short_desc || "The vehicle's metadata does not describe this parameter."));
    if (info?.long_desc) parts.push(el("div", "hint", info.long_desc));
    const facts = el("div", "grid2 param-facts");
    const fact = (label, text, id) => {
      const b = el("b", "", text);
      if (id) b.id = id;
      facts.append(el("span", "", label), b);
    };
    fact("Value", `${formatValue(value, info)}${info?.units ? ` ${info.units}` : ""}`, "param-detail-value");
    if (info) {
      fact("Default", `${formatValue(info.default, info)}${info.units ? ` ${info.units}` : ""}`, "param-detail-default");
      fact("Range", rangeText(info) || "any", "param-detail-range");
      if (changedFromDefault(value, info)) fact("", "changed from the default", "param-detail-changed");
      if (info.reboot_required) fact("", "takes effect after a reboot");
    }
    parts.push(facts);
    if (info?.values?.length) {
      parts.push(el("div", "hint", info.values.map((v) => `${v.value}: ${v.description}`).join(" · ")));
    }
    if (info?.bitmask?.length) {
      parts.push(el("div", "hint", `bits: ${info.bitmask.map((b) => `${b.value}: ${b.description}`).join(" · ")}`));
    }
    const edit = el("div", "row");
    const input = el("input", "ctl num wide");
    input.id = "param-input";
    input.type = "number";
    input.step = info?.increment ?? (info?.type === "Int32" ? 1 : "any");
    if (info?.min !== null && info?.min !== undefined) input.min = info.min;
    if (info?.max !== null && info?.max !== undefined) input.max = info.max;
    input.value = value ?? "";
    input.setAttribute("aria-label", `new value of ${name}`);
    const set = el("button", "ctl", "Set…");
    set.id = "param-set";
    set.addEventListener("click", () => this.set(name, Number(input.value), input.value));
    edit.append(input, document.createTextNode(info?.units || ""), set);
    if (info && info.default !== null && info.default !== undefined) {
      const reset = el("button", "ctl", "Default");
      reset.id = "param-default";
      reset.title = `put the default ${formatValue(info.default, info)} in the field`;
      reset.addEventListener("click", () => { input.value = info.default; });
      edit.append(reset);
    }
    parts.push(edit);
    this.detail.replaceChildren(...parts);
    this.detail.classList.remove("hidden");
    updateControls(); // the new controls follow who is in control
  }

  /** The vehicle reports a parameter at a new value (another ground station, a script or the
   * vehicle itself set it): its row and detail show it; a value being typed is kept. */
  vehicleSaid(name, value) {
    if (!(name in this.values) || this.values[name] === value) return;
    const input = this.selected === name ? document.getElementById("param-input") : null;
    const focused = input !== null && document.activeElement === input;
    const typed = input && input.value !== String(this.values[name] ?? "") ? input.value : null;
    this.values[name] = value;
    this.render();
    const again = document.getElementById("param-input");
    if (again && typed !== null) again.value = typed;
    if (again && focused) again.focus();
  }

  say(text, cls) {
    this.answer.textContent = text;
    this.answer.className = `result params-answer ${cls}`;
  }

  /** Held to the range, confirmed, sent; the vehicle's echo (or its refusal) is shown. */
  async set(name, value, raw) {
    const info = this.metadata[name];
    const why = raw === "" ? `${name}: enter a number` : outOfRange(name, value, info);
    if (why) {
      this.say(`Not sent — ${why}`, "bad");
      log("WARNING", `parameter not sent — ${why}`);
      return;
    }
    const unit = info?.units ? ` ${info.units}` : "";
    const from = formatValue(this.values[name], info);
    const ok = await confirmAction({
      title: `Set ${name}?`,
      text: `${info?.short_desc ? `${info.short_desc}: ` : ""}from ${from}${unit} to ${value}${unit}`
        + `${info ? ` (default ${formatValue(info.default, info)}${unit}, range ${rangeText(info) || "any"})` : ""}.`
        + `${info?.reboot_required ? " It takes effect after a reboot." : ""}`,
      confirm: `Set ${name}`,
    });
    if (!ok) return;
    this.say(`${name}: sent, waiting for the vehicle…`, "pending");
    try {
      const answer = await callApi("set_param", {
        vehicle: vehiclePath(), params: { name }, body: { value },
        headers: { "X-Lease-Id": page.control?.leaseId || "" },
      });
      this.values[name] = answer.value;
      const shown = `${formatValue(answer.value, info)}${unit}`;
      const text = `${name} = ${shown} (the vehicle's echo)${changedFromDefault(answer.value, info) ? ", changed from the default" : ""}`;
      this.say(text, "ok");
      log("OK", text);
    } catch (err) {
      const text = `${name}: refused — ${err.message}`;
      this.say(text, "bad");
      log("ERROR", text);
    }
    this.render();
  }
}
