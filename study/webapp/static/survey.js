// Save every answer as it is given (one small POST per change) so that a reload or a crashed tablet resumes.
// Without JavaScript the form still works: "Save and continue later" and "Submit answers" post the whole form.
(function () {
  "use strict";
  var form = document.getElementById("survey-form");
  if (!form || !form.dataset.autosave) { return; }
  var url = form.dataset.autosave;
  var status = document.getElementById("save-status");
  var msg = document.getElementById("save-msg");
  var progress = document.getElementById("progress");
  var pending = 0;
  var timers = {};

  function setPending(delta) {
    pending += delta;
    status.dataset.pending = String(pending);
  }

  function updateProgress() {
    var required = {};
    form.querySelectorAll("[required]").forEach(function (el) { required[el.name] = required[el.name] || false; });
    form.querySelectorAll("[required]").forEach(function (el) {
      if ((el.type === "radio" && el.checked) || (el.type !== "radio" && el.value.trim() !== "")) { required[el.name] = true; }
    });
    var names = Object.keys(required);
    var done = names.filter(function (n) { return required[n]; }).length;
    progress.textContent = done + " of " + names.length + " questions answered.";
  }

  function save(name, value) {
    setPending(1);
    msg.textContent = "Saving…";
    var body = new URLSearchParams();
    body.set("item", name);
    body.set("value", value);
    fetch(url, { method: "POST", body: body, credentials: "same-origin" })
      .then(function (r) { return r.json().then(function (j) { return { ok: r.ok, json: j }; }); })
      .then(function (res) {
        setPending(-1);
        var item = form.querySelector('[data-item="' + name + '"]');
        if (res.ok) {
          if (item) { item.classList.remove("invalid", "save-failed"); }
          if (pending === 0) { msg.textContent = "All answers saved (" + res.json.saved_at + " UTC)."; }
        } else {
          if (item) { item.classList.add("save-failed"); }
          msg.textContent = "Not saved: " + (res.json.error || "error");
        }
      })
      .catch(function () {
        setPending(-1);
        msg.textContent = "Not saved: no connection. Your answers on this page are kept; please tell the researcher.";
      });
  }

  form.addEventListener("change", function (ev) {
    var el = ev.target;
    if (!el.name || el.name === "action") { return; }
    clearTimeout(timers[el.name]);
    save(el.name, el.value);
    updateProgress();
  });
  // free text and numbers: also save while typing (after a pause), not only when the field is left
  form.addEventListener("input", function (ev) {
    var el = ev.target;
    if (el.tagName !== "TEXTAREA" && el.type !== "number") { return; }
    clearTimeout(timers[el.name]);
    timers[el.name] = setTimeout(function () { save(el.name, el.value); updateProgress(); }, 800);
  });
  var summary = document.getElementById("error-summary");
  if (summary) { summary.focus(); }
})();
