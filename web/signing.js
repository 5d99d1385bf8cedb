// The MAVLink signing badge: whether the link to this vehicle is signed (state.link.signing).
import { setText } from "./ui.js";

export function renderSigning(state) {
  const s = (state.link || {}).signing;
  if (!s || !s.enabled) {
    setText("signing", "UNSIGNED", "");
  } else if (s.vehicles_signed) {
    setText("signing", "SIGNED", "ok");
  } else {
    // our key is set but the vehicle's frames do not verify: wrong key, or none on it (a
    // word that fits the badge whole at every width: test_layout.py)
    setText("signing", "SIGN FAIL", "bad");
  }
  const el = document.getElementById("signing");
  const failing = s?.enabled && !s.vehicles_signed
    ? " · our key is set but the vehicle's frames do not verify: it has another key, or none" : "";
  const title = `MAVLink 2 signing${failing} · rejected: ${s?.rejected_bad_signature} bad signature, ${s?.rejected_replay} replayed, ${s?.rejected_unsigned} unsigned`;
  if (el && s && el.title !== title) el.title = title;
}
