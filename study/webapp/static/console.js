/* The researcher console: a drive-log upload shows its progress (bytes sent, then the server's import). Without
   JavaScript the form posts as usual; with it, the same request is sent by XHR so that progress can be shown. */
"use strict";
document.querySelectorAll("form[data-upload]").forEach((form) => {
  const box = form.querySelector(".upload-progress");
  const bar = box.querySelector("progress");
  const text = box.querySelector(".upload-text");
  const button = form.querySelector("button[type=submit]");
  const mb = (n) => (n / 1048576).toFixed(1);
  form.addEventListener("submit", (ev) => {
    ev.preventDefault();
    const xhr = new XMLHttpRequest();
    xhr.open("POST", form.action);
    xhr.setRequestHeader("X-Requested-With", "XMLHttpRequest");
    xhr.responseType = "json";
    box.hidden = false;
    button.disabled = true;
    text.textContent = "Uploading…";
    xhr.upload.addEventListener("progress", (e) => {
      if (!e.lengthComputable) return;
      bar.value = Math.round((100 * e.loaded) / e.total);
      text.textContent = `${mb(e.loaded)} of ${mb(e.total)} MB sent (${bar.value} %)`;
    });
    xhr.upload.addEventListener("load", () => {
      bar.removeAttribute("value");  // indeterminate while the server reads, checks and stores the log
      text.textContent = "Uploaded; the server is checking and importing the log…";
    });
    xhr.addEventListener("load", () => {
      if (xhr.response && xhr.response.next) {
        window.location.assign(xhr.response.next);
      } else if (xhr.status === 200 && xhr.responseURL) {
        window.location.assign(xhr.responseURL);  // a page instead of the answer: e.g. the session ended (sign-in)
      } else {
        text.textContent = xhr.status === 413 ? "The file is too large." : `Upload failed (HTTP ${xhr.status}).`;
        button.disabled = false;
      }
    });
    xhr.addEventListener("error", () => {
      text.textContent = "Upload failed: the connection to the server broke.";
      button.disabled = false;
    });
    xhr.send(new FormData(form));
  });
});
