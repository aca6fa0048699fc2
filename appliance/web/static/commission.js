// The commissioning page: a guided sequence over GET/POST /api/commissioning (docs/api/README.md).
// The daemon says which actions each step allows now; this script only lays them out for a thumb.
"use strict";
(function () {
  if (document.body.dataset.page !== "commission") return;
  const { api, show, text } = window.InkSlice;
  const $ = (s) => document.querySelector(s);
  const ORDER = ["level_zero", "camera", "tank", "meniscus"];
  const ACTION = {
    start: "Start", measure: "Measure level zero", accept: "Accept and store",
    view: "Take a tilted view", plane: "Measure the flat board", scan: "Scan the ball",
  };
  const STATUS = { done: "done", stale: "out of date: the ink changed since", skipped: "skipped", missing: "not done yet" };
  // what an idle step asks before it starts; the daemon checks the values again
  const FORMS = {
    level_zero: [{ name: "level_at_home_mm", label: "Or enter it: stage position where the base top meets the ink (mm)", action: "enter", button: "Save this level zero" }],
    tank: [{ name: "width_mm", label: "Tank inside width (mm)", value: 150 },
           { name: "depth_mm", label: "Tank inside depth (mm)", value: 150, action: "enter", button: "Save the tank area" },
           { name: "level_held", label: "An overflow holds the ink's level (it does not fall as a part comes out)", type: "checkbox" }],
    meniscus: [{ name: "diameter_mm", label: "Reference ball diameter (mm)", value: 25.4, action: "start", button: "Start: the ball goes on the base" }],
  };
  const HELP = {
    level_zero: "Where the empty base's top meets the ink. The stage homes, then raises the base until the camera sees its top break the surface.",
    camera: "The lens, from a few views of the printed board held tilted, then the liquid plane from the board lying flat on the base.",
    tank: "The ink's area, to correct the level for the ink a part displaces.",
    meniscus: "How the ink climbs a part, from a scan of a precision ball of known diameter.",
  };
  let cm = null, focus = null, busy = false, frameSeq = 0, poller = null, refused = "";
  // counts cancels and skips: an action's answer that arrives after one (the stopped
  // measurement's error, say) is about a step already left, and must not undo what it showed
  let leaves = 0;

  const num = (v, d) => (typeof v === "number" ? v.toFixed(d) : String(v));
  function summary(step) {
    const r = step.result || {};
    if (step.summary) return step.summary;
    if (!step.result) return "";
    if (step.id === "level_zero") return "base top meets the ink at stage position " + num(r.level_at_home_mm, 3) + " mm";
    if (step.id === "tank") return r.figure || num(r.area_mm2, 0) + " mm²";
    if (step.id === "camera") return num(r.mm_per_px, 4) + " mm per pixel, plane RMS " + num(r.plane_rms_mm, 3) + " mm, lens " + (r.lens || "none");
    if (step.id === "meniscus") return "capillary length " + num(r.capillary_length_mm, 2) + " mm, contact angle " + num(r.contact_angle_deg, 1) + "°";
    return "";
  }
  function referenceLine(step) {
    const ref = step && step.result && step.result.reference;
    if (!ref || typeof ref.mean_abs_error_mm !== "number") return "";
    return "This box measures the " + ref.diameter_mm + " mm ball to " + ref.mean_abs_error_mm.toFixed(2) + " mm" +
      (typeof ref.max_error_mm === "number" ? " (largest error " + ref.max_error_mm.toFixed(2) + " mm)" : "") +
      (step.date_text ? ", measured " + step.date_text : "") + "." +
      (step.status === "stale" ? " The ink was changed since: scan the ball again." : "");
  }
  const stepOf = (id) => cm.steps.find((s) => s.id === id);
  const title = (id) => (stepOf(id) || { title: id }).title;

  // ------------------------------------------------------------------ the results
  function renderResults() {
    const ol = $("#cm-results"); ol.innerHTML = "";
    cm.steps.forEach((s, i) => {
      const li = document.createElement("li");
      li.className = "cm-result st-" + s.status;
      const head = document.createElement("div"); head.className = "cm-result-head";
      const h = document.createElement("strong"); h.textContent = (i + 1) + ". " + s.title;
      const badge = document.createElement("span"); badge.className = "badge b-" + s.status; badge.textContent = s.status === "stale" ? "out of date" : (s.status === "missing" ? "not done" : s.status);
      head.append(h, badge);
      const p = document.createElement("p"); p.className = "small";
      p.textContent = s.status === "missing" || s.status === "skipped" ? STATUS[s.status] :
        summary(s) + (s.date_text ? " — " + s.date_text : "") + (s.method && s.method !== "measured" ? " (" + s.method + ")" : "") +
        (s.status === "stale" ? " — " + STATUS.stale : "");
      li.append(head, p);
      if (!cm.active && s.id !== focus) {       // the step in hand has its own card; one step at a time
        const b = document.createElement("button"); b.type = "button"; b.className = "cm-goto";
        b.textContent = s.status === "done" ? "Do again" : "Do this step";
        b.setAttribute("aria-label", b.textContent + ": " + s.title);
        b.disabled = busy;
        b.addEventListener("click", () => { focus = s.id; clearNote(); renderStep(); renderResults(); $("#cm-step").scrollIntoView(); });
        li.appendChild(b);
      }
      ol.appendChild(li);
    });
    const ref = referenceLine(stepOf("meniscus"));
    text("#cm-reference", ref); show($("#cm-reference"), !!ref);
    text("#cm-ink", cm.ink_changed_text ? "Ink last changed " + cm.ink_changed_text + "." : "No ink change recorded.");
  }

  // ------------------------------------------------------------------ the step in hand
  function nextStep() {
    const open = cm.steps.find((s) => s.status === "missing" || s.status === "stale");
    return open ? open.id : null;
  }
  function button(label, onClick, cls) {
    const b = document.createElement("button"); b.type = "button"; b.textContent = label;
    if (cls) b.className = cls;
    b.addEventListener("click", onClick);
    return b;
  }
  function field(f) {
    const l = document.createElement("label"); l.textContent = f.label;
    const inp = document.createElement("input");
    inp.name = f.name; inp.id = "cm-in-" + f.name;
    const s = stepOf(focus);
    if (f.type === "checkbox") {   // a yes / no the step's result remembers (level_held: the ink does not fall)
      inp.type = "checkbox"; l.className = "check";
      inp.checked = !!(s && s.result && s.result.surface_falls === false);
      l.prepend(inp);
      return l;
    }
    inp.type = "number"; inp.step = "any"; inp.min = "0"; inp.inputMode = "decimal";
    if (f.value !== undefined) inp.value = f.value;
    if (s && s.result && typeof s.result[f.name] === "number") inp.value = s.result[f.name];
    l.appendChild(inp);
    return l;
  }
  function values() {
    const out = {};
    document.querySelectorAll("#cm-inputs input").forEach((i) => {
      if (i.type === "checkbox") out[i.name] = i.checked;
      else if (i.value !== "") out[i.name] = Number(i.value);
    });
    return out;
  }

  function renderStep() {
    const a = cm.active;
    const id = a ? a.step : (focus || nextStep());
    const inputs = $("#cm-inputs"), actions = $("#cm-actions"), starter = $("#cm-start");
    inputs.innerHTML = ""; actions.innerHTML = ""; starter.innerHTML = "";
    show($("#cm-progress"), false);
    if (!id) {
      text("#cm-step-count", "");
      text("#cm-step-title", "This box is commissioned");
      text("#cm-prompt", "Every step has a result or was skipped. Do a step again from the results below, e.g. after the ink was changed.");
      show($("#cm-skip"), false); show($("#cm-cancel"), false); show($("#cm-detected"), false); show($("#cm-error"), false);
      show($("#cm-view"), false);
      return;
    }
    focus = id;
    const s = stepOf(id);
    text("#cm-step-count", "Step " + (ORDER.indexOf(id) + 1) + " of " + ORDER.length + (a ? " · in progress" + (a.holds_bench ? ", holding the bench" : "") : ""));
    text("#cm-step-title", s.title);
    const scanning = a && a.stage === "scanning";
    text("#cm-prompt", scanning ? "The bench is scanning the ball, then fits the meniscus to it: a few minutes. Cancel stops the scan." :
      (a && a.prompt ? a.prompt : HELP[id]));
    const allowed = a ? a.actions : s.actions;
    if (!a) {
      const form = FORMS[id] || [];
      const bare = allowed.includes("start") && !form.some((f) => f.action === "start");   // starts without values
      if (bare) starter.appendChild(button(id === "level_zero" ? "Start: measure it on the bench" : "Start", () => act(id, "start"), "big"));
      form.forEach((f) => inputs.appendChild(field(f)));
      form.filter((f) => f.action && allowed.includes(f.action)).forEach((f) => {
        actions.appendChild(button(f.button, () => act(id, f.action, values()), bare ? "big alt" : "big"));
      });
    } else {
      allowed.filter((x) => x !== "cancel" && x !== "skip").forEach((x) => {
        let label = ACTION[x] || x;
        if (x === "view" && a.detected && a.detected.views) label += " (" + a.detected.views + " taken)";
        if (a.stage === "check" && x !== "accept") label = (x === "scan" ? "Scan the ball again" : label.replace("Measure", "Measure again:"));
        actions.appendChild(button(label, () => act(id, x), x === "accept" || allowed.length <= 3 ? "big" : "big alt"));
      });
      if (a.stage === "scanning") { show($("#cm-progress"), true); watchScan(); }
    }
    renderDetected(a);
    const err = refused || (a && a.error) || "";          // the daemon's refusal of the last action, or the step's own
    text("#cm-error", err); show($("#cm-error"), !!err);
    show($("#cm-skip"), true); show($("#cm-cancel"), true);
    $("#cm-skip").disabled = busy;
    show($("#cm-view"), !!a && (id === "camera" || id === "level_zero"));
    document.querySelectorAll("#cm-actions button, #cm-start button").forEach((b) => { b.disabled = busy; });
  }
  function renderDetected(a) {
    const dl = $("#cm-detected"); dl.innerHTML = "";
    const d = a && a.detected;
    if (!d) { show(dl, false); return; }
    Object.entries(d).forEach(([k, v]) => {
      if (v === null || typeof v === "object") return;
      const dt = document.createElement("dt"); dt.textContent = k.replace(/_/g, " ");
      const dd = document.createElement("dd"); dd.textContent = typeof v === "number" ? String(+v.toFixed(4)) : String(v);
      dl.append(dt, dd);
    });
    if (d.reference && typeof d.reference.mean_abs_error_mm === "number") {
      const dt = document.createElement("dt"); dt.textContent = "reference ball";
      const dd = document.createElement("dd"); dd.textContent = "measured to " + d.reference.mean_abs_error_mm.toFixed(3) + " mm (largest " + num(d.reference.max_error_mm, 3) + " mm)";
      dl.append(dt, dd);
    }
    show(dl, dl.children.length > 0);
  }

  // ------------------------------------------------------------------ acting
  function clearNote() { note(""); refused = ""; }
  function note(t, bad) { text("#cm-note", t); show($("#cm-note"), !!t); $("#cm-note").classList.toggle("bad", !!bad); }
  function render(answer) {
    cm = answer;
    if (!cm.active && focus && stepOf(focus) && stepOf(focus).status !== "missing" && stepOf(focus).status !== "stale" && !busy) {
      // the step just ended (stored or skipped): the sequence goes on with the next open one
      const after = ORDER.slice(ORDER.indexOf(focus) + 1).find((k) => ["missing", "stale"].includes(stepOf(k).status));
      focus = after || nextStep();
    }
    renderResults(); renderStep();
    if (cm.active) frame();
    if (cm.active && !poller) poller = setInterval(refresh, 1500);
    if (!cm.active && poller) { clearInterval(poller); poller = null; }
  }
  async function refresh() { if (!busy) { try { render(await api("GET", "/api/commissioning")); } catch (e) { /* next poll */ } } }
  async function act(step, action, body) {
    const since = leaves;
    busy = true; clearNote();
    text("#cm-busy", "Working: " + (ACTION[action] || action) + "… (Cancel stops it)"); show($("#cm-busy"), true);
    renderStep(); renderResults();
    try {
      const answer = await api("POST", "/api/commissioning/" + step + "/" + action, body || {});
      busy = false;
      if (since === leaves) {
        if (action === "accept" || action === "enter") note(title(step) + " stored.");
        render(answer);
      }
    } catch (e) {
      busy = false;
      if (since === leaves) {
        note("");
        refused = e.message;
        try { render(await api("GET", "/api/commissioning")); } catch (e2) { /* keep the old view */ }
      }
    }
    show($("#cm-busy"), false);
    renderStep(); renderResults();
  }
  async function leave(action) {
    const id = (cm.active && cm.active.step) || focus;
    if (!id) return;
    leaves += 1;
    refused = "";
    try {
      const answer = await api("POST", "/api/commissioning/" + id + "/" + action, {});
      busy = false;
      if (action === "cancel") { focus = id; }
      render(answer);
      if (action === "skip") { focus = ORDER.slice(ORDER.indexOf(id) + 1).find((k) => ["missing", "stale"].includes(stepOf(k).status)) || null; render(answer); }
      note(action === "cancel" ? title(id) + " cancelled; nothing was stored. The bench is free for scans." :
        title(id) + " skipped.");
    } catch (e) { note((action === "cancel" ? "Not cancelled: " : "Not skipped: ") + e.message, true); }
  }
  $("#cm-cancel").addEventListener("click", () => leave("cancel"));
  $("#cm-skip").addEventListener("click", () => leave("skip"));

  // the reference scan's progress, from the bench's state
  async function watchScan() {
    try {
      const st = await api("GET", "/api/state");
      const p = $("#cm-progress"); p.max = Math.max(1, st.levels_total || 0); p.value = st.levels_done || 0;
      text("#cm-busy", "Reference scan: " + (st.levels_done || 0) + " / " + (st.levels_total || 0) + " levels, " + (st.message || st.state));
      show($("#cm-busy"), true);
    } catch (e) { /* next poll */ }
  }
  function frame() {
    fetch("/api/frame.jpg?cm=" + (frameSeq++), { credentials: "same-origin" }).then((r) => (r.status === 200 ? r.blob() : null)).then((b) => {
      if (!b) return;
      const img = $("#cm-frame"), old = img.src;
      img.src = URL.createObjectURL(b); show(img, true); show($("#cm-noframe"), false);
      if (old && old.startsWith("blob:")) URL.revokeObjectURL(old);
    }).catch(() => {});
  }

  // ------------------------------------------------------------------ export, import, ink
  $("#cm-import-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    const f = $("#cm-import-file").files[0];
    if (!f) return;
    let doc;
    try { doc = JSON.parse(await f.text()); } catch (e) { text("#cm-files-note", "Not imported: " + f.name + " is not a JSON file."); return; }
    try { clearNote(); render(await api("POST", "/api/commissioning/import", doc)); text("#cm-files-note", "Imported " + f.name + "; the results keep their dates."); }
    catch (e) { text("#cm-files-note", "Not imported: " + e.message); }
  });
  $("#cm-ink-changed").addEventListener("click", async () => {
    try { clearNote(); render(await api("POST", "/api/commissioning/ink-changed")); focus = nextStep(); renderStep(); text("#cm-files-note", "Ink change recorded: measure the level zero and the meniscus again."); }
    catch (e) { text("#cm-files-note", e.message); }
  });

  api("GET", "/api/commissioning").then(render).catch((e) => { text("#cm-error", e.message); show($("#cm-error"), true); });
})();
