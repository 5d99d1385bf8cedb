// Boxes of every visible control and panel, checked in the page: returns what is wrong
// (test_layout.py evaluates this function).
() => {
  const CONTROLS = "button, input, select, textarea, a[href], iframe, [role=button]";
  const BOXES = CONTROLS + ", .panel, .view, .leaflet-control";
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
    if (!shown(el)) continue;
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
  const controls = [...document.querySelectorAll(CONTROLS)].filter(shown);
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
  const pageScrolls = document.documentElement.scrollHeight > vh + EPS;
  return { problems, controls: controls.length, pageScrolls };
}
