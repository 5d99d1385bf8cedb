// Runs before the page is drawn (a classic script in <head>), so a remembered theme never
// flashes the other one first. <html data-theme-choice> is the pilot's choice (auto, light,
// dark; kept in localStorage); <html data-theme> the one in effect, which for "auto" follows
// the system's prefers-color-scheme, also when it changes.
(() => {
  const root = document.documentElement;
  const systemLight = window.matchMedia("(prefers-color-scheme: light)");
  const apply = () => {
    const choice = root.dataset.themeChoice || "auto";
    root.dataset.theme = choice === "auto" ? (systemLight.matches ? "light" : "dark") : choice;
  };
  let saved = null;
  try { saved = localStorage.getItem("skyhelm.theme"); } catch { /* storage off */ }
  root.dataset.themeChoice = saved === "light" || saved === "dark" ? saved : "auto";
  apply();
  systemLight.addEventListener("change", apply);
  window.skyhelmApplyTheme = apply;
})();
