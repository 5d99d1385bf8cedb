// viser's own notices about WebGL ("Software WebGL rendering detected", "WebGL unavailable")
// are toasts at the top of the 3D view that stay until closed, over the scene's controls.
// The scene is served from this page's origin, so the page looks into the scene's document
// twice a second for its first minute (viser shows them once, at start; cheaper than
// observing every change of a document React redraws all the time), closes those toasts with
// their own close button, as the pilot would, and says the same, shorter, in the views' bar
// beside the 3D box (viser's words in its tooltip). Any other viser notice is left where
// viser puts it.

import { $ } from "./ui.js";

const TOAST = ".mantine-Notification-root";
const LOOK_EVERY_MS = 500;
const LOOK_FOR_MS = 60000;
// viser's titles (viser/client/src/BrowserWarning.tsx) and what the bar says instead
const NOTICES = [
  { title: /software webgl/i, text: "3D: no GPU, costs CPU" },
  { title: /webgl unavailable/i, text: "3D: WebGL unavailable" },
];

/** Hides viser's WebGL toasts in `doc` and shows their text in the bar; true once one was. */
function moveNotices(doc) {
  let moved = false;
  for (const toast of doc.querySelectorAll(TOAST)) {
    if (toast.dataset.skyhelmMoved) continue;
    const title = toast.querySelector(".mantine-Notification-title")?.textContent || toast.textContent;
    const notice = NOTICES.find((n) => n.title.test(title));
    if (!notice) continue;
    toast.dataset.skyhelmMoved = "1";
    // closed by its own button, so viser's notification list lets it go as when the pilot
    // closes it
    const close = toast.querySelector(".mantine-Notification-closeButton, button");
    if (close) close.click();
    else toast.style.display = "none";
    const shown = $("scene-notice");
    shown.textContent = notice.text;
    shown.title = `${title}: ${toast.querySelector(".mantine-Notification-description")?.textContent || ""}`.trim();
    shown.classList.remove("hidden");
    moved = true;
  }
  return moved;
}

/** Looks into every document the scene's frame loads. */
export function watchSceneNotices(frame) {
  let timer = null;
  frame.addEventListener("load", () => {
    clearInterval(timer);
    let doc = null;
    try {
      doc = frame.contentDocument;
    } catch {
      return; // not this origin (never, as served): viser keeps its toast
    }
    if (!doc?.body) return;
    const until = performance.now() + LOOK_FOR_MS;
    timer = setInterval(() => {
      if (moveNotices(doc) || performance.now() > until) clearInterval(timer);
    }, LOOK_EVERY_MS);
  });
}
