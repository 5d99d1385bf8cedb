// viser's own notices about WebGL ("Software WebGL rendering detected", "WebGL unavailable")
// are toasts at the top of the 3D view that stay until closed, over the scene's controls.
// The scene is served from this page's origin, so the page watches the scene's document,
// hides those toasts there and says the same, shorter, in the views' bar beside the 3D box
// (viser's words in its tooltip). Any other viser notice is left where viser puts it.

import { $ } from "./ui.js";

const TOAST = ".mantine-Notification-root";
// viser's titles (viser/client/src/BrowserWarning.tsx) and what the bar says instead
const NOTICES = [
  { title: /software webgl/i, text: "3D: software rendering (no GPU), costs CPU" },
  { title: /webgl unavailable/i, text: "3D: WebGL unavailable" },
];

function moveNotices(doc) {
  for (const toast of doc.querySelectorAll(TOAST)) {
    if (toast.dataset.skyhelmMoved) continue;
    const title = toast.querySelector(".mantine-Notification-title")?.textContent || toast.textContent;
    const notice = NOTICES.find((n) => n.title.test(title));
    if (!notice) continue;
    toast.dataset.skyhelmMoved = "1";
    toast.style.display = "none";
    const shown = $("scene-notice");
    shown.textContent = notice.text;
    shown.title = `${title}: ${toast.querySelector(".mantine-Notification-description")?.textContent || ""}`.trim();
    shown.classList.remove("hidden");
  }
}

/** Watches every document the scene's frame loads. */
export function watchSceneNotices(frame) {
  let observer = null;
  frame.addEventListener("load", () => {
    observer?.disconnect();
    observer = null;
    let doc = null;
    try {
      doc = frame.contentDocument;
    } catch {
      return; // not this origin (never, as served): viser keeps its toast
    }
    if (!doc?.body) return;
    moveNotices(doc);
    observer = new MutationObserver(() => moveNotices(doc));
    observer.observe(doc.body, { childList: true, subtree: true });
  });
}
