// Boxes of every visible control and panel, checked in the page: returns what is wrong
// (test_layout.py evaluates this function). Options: `reach`, ids of controls that must be
// in sight without scrolling anything; `boxes`, ids whose boxes (page coordinates) come back;
// `scope`, a selector: only what lies inside it is checked (and the top bar's row).
(given) => {
  const options = given || {};
  const inScope = options.scope ? (el) => el.closest(options.scope) !== null : () => true;
  const CONTROLS = "button, input, select, textarea, a[href], iframe, [role=button]";
  const BOXES = CONTROLS + ", .panel, .view, .leaflet-control, #topbar .slot, #alerts > *";
  const problems = [];
  const vw = document.documentElement.clientWidth;
  const vh = document.documentElement.clientHeight;
  const name = (el) => el.id ? `#${el.id}` : `${el.tagName.toLowerCase()}.${[...el.classList].join(".")}`
    + (el.textContent.trim() ? ` "${el.textContent.trim().slice(0, 24)}"` : "");
  // drawn: not display:none, hidden, transparent, nor inside a closed <details>
  const shown = (el) => {
    const r = el.getBoundingClientRect();
    if (r.width < 1 || r.height < 1) return false;
    return el.checkVisibility({ contentVisibilityAuto: true, opacityProperty: true, visibilityProperty: true });
  };
  const scrolls = (cs) => /(auto|scroll)/.test(cs.overflowY) || /(auto|scroll)/.test(cs.overflowX);
  const clips = (cs) => cs.overflowX !== "visible" || cs.overflowY !== "visible";
  const EPS = 1;
  for (const el of document.querySelectorAll(BOXES)) {
    if (!inScope(el) || !shown(el)) continue;
    const r = el.getBoundingClientRect();
    // inside every ancestor that clips it: a scrolling one by its content, others by their box
    let inScroller = false;
    for (let p = el.parentElement; p && p !== document.body; p = p.parentElement) {
      const cs = getComputedStyle(p);
      if (!clips(cs)) continue;
      const b = p.getBoundingClientRect();
      if (scrolls(cs)) {
        inScroller = true;
        const top = b.top - p.scrollTop;
        const left = b.left - p.scrollLeft;
        if (r.left < left - EPS || r.right > left + p.scrollWidth + EPS
            || r.top < top - EPS || r.bottom > top + p.scrollHeight + EPS) {
          problems.push(`${name(el)} outside its scrolling ${name(p)}`);
        }
        if (p.scrollWidth > p.clientWidth + EPS && cs.overflowX !== "scroll") {
          problems.push(`${name(p)} scrolls sideways (${p.scrollWidth} > ${p.clientWidth})`);
        }
      } else if (r.left < b.left - EPS || r.right > b.right + EPS
                 || r.top < b.top - EPS || r.bottom > b.bottom + EPS) {
        problems.push(`${name(el)} cut by ${name(p)}`);
      }
    }
    if (r.left < -EPS || r.right > vw + EPS) problems.push(`${name(el)} outside the window sideways`);
    // the page itself may scroll (a tablet); test_layout checks it does not on a desktop
    const pageBottom = Math.max(vh, document.documentElement.scrollHeight) - window.scrollY;
    if (!inScroller && (r.top < -window.scrollY - EPS || r.bottom > pageBottom + EPS)) {
      problems.push(`${name(el)} below the page`);
    }
    if (el.tagName === "BUTTON" && el.scrollWidth > el.clientWidth + EPS) problems.push(`${name(el)} label cut`);
  }
  // a label cut: text in a box that hides what overflows it (…), wider than the box; a
  // select by its shown option, an input by its value
  const measure = document.createElement("span");
  measure.style.cssText = "position:absolute;visibility:hidden;white-space:pre;left:-9999px;top:0";
  document.body.append(measure);
  const textWidth = (text, cs) => {
    measure.style.font = cs.font;
    measure.style.letterSpacing = cs.letterSpacing;
    measure.style.textTransform = cs.textTransform;
    measure.textContent = text;
    return measure.getBoundingClientRect().width;
  };
  const ownText = (el) => [...el.childNodes].some((n) => n.nodeType === Node.TEXT_NODE && n.textContent.trim());
  for (const el of document.querySelectorAll("#topbar *, #layout *, #alerts *, .overlay *")) {
    if (!inScope(el) || !shown(el)
        || el.closest("#log, .leaflet-pane, .leaflet-control-attribution, iframe")) continue;
    const cs = getComputedStyle(el);
    let cut = false;
    let text = el.textContent.trim();
    if (el.tagName === "SELECT") {
      const option = el.options[el.selectedIndex];
      text = option ? option.textContent : "";
      const room = el.clientWidth - parseFloat(cs.paddingLeft) - parseFloat(cs.paddingRight) - 18;
      cut = Boolean(text) && textWidth(text, cs) > room + EPS;
    } else if (el.tagName === "INPUT" && /^(text|number|search|)$/.test(el.type)) {
      text = el.value;
      cut = el.scrollWidth > el.clientWidth + EPS;
    } else if (ownText(el) && (/(hidden|clip)/.test(cs.overflowX) || cs.textOverflow === "ellipsis")) {
      cut = el.scrollWidth > el.clientWidth + EPS;
    }
    if (cut) problems.push(`${name(el)} label cut: "${text.slice(0, 40)}"`);
  }
  measure.remove();
  // a disabled control says why: its tooltip, or the line it is described by
  for (const el of document.querySelectorAll("button, input, select, textarea")) {
    if (!el.disabled || !inScope(el) || !shown(el)) continue;
    const line = (el.getAttribute("aria-describedby") || "").split(/\s+/)
      .map((id) => document.getElementById(id)).filter((d) => d && shown(d))
      .map((d) => d.textContent.trim()).join(" ");
    if (!(el.title || "").trim() && !line) problems.push(`${name(el)} disabled without a reason`);
  }
  const controls = [...document.querySelectorAll(CONTROLS)].filter((el) => inScope(el) && shown(el));
  for (let i = 0; i < controls.length; i++) {
    for (let j = i + 1; j < controls.length; j++) {
      const a = controls[i], b = controls[j];
      if (a.contains(b) || b.contains(a)) continue;
      const ra = a.getBoundingClientRect(), rb = b.getBoundingClientRect();
      const w = Math.min(ra.right, rb.right) - Math.max(ra.left, rb.left);
      const h = Math.min(ra.bottom, rb.bottom) - Math.max(ra.top, rb.top);
      if (w > EPS && h > EPS) problems.push(`${name(a)} overlaps ${name(b)}`);
    }
  }
  // the top bar is one row: every slot inside it, none pushed out of its end
  const bar = document.getElementById("topbar").getBoundingClientRect();
  const topbar = document.getElementById("topbar");
  if (topbar.scrollWidth > topbar.clientWidth + EPS) problems.push(`#topbar overflows (${topbar.scrollWidth} > ${topbar.clientWidth})`);
  for (const slot of topbar.children) {
    if (!shown(slot)) continue;
    const r = slot.getBoundingClientRect();
    if (r.top < bar.top - EPS || r.bottom > bar.bottom + EPS || r.right > bar.right + EPS) {
      problems.push(`${name(slot)} off the top bar's row`);
    }
  }
  // the alert area never covers the views (the map with its north arrow, the 3D scene)
  const views = document.querySelector(".views-panel").getBoundingClientRect();
  for (const alert of document.querySelectorAll("#alerts > *")) {
    if (!inScope(alert) || !shown(alert)) continue;
    const r = alert.getBoundingClientRect();
    if (Math.min(r.right, views.right) - Math.max(r.left, views.left) > EPS
        && Math.min(r.bottom, views.bottom) - Math.max(r.top, views.top) > EPS) {
      problems.push(`${name(alert)} covers the views`);
    }
  }
  // in sight without scrolling: inside the window and inside every ancestor's visible box
  const unreachable = [];
  for (const id of options.reach || []) {
    const el = document.getElementById(id);
    if (!el || !shown(el)) { unreachable.push(`#${id} not shown`); continue; }
    const r = el.getBoundingClientRect();
    let inSight = r.top >= -EPS && r.left >= -EPS && r.bottom <= vh + EPS && r.right <= vw + EPS;
    for (let p = el.parentElement; inSight && p && p !== document.body; p = p.parentElement) {
      if (!clips(getComputedStyle(p))) continue;
      const b = p.getBoundingClientRect();
      inSight = r.top >= b.top - EPS && r.bottom <= b.bottom + EPS;
    }
    if (!inSight) unreachable.push(`#${id} needs scrolling (${Math.round(r.top)}..${Math.round(r.bottom)} of ${vh})`);
  }
  const boxes = {};
  for (const id of options.boxes || []) {
    const el = document.getElementById(id);
    const r = el && shown(el) ? el.getBoundingClientRect() : null;
    boxes[id] = r && [r.x + window.scrollX, r.y + window.scrollY, r.width, r.height].map(Math.round);
  }
  const pageScrolls = document.documentElement.scrollHeight > vh + EPS;
  return { problems, controls: controls.length, pageScrolls, unreachable, boxes };
}
