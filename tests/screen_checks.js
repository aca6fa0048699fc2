// What tests/test_web_screens.py asks of every screen, run inside the page.
// Returns {overflow, small, unlabelled}: lists of short descriptions, empty when the screen is fine.
return (function () {
  const MIN = 44;                                   // CSS px, both ways (issue 21: touch and accessibility)
  const visible = (el) => {
    const r = el.getBoundingClientRect(), cs = getComputedStyle(el);
    return r.width > 0 && r.height > 0 && cs.visibility !== "hidden" && cs.display !== "none";
  };
  const describe = (el) => {
    const t = (el.getAttribute("aria-label") || el.textContent || el.name || el.id || "").trim().replace(/\s+/g, " ");
    return el.tagName.toLowerCase() + (el.id ? "#" + el.id : "") + (t ? ' "' + t.slice(0, 40) + '"' : "");
  };
  // A link inside a sentence is exempt from the size rule (WCAG 2.5.8's "inline" exception):
  // its paragraph or list item holds text of its own besides the link.
  const inline = (a) => {
    const p = a.closest("p, li, td, dd, figcaption, summary");
    if (!p || a.classList.contains("button")) return false;
    const own = Array.from(p.childNodes).filter((n) => n !== a && !(n.contains && n.contains(a)))
      .map((n) => n.textContent).join("").trim();
    return own.length > 0;
  };
  // the element a finger really hits: a checkbox or radio is hit through its label
  const target = (el) => {
    if (el.matches("input[type=checkbox], input[type=radio]")) return el.closest("label") || el;
    return el;
  };
  const controls = Array.from(document.querySelectorAll(
    "a[href], button, input:not([type=hidden]), select, textarea, summary, [role=button], [tabindex]:not([tabindex='-1'])"))
    .filter(visible);
  const small = [], unlabelled = [];
  controls.forEach((el) => {
    const r = target(el).getBoundingClientRect();
    if ((r.width < MIN - 0.5 || r.height < MIN - 0.5) && !(el.tagName === "A" && inline(el)))
      small.push(describe(el) + " " + Math.round(r.width) + "x" + Math.round(r.height));
    if (el.matches("input, select, textarea")) {
      const labelled = el.labels && el.labels.length && Array.from(el.labels).some((l) => l.textContent.trim())
        || el.getAttribute("aria-label") || el.getAttribute("aria-labelledby") || el.getAttribute("title");
      if (!labelled) unlabelled.push(describe(el));
    } else if (el.matches("button, a, summary, [role=button]")) {
      if (!(el.textContent.trim() || el.getAttribute("aria-label") || el.getAttribute("aria-labelledby")
            || el.getAttribute("title") || el.querySelector("img[alt]:not([alt=''])")))
        unlabelled.push(describe(el));
    }
  });
  const sw = document.documentElement.scrollWidth, iw = window.innerWidth;
  const overflow = sw > iw ? ["page is " + sw + " px wide in a " + iw + " px window"] : [];
  // the nav scrolls sideways rather than widen the page: what it hides is as lost as a wide page
  document.querySelectorAll("nav").forEach((nav) => {
    if (nav.scrollWidth > nav.clientWidth + 0.5)
      overflow.push("the nav hides " + (nav.scrollWidth - nav.clientWidth) + " px of its links");
  });
  return { overflow: overflow, small: small, unlabelled: unlabelled };
})();
