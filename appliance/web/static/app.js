// InkSlice pages: every action goes through the JSON API with the session's CSRF token.
"use strict";
(function () {
  const $ = (s) => document.querySelector(s);
  const csrf = () => (document.querySelector('meta[name="csrf-token"]') || {}).content || "";
  const ACTIVE = ["homing", "scanning", "processing"];

  async function api(method, url, body) {
    const opts = { method, headers: { "X-CSRF-Token": csrf() }, credentials: "same-origin" };
    if (body instanceof FormData) opts.body = body;
    else if (body !== undefined) { opts.body = JSON.stringify(body); opts.headers["Content-Type"] = "application/json"; }
    const r = await fetch(url, opts);
    let data = null;
    try { data = await r.json(); } catch (e) { data = null; }
    if (r.status === 401) { location.href = "/login?next=" + encodeURIComponent(location.pathname); }
    if (!r.ok) {
      const msg = data && data.error ? (data.where ? data.where + ": " : "") + data.error : r.status + " " + r.statusText;
      throw new Error(msg);
    }
    return data;
  }
  function show(el, on) { if (el) el.classList.toggle("hidden", !on); }
  function text(sel, t) { const e = $(sel); if (e) e.textContent = t; }
  // a form's named fields as the API takes them: by data-kind int, number or bool, else the text
  function formValues(form) {
    const values = {};
    form.querySelectorAll("[name]").forEach((el) => {
      const kind = el.dataset.kind;
      values[el.name] = kind === "int" ? parseInt(el.value, 10) : kind === "number" ? Number(el.value)
        : kind === "bool" ? el.checked : el.value;
    });
    return values;
  }
  function fmtEta(s) {
    if (s === null || s === undefined) return "";
    s = Math.max(0, Math.round(s));
    const m = Math.floor(s / 60), r = s % 60;
    return "about " + (m ? m + " min " + String(r).padStart(2, "0") + " s" : r + " s") + " left";
  }

  // ---------------------------------------------------------------- dashboard
  function dashboard() {
    const btn = $("#startstop"), img = $("#frame");
    let current = null, frameSeq = 0, mapBusy = false, lastMapKey = "";

    function render(st) {
      current = st;
      document.dispatchEvent(new CustomEvent("inkslice:state", { detail: st }));   // static/notify.js
      const s = st.state || "unknown";
      const badge = $("#state");
      badge.textContent = s; badge.className = "badge s-" + s;
      text("#message", st.message || "");
      // the bench's own news (the button's USB copy): shown for its first ten minutes
      const n = st.notice, nb = $("#notice");
      if (nb) {
        const fresh = n && n.text && (!n.age_s || n.age_s < 600);
        text("#notice", fresh ? "Bench: " + n.text : "");
        nb.className = "small " + (fresh ? (n.ok ? "ok" : "error") : "hidden");
      }
      const active = ACTIVE.includes(s);
      btn.disabled = false;
      if (!armed) {
        // processing cannot be "stopped" into a scan: say what a tap really does then
        btn.textContent = !active ? "Start scan…" : (s === "processing" ? "Cancel processing" : "Stop scan");
        btn.className = "big " + (active ? "stop" : "start");
      }
      if (active) show($("#confirm"), false);
      show($("#scan-setup"), !active);
      machine(st, active);
      const total = st.levels_total || 0, done = st.levels_done || 0;
      const p = $("#progress"); p.max = Math.max(1, total); p.value = done;
      text("#levels", done + " / " + total + " levels");
      text("#level", st.level_mm !== null && st.level_mm !== undefined ? "level " + Number(st.level_mm).toFixed(2) + " mm" : "");
      text("#eta", active ? etaText(s, st.eta_display_s) : (s === "done" ? "finished" : ""));
      const link = $("#job-link");
      if (st.job_id) { link.querySelector("a").href = "/jobs/" + encodeURIComponent(st.job_id); link.querySelector("a").textContent = (s === "done" ? "Open the report of " : "Job ") + st.job_id; }
      show(link, !!st.job_id);
      const hw = $("#hardware"); hw.innerHTML = "";
      Object.entries(st.hardware || {}).forEach(([k, v]) => {
        const li = document.createElement("li");
        li.textContent = k + ": " + v;
        li.className = v === "ok" ? "ok" : (String(v).startsWith("fault") ? "fault" : "missing");
        hw.appendChild(li);
      });
      const key = st.job_id + ":" + done;
      if (key !== lastMapKey) { lastMapKey = key; drawLiveMap(); }
    }
    function refreshFrame() {
      // A new object URL per frame: the <img> shows the camera only via an authenticated fetch.
      fetch("/api/frame.jpg?n=" + (frameSeq++), { credentials: "same-origin" }).then((r) => {
        if (!r.ok || r.status === 204) return null;
        text("#frame-meta", r.headers.get("X-Level-mm") ? "level " + Number(r.headers.get("X-Level-mm")).toFixed(2) + " mm, waterline in red" : "");
        return r.blob();
      }).then((b) => {
        if (!b) return;
        const old = img.src; img.src = URL.createObjectURL(b);
        if (old && old.startsWith("blob:")) URL.revokeObjectURL(old);
        show(img, true); show($("#noframe"), false);
      }).catch(() => {});
    }
    async function drawLiveMap() {
      if (mapBusy) return; mapBusy = true;
      try {
        const r = await fetch("/api/heightmap/live", { credentials: "same-origin" });
        if (!r.ok || r.status === 204) return;
        const hm = await r.json();
        const c = $("#livemap"), ctx = c.getContext("2d");
        const ny = hm.z.length, nx = ny ? hm.z[0].length : 0;
        let lo = Infinity, hi = -Infinity;
        hm.z.forEach((row) => row.forEach((v) => { if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); } }));
        ctx.fillStyle = "#0d1b2a"; ctx.fillRect(0, 0, c.width, c.height);
        if (!nx || lo === Infinity) return;
        const cw = c.width / nx, ch = c.height / ny;
        for (let j = 0; j < ny; j++) for (let i = 0; i < nx; i++) {
          const v = hm.z[j][i]; if (v === null) continue;
          const t = hi > lo ? (v - lo) / (hi - lo) : 1;
          ctx.fillStyle = "hsl(" + (240 - 200 * t) + ",75%," + (35 + 30 * t) + "%)";
          ctx.fillRect(i * cw, c.height - (j + 1) * ch, Math.ceil(cw), Math.ceil(ch));
        }
        text("#livemap-note", "Heights " + lo.toFixed(1) + " to " + hi.toFixed(1) + " mm (blue low, yellow high).");
      } finally { mapBusy = false; }
    }
    // Start is confirmed (a dialog naming the scan); Stop needs a second tap within 3 s. So a
    // double tap can neither start and cancel a scan, nor cancel one by accident.
    let armed = null;
    function etaText(s, eta) {
      if (eta === null || eta === undefined) return s === "processing" ? "processing" : "";
      if (s === "processing") return eta < 1 ? "finishing the program…" : "processing, " + fmtEta(eta);
      return fmtEta(eta) + " (scan and processing)";
    }
    function scanParams() {
      const p = {}, name = $("#scan-name").value.trim();
      if (name) p.name = name;
      const step = Number($("#scan-step").value);
      if (step > 0) p.level_step_mm = step;
      if (!$("#range-auto").checked) { p.levels_to_mm = Number($("#range-to").value); p.levels_from_mm = Number($("#range-from").value); }
      return p;
    }
    function describeScan(p) {
      const range = p.levels_to_mm !== undefined ? "levels " + p.levels_to_mm + " down to " + p.levels_from_mm + " mm"
                                                 : "automatic range";
      return "Start scanning " + (p.name ? "“" + p.name + "”" : "an unnamed part") + ": " + range + ", step " +
        (p.level_step_mm || "as set") + " mm? The stage homes first.";
    }
    $("#range-auto").addEventListener("change", () => {
      show($("#range-manual"), !$("#range-auto").checked); show($("#range-auto-text"), $("#range-auto").checked);
    });
    $("#scan-setup").addEventListener("submit", (ev) => { ev.preventDefault(); btn.click(); });
    $("#confirm-back").addEventListener("click", () => { show($("#confirm"), false); btn.focus(); });
    $("#confirm-start").addEventListener("click", () => act(() => api("POST", "/api/scan", scanParams())));
    btn.addEventListener("click", () => {
      const active = current && ACTIVE.includes(current.state);
      if (!active) {
        text("#confirm-text", describeScan(scanParams())); show($("#confirm"), true);
        $("#confirm-start").focus(); return;
      }
      if (!armed) {
        btn.textContent = "Tap again to " + (current.state === "processing" ? "cancel processing" : "stop the scan");
        armed = setTimeout(() => { armed = null; if (current) render(current); }, 3000);
        return;
      }
      clearTimeout(armed); armed = null;
      act(() => api("POST", "/api/scan/cancel"));
    });
    async function act(call) {
      btn.disabled = true; show($("#action-error"), false); show($("#action-fix"), false); show($("#confirm"), false);
      try {
        await call();
      } catch (e) {
        text("#action-error", e.message); show($("#action-error"), true);
        // a commissioning step or the guided calibration holds the bench: the way out is one tap away
        const held = /commissioning step/.test(e.message) ? "/commission" : (/guided calibration/.test(e.message) ? "/calibration" : null);
        if (held) { $("#action-fix a").href = held; show($("#action-fix"), true); }
      }
      poll();
    }
    async function poll() { try { render(await api("GET", "/api/state")); } catch (e) {} }

    // -- the machine panel: a live preview (the light on) while the page is open and the bench is idle
    let previewBusy = false, panelRefused = false;
    const hasMachine = !!$("#home");
    function machine(st, active) {
      if (!hasMachine) return;
      const m = st.manual || {};
      document.querySelectorAll("#machine button, #goto-level").forEach((b) => { b.disabled = active; });
      show($("#machine .jog"), !active); show($("#goto-form"), !active);   // the scan has the stage: no dead buttons
      text("#machine-status", active ? "The stage is the scan's until it ends." :
        (m.open ? "Light on, live preview. " + (m.homed ? "Ink level " + Number(m.level_mm).toFixed(2) + " mm above the base."
                                                          : "Home the stage to move it.")
                : "Light off."));
      if (!active) panelRefused = false;
    }
    async function preview() {
      if (!hasMachine || previewBusy || panelRefused || document.hidden || (current && ACTIVE.includes(current.state))) return;
      previewBusy = true;
      try { await api("POST", "/api/machine/preview"); refreshFrame(); }
      catch (e) { panelRefused = true; }
      finally { previewBusy = false; }
    }
    async function move(call) {
      show($("#machine-error"), false);
      document.querySelectorAll("#machine button").forEach((b) => { b.disabled = true; });
      try { await call(); refreshFrame(); }
      catch (e) { text("#machine-error", e.message); show($("#machine-error"), true); }
      poll();
    }
    if (hasMachine) $("#home").addEventListener("click", () => move(() => api("POST", "/api/machine/home")));
    document.querySelectorAll(".jogb").forEach((b) => b.addEventListener("click",
      () => move(() => api("POST", "/api/machine/jog", { mm: Number(b.dataset.mm) }))));
    if (hasMachine) $("#goto-form").addEventListener("submit", (ev) => {
      ev.preventDefault(); move(() => api("POST", "/api/machine/goto", { level_mm: Number($("#goto-level").value) }));
    });
    setInterval(preview, 3000);
    document.addEventListener("visibilitychange", preview);

    // Live updates: Server-Sent Events; if the stream breaks, poll every 2 s until it is back.
    let fallback = null;
    function startPolling() { if (!fallback) fallback = setInterval(() => { poll(); refreshFrame(); }, 2000); }
    if (window.EventSource) {
      const es = new EventSource("/api/events");
      es.addEventListener("state", (ev) => render(JSON.parse(ev.data)));
      es.addEventListener("frame", () => refreshFrame());
      es.onopen = () => { if (fallback) { clearInterval(fallback); fallback = null; } };
      es.onerror = () => startPolling();
    } else startPolling();
    // A safety net under the stream: the state read every 10 s, and at once when the tab is shown
    // again, so a stream that stalls without an error (a phone that slept, a buffering proxy)
    // cannot leave the page showing a scan that has ended.
    setInterval(() => { if (!fallback && !document.hidden) poll(); }, 10000);
    document.addEventListener("visibilitychange", () => { if (!document.hidden) poll(); });
    poll().then(preview); refreshFrame();
  }

  // ---------------------------------------------------------------- jobs
  function jobs() {
    const f = $("#upload-form");
    if (!f) return;
    f.addEventListener("submit", async (ev) => {
      ev.preventDefault();
      text("#upload-result", "Uploading…");
      try { const r = await api("POST", "/api/uploads/scan", new FormData(f)); location.href = "/jobs/" + r.job_id; }
      catch (e) { text("#upload-result", "Refused: " + e.message); }
    });
  }

  // ---------------------------------------------------------------- job
  function job() {
    const id = $("#job").dataset.job;
    const jobUrl = "/api/jobs/" + encodeURIComponent(id);
    // live until done: a running job's page reloads itself when the job ends
    if (ACTIVE.includes($("#job").dataset.status)) {
      const tick = setInterval(async () => {
        try {
          const j = await api("GET", jobUrl);
          if (!ACTIVE.includes(j.status)) { clearInterval(tick); location.reload(); }
          else { const b = $("#job-status"); b.textContent = j.status; b.className = "badge s-" + j.status; }
        } catch (e) {}
      }, 2000);
    }
    const say = (t) => text("#manage-result", t);
    const rename = $("#rename-form");
    if (rename) rename.addEventListener("submit", async (ev) => {
      ev.preventDefault();
      try { const j = await api("PATCH", jobUrl, { name: $("#rename-name").value }); text("#job-name", j.name); say("Renamed."); }
      catch (e) { say("Not renamed: " + e.message); }
    });
    const rep = $("#reprocess-form");
    if (rep) rep.addEventListener("submit", async (ev) => {
      ev.preventDefault();
      try { await api("POST", jobUrl + "/reprocess", { settings: formValues(rep) }); location.reload(); }
      catch (e) { say("Not started: " + e.message); }
    });
    const post = $("#repost-form");
    if (post) post.addEventListener("submit", async (ev) => {
      ev.preventDefault();
      const options = formValues(post);
      const go = $("#repost-go"); go.disabled = true; text("#repost-result", "Making the program…");
      try { const r = await api("POST", jobUrl + "/post", options); text("#repost-result", "Written: " + r.files.filter((f) => f.endsWith(".nc")).join(", ")); location.reload(); }
      catch (e) { text("#repost-result", "Not made: " + e.message); go.disabled = false; }
    });
    const del = $("#delete");
    if (del) {
      del.addEventListener("click", () => { show($("#delete-confirm"), true); show(del, false); $("#delete-no").focus(); });
      $("#delete-no").addEventListener("click", () => { show($("#delete-confirm"), false); show(del, true); del.focus(); });
      $("#delete-yes").addEventListener("click", async () => {
        try { await api("DELETE", jobUrl); location.href = "/jobs"; }
        catch (e) { say("Not deleted: " + e.message); }
      });
    }
    const resume = $("#resume");
    if (resume) resume.addEventListener("click", async () => {
      try { await api("POST", "/api/jobs/" + encodeURIComponent(id) + "/resume"); location.href = "/"; }
      catch (e) { alert(e.message); }
    });
    const usb = $("#usb");
    if (usb) {
      let sticks = [], told = false;       // told: a copy's outcome stays up after its stick is unmounted
      async function check() {
        try {
          const r = await api("GET", "/api/usb");
          sticks = r.sticks;
          show(usb, r.available || told);
          show($("#usb-copy"), r.available); // the button exists only while a stick is there
          text("#usb-stick", r.available ? "Stick: " + (sticks[0].label || sticks[0].mount) + " (" + Math.round(sticks[0].free_bytes / 1e6) + " MB free)" : "No stick mounted: plug one in to copy.");
        } catch (e) {}
      }
      check(); setInterval(check, 3000);
      $("#usb-copy").addEventListener("click", async () => {
        const b = $("#usb-copy"); b.disabled = true; text("#usb-result", "Copying and verifying…");
        try {
          const r = await api("POST", "/api/jobs/" + encodeURIComponent(id) + "/usb", { file: $("#usb-file").value, stick: sticks.length ? sticks[0].id : null });
          text("#usb-result", "Copied " + r.name + " (" + r.bytes + " bytes, SHA-256 verified). " +
            (r.safe_to_remove ? "The stick is unmounted: safe to remove it."
                              : "Synced, but the stick could not be unmounted (" + r.unmount_problem + "): wait until it is idle before removing it."));
          told = true; check();
        } catch (e) { text("#usb-result", "Not copied: " + e.message); }
        b.disabled = false;
      });
    }
  }

  // ---------------------------------------------------------------- settings
  function settings() {
    // the settings themselves: static/settings.js
    $("#password-form").addEventListener("submit", async (ev) => {
      ev.preventDefault();
      const fd = new FormData(ev.target);
      try { await api("POST", "/api/password", { current: fd.get("current"), new: fd.get("new") }); text("#password-result", "Password changed; other sessions are logged out."); ev.target.reset(); }
      catch (e) { text("#password-result", "Not changed: " + e.message); }
    });
    $("#token-form").addEventListener("submit", async (ev) => {
      ev.preventDefault();
      try { const r = await api("POST", "/api/tokens", { name: new FormData(ev.target).get("name") }); text("#token-result", "New token (copy it now, it is not shown again): " + r.token); }
      catch (e) { text("#token-result", e.message); }
    });
    document.querySelectorAll("button.revoke").forEach((b) => b.addEventListener("click", async () => {
      try { await api("DELETE", "/api/tokens/" + b.dataset.id); b.parentElement.remove(); } catch (e) { alert(e.message); }
    }));
  }

  // ---------------------------------------------------------------- calibration
  function calibration() {
    const list = $("#cal-steps");
    if (!list) return;
    const doBtn = $("#cal-do"), cancelBtn = $("#cal-cancel");
    function render(c) {
      list.innerHTML = "";
      c.steps.forEach((s, i) => {
        const li = document.createElement("li");
        li.textContent = s.text; li.className = i === c.step ? "now" : (i < c.step ? "done" : "");
        list.appendChild(li);
      });
      doBtn.textContent = "Do step " + (c.step + 1) + ": " + c.steps[c.step].id;
      doBtn.dataset.step = c.steps[c.step].id;
      // Cancel is there at every step: it stops the stage and gives the bench back for scans.
      cancelBtn.disabled = !c.holds_bench && c.step === 0;
      text("#cal-hold", c.holds_bench ? "The calibration holds the bench: scans wait until you finish or cancel it." : "The bench is free for scans.");
      text("#cal-detected", c.detected ? "Detected: " + Object.entries(c.detected).map(([k, v]) => k + " " + v).join(", ") : "");
    }
    function frame() {
      fetch("/api/frame.jpg?c=" + Date.now(), { credentials: "same-origin" }).then((r) => r.status === 200 ? r.blob() : null).then((b) => {
        if (!b) return; const img = $("#cal-frame"); img.src = URL.createObjectURL(b); show(img, true); show($("#cal-noframe"), false);
      });
    }
    doBtn.addEventListener("click", async () => {
      doBtn.disabled = true; text("#cal-result", "Working on " + doBtn.dataset.step + "…");
      try { render(await api("POST", "/api/calibration/" + doBtn.dataset.step)); text("#cal-result", "Done."); frame(); }
      catch (e) { text("#cal-result", e.message + " (retry the step, or cancel)"); api("GET", "/api/calibration").then(render); }
      doBtn.disabled = false;
    });
    cancelBtn.addEventListener("click", async () => {
      // not disabled while a step runs: cancelling is how a long homing is stopped
      text("#cal-result", "Cancelling…");
      try { render(await api("POST", "/api/calibration/cancel")); text("#cal-result", "Calibration cancelled; nothing was stored. The bench takes scans again."); }
      catch (e) { text("#cal-result", "Not cancelled: " + e.message); }
    });
    api("GET", "/api/calibration").then(render); frame();
  }

  // ---------------------------------------------------------------- API docs
  function apidocs() {
    fetch("/api/openapi.json").then((r) => r.json()).then((doc) => {
      const box = $("#api-list");
      Object.entries(doc.paths).forEach(([path, ops]) => Object.entries(ops).forEach(([m, op]) => {
        const d = document.createElement("div"); d.className = "api-op";
        const c = document.createElement("code"); c.className = "m-" + m; c.textContent = m.toUpperCase() + " /api" + path;
        const p = document.createElement("div"); p.className = "small"; p.textContent = op.summary + (op.description ? " — " + op.description : "");
        d.appendChild(c); d.appendChild(p); box.appendChild(d);
      }));
    });
  }

  window.InkSlice = { api, show, text };      // for the page scripts of their own (commission.js)
  const pages = { dashboard, jobs, job, settings, calibration, api: apidocs };
  const init = pages[document.body.dataset.page];
  if (init) init();
})();
