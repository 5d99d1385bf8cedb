// A modal confirmation for the actions a pilot must not take by a slip: arming in the air,
// killing the motors. Resolves true only on the explicit confirm button; Escape, Cancel or a
// click outside resolve false.

const $ = (id) => document.getElementById(id);
let pending = null;

/** Asks; resolves true when the pilot confirms. */
export function confirmAction({ title, text, confirm = "Confirm" }) {
  const dialog = $("confirm-dialog");
  pending?.(false);
  $("confirm-title").textContent = title;
  $("confirm-text").textContent = text;
  $("confirm-ok").textContent = confirm;
  return new Promise((resolve) => {
    pending = (answer) => {
      pending = null;
      if (dialog.open) dialog.close();
      resolve(answer);
    };
    dialog.showModal();
    $("confirm-cancel").focus(); // Enter must not confirm by accident
  });
}

export function wireConfirm() {
  const dialog = $("confirm-dialog");
  $("confirm-ok").addEventListener("click", () => pending?.(true));
  $("confirm-cancel").addEventListener("click", () => pending?.(false));
  dialog.addEventListener("close", () => pending?.(false));
  dialog.addEventListener("click", (e) => { if (e.target === dialog) pending?.(false); });
}
