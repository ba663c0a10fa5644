// Clip gating and page timing. The answer controls stay disabled until the clip has played to its end
// (replays allowed); every clip event is logged and sent with the form, with the time spent on the page.
"use strict";

(function () {
  const started = performance.now();
  const events = document.querySelector("[data-events]");
  const log = events && events.value ? safeParse(events.value) : [];

  function safeParse(text) {
    try { const value = JSON.parse(text); return Array.isArray(value) ? value : []; } catch (e) { return []; }
  }

  function record(type) {
    log.push({ type: type, t: Math.round(performance.now() - started) });
    if (events) events.value = JSON.stringify(log.slice(-400));
  }

  function setUpClip(box) {
    const video = box.querySelector("video");
    const button = box.querySelector("[data-play]");
    const status = box.querySelector("[data-status]");
    const answers = document.querySelector("[data-answers]");
    const gated = box.hasAttribute("data-gated");
    let loaded = false;

    function say(text, failed) {
      status.textContent = text;
      status.classList.toggle("failed", Boolean(failed));
    }

    const timeout = parseFloat(box.dataset.timeout || "20") * 1000;
    const timer = setTimeout(function () {
      if (!loaded) {
        record("timeout");
        say("The clip is taking too long to load. Check your internet connection and reload the page. " +
            "If it still does not load, please contact the researchers.", true);
      }
    }, timeout);

    video.addEventListener("loadeddata", function () {
      if (loaded) return;
      loaded = true;
      clearTimeout(timer);
      record("loaded");
      say(gated && !box.hasAttribute("data-watched") ? "Press Play clip. The questions unlock when the clip ends." : "Ready.");
    });
    video.addEventListener("error", function () {
      clearTimeout(timer);
      record("error");
      say("The clip could not be loaded. Please reload the page; if it still fails, contact the researchers.", true);
    });
    video.addEventListener("play", function () { record("play"); button.textContent = "Pause"; say("Playing…"); });
    video.addEventListener("pause", function () {
      if (!video.ended) { record("pause"); button.textContent = "Play clip"; say("Paused."); }
    });
    video.addEventListener("ended", function () {
      record("ended");
      button.textContent = "Replay clip";
      say(gated ? "Clip finished. You can now answer, or replay the clip." : "Clip finished.");
      if (answers) answers.disabled = false;
      video.controls = true;  // seeking is fine once the whole clip has been seen
    });
    button.addEventListener("click", function () {
      if (video.paused || video.ended) {
        const played = video.play();
        if (played && played.catch) played.catch(function () { say("Press Play clip again to start the clip.", true); });
      } else {
        video.pause();
      }
    });
    if (box.hasAttribute("data-watched")) video.controls = true;
    video.load();
  }

  document.querySelectorAll("[data-clip]").forEach(setUpClip);

  document.querySelectorAll("form[data-step-form]").forEach(function (form) {
    form.addEventListener("submit", function (event) {
      const time = form.querySelector("[data-time]");
      if (time) time.value = String(Math.round(performance.now() - started));
      if (form.dataset.sent) { event.preventDefault(); return; }  // a double click sends once
      form.dataset.sent = "1";
    });
  });

  const summary = document.querySelector("[data-focus]");
  if (summary) summary.focus();

  const redirect = document.querySelector("[data-redirect]");
  if (redirect) setTimeout(function () { window.location.href = redirect.href; }, 4000);
})();
