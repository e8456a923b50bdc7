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

  // One request in flight per item, the newest value queued behind it: arrow keys on a radio group fire a change
  // per step, and parallel requests could reach the server out of order and leave an older value stored.
  var inflight = {};
  var queued = {};

  function save(name, value) {
    if (inflight[name]) {
      if (!(name in queued)) { setPending(1); }
      queued[name] = value;
      return;
    }
    send(name, value);
  }

  function next(name) {
    inflight[name] = false;
    if (name in queued) {
      var value = queued[name];
      delete queued[name];
      setPending(-1);
      send(name, value);
    }
  }

  function send(name, value) {
    inflight[name] = true;
    setPending(1);
    msg.textContent = "Saving…";
    var body = new URLSearchParams();
    body.set("item", name);
    body.set("value", value);
    fetch(url, { method: "POST", body: body, credentials: "same-origin" })
      .then(function (r) { return r.json().then(function (j) { return { ok: r.ok, json: j }; }); })
      .then(function (res) {
        var item = form.querySelector('[data-item="' + name + '"]');
        // the message is set before the count drops: a pending count of 0 means the message is final
        if (res.ok) {
          if (item) { item.classList.remove("invalid", "save-failed"); }
          if (pending === 1) { msg.textContent = "All answers saved (" + res.json.saved_at + " UTC)."; }
        } else {
          if (item) { item.classList.add("save-failed"); }
          msg.textContent = "Not saved: " + (res.json.error || "error");
        }
        setPending(-1);
        next(name);
      })
      .catch(function () {
        msg.textContent = "Not saved: no connection. Your answers on this page are kept; please tell the researcher.";
        setPending(-1);
        next(name);
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
  // Sliders: the range input has no name; the number field beside it carries the answer. The range is shown only
  // with JavaScript (here), starts "unset" (no visible thumb) until the participant moves it, clicks it or presses a
  // key on it, and every committed position is saved like any other answer.
  function commitSlider(range) {
    var field = document.getElementById(range.dataset.for);
    range.parentNode.classList.remove("unset");
    var hint = field.parentNode.querySelector(".not-yet");
    if (hint) { hint.remove(); }
    field.value = range.value;
    if (range.dataset.saved !== range.value) {        // each committed position is saved once
      range.dataset.saved = range.value;
      save(field.name, field.value);
      updateProgress();
    }
  }
  form.querySelectorAll("input[type=range][data-for]").forEach(function (range) {
    var field = document.getElementById(range.dataset.for);
    range.dataset.saved = field.value;
    range.parentNode.hidden = false;
    range.addEventListener("input", function () {
      field.value = range.value;                      // shown while dragging; saved when the thumb is let go
      range.parentNode.classList.remove("unset");
    });
    range.addEventListener("change", function () { commitSlider(range); });
    // a click on the unset slider's starting position changes nothing, so no change event: commit it here
    range.addEventListener("pointerup", function () { commitSlider(range); });
    range.addEventListener("keyup", function (ev) {
      if (/^(Arrow|Page|Home|End)/.test(ev.key)) { commitSlider(range); }
    });
  });
  // typing in a slider's number field moves the slider with it (the field itself is saved like any number)
  form.addEventListener("input", function (ev) {
    var el = ev.target;
    if (el.dataset && el.dataset.range && el.value !== "") {
      var range = document.getElementById(el.dataset.range);
      range.value = el.value;
      range.dataset.saved = el.value;
      range.parentNode.classList.remove("unset");
    }
  });
  var summary = document.getElementById("error-summary");
  if (summary) { summary.focus(); }
})();
