// On every page: the tab's title shows the bench's progress, and the browser is told (a notification,
// once permitted on the System page) when a job finishes, fails or needs attention.
// The bench page's live stream hands its states over as "inkslice:state" events; other pages poll.
"use strict";
(function () {
  const base = document.title;
  const ACTIVE = ["homing", "scanning", "processing"];
  let last = null;

  function title(st) {
    const s = st.state;
    if (ACTIVE.includes(s)) {
      const pct = st.levels_total ? Math.round(100 * (st.levels_done || 0) / st.levels_total) : 0;
      document.title = (s === "processing" ? "processing" : pct + " %") + " · " + base;
    } else if (s === "done" || s === "failed") document.title = (s === "done" ? "done" : "FAILED") + " · " + base;
    else document.title = base;
  }
  function tell(heading, body, tag) {
    if (!("Notification" in window) || Notification.permission !== "granted") return;
    try { new Notification(heading, { body: body, tag: tag, icon: "/static/favicon.svg" }); } catch (e) { /* some phones only allow it from a service worker */ }
  }
  function seen(st) {
    if (!st || !st.state) return;
    title(st);
    const was = last;
    last = st;
    if (!was || !ACTIVE.includes(was.state) || ACTIVE.includes(st.state) || was.job_id !== st.job_id) return;
    const job = st.job_id || "";
    if (st.state === "done") tell("InkSlice: job finished", job + " is done.", job);
    else if (st.state === "failed") tell("InkSlice: job failed", st.message || job, job);
    else if (st.state === "cancelled") tell("InkSlice: needs attention", "The scan stopped: " + (st.message || "cancelled"), job);
  }
  document.addEventListener("inkslice:state", (ev) => seen(ev.detail));
  if (document.body.dataset.page !== "dashboard" && document.body.dataset.page !== "") {
    const poll = () => fetch("/api/state", { credentials: "same-origin" }).then((r) => r.ok ? r.json() : null).then(seen).catch(() => {});
    poll();
    setInterval(poll, 5000);
  }
})();
