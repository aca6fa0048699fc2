// The system page: uptimes in words, the logs, restore from a backup file, notification permission.
"use strict";
(function () {
  const { api } = window.InkSlice;
  const $ = (s) => document.querySelector(s);

  function duration(s) {
    if (s === "" || s === null || isNaN(Number(s))) return "unknown";
    s = Math.round(Number(s));
    const d = Math.floor(s / 86400), h = Math.floor(s % 86400 / 3600), m = Math.floor(s % 3600 / 60);
    return d ? d + " d " + h + " h" : h ? h + " h " + m + " min" : m ? m + " min" : s + " s";
  }
  document.querySelectorAll("dd[data-s]").forEach((dd) => { dd.textContent = duration(dd.dataset.s); });

  async function showLog() {
    const name = $("#log-name").value;
    $("#log-download").href = "/api/logs/" + name + "?download=1";
    const r = await fetch("/api/logs/" + name, { credentials: "same-origin" });
    const text = r.ok ? await r.text() : "(cannot read it: " + r.status + ")";
    const pre = $("#log-text");
    pre.textContent = text || "(empty: nothing logged to a file yet)";
    pre.scrollTop = pre.scrollHeight;
  }
  $("#log-name").addEventListener("change", showLog);
  showLog();

  $("#restore-file").addEventListener("change", async (ev) => {
    const file = ev.target.files[0];
    if (!file) return;
    const out = $("#restore-result");
    let doc;
    try { doc = JSON.parse(await file.text()); } catch (e) { out.textContent = "Not restored: that file is not JSON."; return; }
    if (!confirm("Replace this box's settings and calibration by the backup's?")) { ev.target.value = ""; return; }
    try {
      const r = await api("POST", "/api/restore", doc);
      out.textContent = "Restored " + r.settings + " settings and " + r.calibration + " calibration records.";
      out.className = "small ok";
    } catch (e) { out.textContent = "Not restored: " + e.message; out.className = "small error"; }
    ev.target.value = "";
  });

  const btn = $("#notify-enable"), st = $("#notify-state");
  function showPermission() {
    if (!("Notification" in window)) { st.textContent = "This browser cannot show notifications."; btn.disabled = true; return; }
    const p = Notification.permission;
    st.textContent = p === "granted" ? "On: this device is told when a job ends." :
      p === "denied" ? "Blocked in the browser's site settings; allow notifications there." : "Off.";
    btn.disabled = p !== "default";
  }
  btn.addEventListener("click", async () => { if ("Notification" in window) await Notification.requestPermission(); showPermission(); });
  showPermission();
})();
