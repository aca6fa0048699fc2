// The settings form (drawn from the settings schema): only changed fields are sent, a refusal is shown
// beside the field it names, and the save bar says whether everything on screen is stored.
"use strict";
(function () {
  const form = document.getElementById("settings-form");
  if (!form) return;
  const { api } = window.InkSlice;
  const status = document.getElementById("settings-result");
  const bar = document.getElementById("savebar");
  const fields = Array.from(form.querySelectorAll(".setting[data-key]"));
  let saved = {};

  function valueOf(div) {
    const input = div.querySelector("input, select");
    const kind = div.dataset.kind;
    if (kind === "bool") return input.checked;
    if (kind === "number" || kind === "int") {
      const t = input.value.trim();
      // an empty or unreadable number goes to the daemon as typed, so it names the problem itself
      return t === "" || isNaN(Number(t)) ? t : Number(t);
    }
    return input.value;
  }
  function changes() {
    const out = {};
    fields.forEach((div) => {
      const v = valueOf(div);
      if (v !== saved[div.dataset.key]) out[div.dataset.key] = v;
    });
    return out;
  }
  function say(text, kind) {
    status.textContent = text;
    bar.classList.remove("dirty", "saved", "refused");
    if (kind) bar.classList.add(kind);
  }
  function clearErrors() {
    fields.forEach((div) => { div.classList.remove("bad"); div.querySelector(".field-error").textContent = ""; });
  }
  function refresh() {
    const n = Object.keys(changes()).length;
    fields.forEach((div) => div.classList.toggle("changed", valueOf(div) !== saved[div.dataset.key]));
    if (n) say(n + (n === 1 ? " change" : " changes") + " not saved yet.", "dirty");
    else if (!bar.classList.contains("saved")) say("All changes saved.", null);
  }
  fields.forEach((div) => { saved[div.dataset.key] = valueOf(div); });
  // a link to #group-x (or to something inside a group, like #password) opens that group
  function openHash() {
    const target = location.hash ? document.getElementById(location.hash.slice(1)) : null;
    const g = target && target.closest("details.group");
    if (g) { g.open = true; target.scrollIntoView(); }
  }
  // "?" beside a setting shows what it does (and its range and default) under it
  document.querySelectorAll("button.helpq").forEach((b) => b.addEventListener("click", () => {
    const help = document.getElementById(b.getAttribute("aria-controls"));
    help.hidden = !help.hidden;
    b.setAttribute("aria-expanded", String(!help.hidden));
  }));
  window.addEventListener("hashchange", openHash);
  openHash();
  const hook = document.getElementById("webhook-test");
  if (hook) hook.addEventListener("click", async () => {
    const out = document.getElementById("webhook-result");
    hook.disabled = true; out.textContent = "Sending…";
    try {
      const r = await api("POST", "/api/webhook/test");
      out.textContent = r.ok ? "Delivered: the receiver took it." : "Not delivered: " + r.problem;
    } catch (e) { out.textContent = "Not sent: " + e.message; }
    hook.disabled = false;
  });
  form.addEventListener("input", refresh);
  form.addEventListener("change", refresh);
  form.addEventListener("submit", async (ev) => {
    ev.preventDefault();
    clearErrors();
    const c = changes();
    if (!Object.keys(c).length) { say("Nothing to save: all changes are saved.", "saved"); return; }
    say("Saving…", "dirty");
    try {
      const now = await api("PATCH", "/api/settings", c);
      fields.forEach((div) => { if (div.dataset.key in now) saved[div.dataset.key] = now[div.dataset.key]; });
      fields.forEach((div) => div.classList.remove("changed"));
      say("Saved at " + new Date().toLocaleTimeString() + ". " + Object.keys(c).length + " changed.", "saved");
    } catch (e) {
      // "key: problem" from the daemon: shown at that field, which is scrolled to
      const m = /^([a-z_]+): (.*)$/.exec(e.message);
      const div = m && form.querySelector('.setting[data-key="' + m[1] + '"]');
      if (div) {
        div.closest("details.group").open = true;
        div.classList.add("bad");
        div.querySelector(".field-error").textContent = m[2];
        div.querySelector("input, select").focus();
        say("Not saved: " + div.querySelector("label").textContent.trim() + " " + m[2] + ". Nothing was changed.", "refused");
      } else say("Not saved: " + e.message, "refused");
    }
  });
})();
