// The page around the panels: which views show (2D map, 3D scene), light or dark (the
// system's choice, or the one the pilot picked, kept in localStorage), and the page's
// shortcut keys with their '?' list. The flying keys are offboard.js's KeyboardPilot.

import { $ } from "./ui.js";

const THEME_KEY = "skyhelm.theme";
export const THEMES = ["auto", "light", "dark"];
const THEME_LABELS = { auto: "◐", light: "☀", dark: "☾" };

export function currentTheme() {
  const chosen = document.documentElement.dataset.themeChoice;
  return THEMES.includes(chosen) ? chosen : "auto";
}

/** The theme in effect ("light" or "dark"): the chosen one, or the system's. */
export function effectiveTheme() {
  return document.documentElement.dataset.theme === "light" ? "light" : "dark";
}

export function setTheme(name) {
  const theme = THEMES.includes(name) ? name : "auto";
  document.documentElement.dataset.themeChoice = theme;
  window.skyhelmApplyTheme();
  try {
    if (theme === "auto") localStorage.removeItem(THEME_KEY);
    else localStorage.setItem(THEME_KEY, theme);
  } catch { /* storage off: the choice lasts for this page */ }
  const button = $("theme-toggle");
  button.textContent = THEME_LABELS[theme];
  button.title = `theme: ${theme}${theme === "auto" ? ` (${effectiveTheme()} from the system)` : ""} — T to change`;
}

function nextTheme() {
  setTheme(THEMES[(THEMES.indexOf(currentTheme()) + 1) % THEMES.length]);
}

// ---- views ---------------------------------------------------------------------------------

function showViews() {
  const map = $("map-enable").checked;
  const scene = $("scene-enable").checked;
  const views = $("views");
  views.classList.toggle("no-map", !map);
  views.classList.toggle("no-scene", !scene);
  $("views-off").classList.toggle("hidden", map || scene);
}

// ---- shortcuts -----------------------------------------------------------------------------

function typing(event) {
  const el = event.target;
  const tag = el?.tagName;
  return (tag === "INPUT" && el.type !== "range" && el.type !== "checkbox")
    || tag === "SELECT" || tag === "TEXTAREA" || el?.isContentEditable;
}

export function showShortcuts(on) {
  $("shortcuts").classList.toggle("hidden", !on);
  if (on) $("shortcuts-close").focus();
}

/** The page's own keys; `map` is the VehicleMap (follow, close its question). */
export function wireLayout(map) {
  setTheme(currentTheme());
  $("theme-toggle").addEventListener("click", nextTheme);
  $("shortcuts-open").addEventListener("click", () => showShortcuts(true));
  $("shortcuts-close").addEventListener("click", () => showShortcuts(false));
  $("shortcuts").addEventListener("click", (e) => { if (e.target.id === "shortcuts") showShortcuts(false); });
  for (const id of ["map-enable", "scene-enable"]) $(id).addEventListener("change", showViews);
  showViews();
  const toggle = (id) => $(id).click();
  const keys = {
    "?": () => showShortcuts($("shortcuts").classList.contains("hidden")),
    m: () => toggle("map-enable"),
    v: () => toggle("scene-enable"),
    c: () => map.setFollow(true),
    t: nextTheme,
  };
  window.addEventListener("keydown", (event) => {
    if (event.key === "Escape") {
      showShortcuts(false);
      map.map.closePopup();
      return;
    }
    if (event.ctrlKey || event.metaKey || event.altKey || typing(event)) return;
    const action = keys[event.key.length === 1 ? event.key.toLowerCase() : event.key];
    if (!action) return;
    event.preventDefault();
    action();
  });
}
