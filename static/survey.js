// Clip gating, playback record and page state. The answer controls stay disabled until the clip (on a screen of
// reels: every reel, one playing at a time) has played to its end; on a first viewing seeking forward and faster
// playback are undone. Every clip event (plays, pauses, seeks, rate changes, the tab being hidden; a reel's with
// its place, `reel`) is logged and sent with the form, with the time on the page and the viewport. What the
// participant typed or chose, the log and whether the clip was watched are kept in the browser's storage for this
// screen, so a reload (phones reload background tabs) loses nothing; the server keeps its own clock and refuses
// answers given sooner than the clip can have been watched.
"use strict";

(function () {
  const started = performance.now();
  const events = document.querySelector("[data-events]");
  const stepField = document.querySelector("input[name=step]");
  const csrf = document.querySelector("input[name=csrf_token]");
  const answers = document.querySelector("[data-answers]");
  const storageKey = stepField && csrf ? "foil:" + csrf.value.slice(0, 16) + ":" + stepField.value : null;
  const renderedWithLog = Boolean(events && events.value);
  let log = renderedWithLog ? safeParse(events.value) : [];
  let state = { watched: false, reels: [], values: {} };  // watched: every gated clip; reels: those of them ended

  function safeParse(text) {
    try { const value = JSON.parse(text); return Array.isArray(value) ? value : []; } catch (e) { return []; }
  }

  function storage() {
    try { return window.localStorage; } catch (e) { return null; }
  }

  function save() {
    const store = storage();
    if (!store || !storageKey) return;
    const kept = { log: log.slice(-400), watched: state.watched, reels: state.reels, values: state.values };
    try { store.setItem(storageKey, JSON.stringify(kept)); }
    catch (e) { /* storage full or off: the page still works, a reload just starts it afresh */ }
  }

  function restore() {
    const store = storage();
    if (!store || !storageKey) return;
    const prefix = storageKey.slice(0, storageKey.lastIndexOf(":") + 1);
    for (let i = store.length - 1; i >= 0; i--) {  // screens answered before this one are done with
      const key = store.key(i);
      if (key && key.indexOf("foil:") === 0 && key !== storageKey) store.removeItem(key);
    }
    let kept = null;
    try { kept = JSON.parse(store.getItem(storageKey) || "null"); } catch (e) { kept = null; }
    if (!kept || typeof kept !== "object" || prefix === "") return;
    state.watched = kept.watched === true;
    state.reels = Array.isArray(kept.reels) ? kept.reels : [];
    state.values = kept.values && typeof kept.values === "object" ? kept.values : {};
    if (!renderedWithLog && Array.isArray(kept.log) && kept.log.length) {
      log = kept.log.concat([{ type: "reload", t: 0 }]);
      if (events) events.value = JSON.stringify(log.slice(-400));
    }
  }

  function record(type, value, reel) {
    const item = { type: type, t: Math.round(performance.now() - started) };
    if (typeof value === "number" && isFinite(value)) item.v = Math.round(value * 1000) / 1000;
    if (typeof reel === "number") item.reel = reel;
    log.push(item);
    if (events) events.value = JSON.stringify(log.slice(-400));
    save();
  }

  // Form values: kept on every change, put back after a reload unless the server already filled them in.
  function keepValues(form) {
    form.addEventListener("input", function (event) {
      const field = event.target;
      if (!field.name || field.type === "hidden") return;
      state.values[field.name] = field.value;
      save();
    });
    form.addEventListener("change", function (event) {
      const field = event.target;
      if (!field.name || field.type === "hidden") return;
      if (field.type === "radio" && !field.checked) return;
      state.values[field.name] = field.value;
      save();
    });
  }

  function putBackValues(form) {
    Object.keys(state.values).forEach(function (name) {
      const value = String(state.values[name]);
      const fields = form.querySelectorAll("[name='" + name.replace(/'/g, "") + "']");
      fields.forEach(function (field) {
        if (field.type === "radio") {
          if (!form.querySelector("input[type=radio][name='" + field.name + "']:checked") && field.value === value) field.checked = true;
        } else if (field.type !== "hidden" && !field.value) {
          field.value = value;
        }
      });
    });
  }

  function allWatched() {  // every clip the answers wait for has played to its end
    return Array.prototype.every.call(document.querySelectorAll("[data-clip][data-gated]"), function (box) {
      return box.hasAttribute("data-watched");
    });
  }

  function unlock() {
    if (answers) answers.disabled = false;
    const stale = document.getElementById("video-error");
    if (stale) stale.hidden = true;
    const listed = document.querySelector(".error-summary a[href='#video-error']");  // and its line at the top
    if (listed) {
      const summary = listed.closest(".error-summary");
      listed.closest("li").remove();
      if (!summary.querySelector("li")) summary.hidden = true;
    }
    const hint = document.querySelector("[data-example-hint]");
    if (hint) hint.hidden = true;
  }

  function setUpClip(box) {
    const video = box.querySelector("video");
    const button = box.querySelector("[data-play]");
    const status = box.querySelector("[data-status]");
    const fill = box.querySelector("[data-fill]");
    const gated = box.hasAttribute("data-gated");
    const nextOnly = box.hasAttribute("data-next-only");  // a clip to watch, no questions: only Next unlocks
    const reel = box.hasAttribute("data-reel") ? parseInt(box.dataset.reel, 10) : null;  // its place among reels
    const agent = box.dataset.agent;  // the world's word for an agent
    const unlocks = nextOnly ? (reel !== null ? "The Next button unlocks when each " + agent + "'s clip has ended."
                                              : "The Next button unlocks when the clip ends.")
                  : reel !== null ? "You can answer when each " + agent + "'s clip has ended." : "You can answer when the clip ends.";
    const width = parseFloat(video.getAttribute("width")), height = parseFloat(video.getAttribute("height"));
    if (width > 0 && height > 0) box.style.setProperty("--ratio", String(width / height));
    const keptWatched = state.watched || (reel !== null && state.reels.indexOf(reel) >= 0);
    let watched = box.hasAttribute("data-watched") || (gated && keptWatched && !box.hasAttribute("data-refused"));
    if (box.hasAttribute("data-refused")) { state.watched = false; state.reels = []; save(); }
    if (watched) box.setAttribute("data-watched", "");
    let loaded = false;
    let furthest = 0;  // the furthest point reached by playing, on a first viewing
    let undoing = false;
    // A ranking round's clips show their last frame (how they ended) until played; those seeks are not logged.
    const showsEnd = video.hasAttribute("data-round");
    let atEnd = false;

    function note(type, value) { record(type, value, reel); }  // an event of this clip

    function say(text, failed) {
      status.textContent = text;
      status.classList.toggle("failed", Boolean(failed));
    }

    const timeout = parseFloat(box.dataset.timeout || "20") * 1000;
    const timer = setTimeout(function () {
      if (!loaded) {
        note("timeout");
        say("The clip is taking too long to load. Check your internet connection and reload the page. " +
            "If it still does not load, please contact the researchers.", true);
      }
    }, timeout);

    video.addEventListener("loadeddata", function () {
      if (loaded) return;
      loaded = true;
      clearTimeout(timer);
      note("loaded");
      if (showsEnd && video.duration) {
        atEnd = undoing = true;
        video.currentTime = Math.max(0, video.duration - 0.05);
      }
      say(gated && !watched ? "Press Play clip (or tap the picture). " + unlocks : "Ready. You can replay the clip.");
    });
    video.addEventListener("error", function () {
      clearTimeout(timer);
      note("error");
      say("The clip could not be loaded. Please reload the page; if it still fails, contact the researchers.", true);
    });
    video.addEventListener("play", function () {
      note("play");
      button.textContent = "Pause";
      say("Playing…");
      if (reel !== null) {  // one reel at a time: the server holds the answers for the reels' times added up
        box.closest("[data-reels]").querySelectorAll("video").forEach(function (other) {
          if (other !== video && !other.paused) other.pause();
        });
      }
    });
    video.addEventListener("pause", function () {
      if (!video.ended) { note("pause"); button.textContent = "Play clip"; say("Paused. Press Play clip to go on."); }
    });
    video.addEventListener("timeupdate", function () {
      if (!video.seeking && video.currentTime > furthest && video.currentTime - furthest < 1.5) furthest = video.currentTime;
      if (fill && video.duration) fill.style.width = (100 * video.currentTime / video.duration).toFixed(1) + "%";
    });
    video.addEventListener("seeking", function () {
      if (undoing) { undoing = false; return; }
      if (!watched && video.currentTime > furthest + 0.5) {
        note("seek_blocked", video.currentTime);
        undoing = true;
        video.currentTime = furthest;
        say("Please watch the whole clip once before skipping ahead.", true);
        return;
      }
      note("seek", video.currentTime);
    });
    video.addEventListener("ratechange", function () {
      note("ratechange", video.playbackRate);
      if (!watched && video.playbackRate !== 1) video.playbackRate = 1;
    });
    video.addEventListener("ended", function () {
      if (!watched && video.duration && furthest + 1.5 < video.duration) {  // reached by a skip, not by playing
        note("seek_blocked", video.currentTime);
        undoing = true;
        video.currentTime = furthest;
        button.textContent = "Play clip";
        say("Please watch the whole clip once before skipping ahead. Press Play clip to go on.", true);
        return;
      }
      note("ended");
      watched = true;
      box.setAttribute("data-watched", "");
      if (gated) {
        if (reel !== null && state.reels.indexOf(reel) < 0) state.reels.push(reel);
        state.watched = allWatched();
        save();
      }
      button.textContent = "Replay clip";
      say(!gated ? "Clip finished. You can replay it."
          : !allWatched() ? (nextOnly ? "Clip finished. Now play the other " + agent + "'s clip: Next unlocks when it has ended."
                                      : "Clip finished. Now play the other " + agent + "'s clip: you can answer when it has ended.")
          : nextOnly ? "Clip finished. Press Next to go on, or replay the clip."
          : "Clip finished. You can now answer, or replay the clip.");
      if (gated && allWatched()) {
        unlock();
        if (reel !== null) {  // every reel's line says so, not only the last one's
          box.closest("[data-reels]").querySelectorAll("[data-status]").forEach(function (line) {
            line.textContent = nextOnly ? "Both clips finished. Press Next to go on, or replay them."
                                        : "Clip finished. You can now answer, or replay the clips.";
          });
        }
      }
    });
    video.addEventListener("contextmenu", function (event) { event.preventDefault(); });  // no "Show controls"

    function toggle() {
      if (video.paused || video.ended) {
        if (atEnd) { atEnd = false; undoing = true; video.currentTime = 0; }  // from the start, not logged
        else if (video.ended) video.currentTime = 0;
        const played = video.play();
        if (played && played.catch) played.catch(function () { say("Press Play clip again to start the clip.", true); });
      } else {
        video.pause();
      }
    }
    button.addEventListener("click", toggle);
    video.addEventListener("click", toggle);  // tapping the picture plays and pauses it
    video.controls = false;
    if (watched && gated) {
      if (allWatched()) unlock();
      button.textContent = "Replay clip";
    }
    video.load();
  }

  const form = document.querySelector("form[data-step-form]");
  if (form) {
    restore();
    putBackValues(form);
    keepValues(form);
  }

  document.querySelectorAll("[data-clip]").forEach(setUpClip);

  document.addEventListener("visibilitychange", function () {
    if (events) record(document.visibilityState === "hidden" ? "hidden" : "visible");
  });

  // A ranking names each agent once: say so as soon as one is chosen twice, before sending.
  document.querySelectorAll("[data-ranking]").forEach(function (group) {
    const selects = Array.prototype.slice.call(group.querySelectorAll("select"));
    const message = group.querySelector("[data-rank-error]");
    function check() {
      const seen = {};
      let twice = "";
      selects.forEach(function (select) {
        if (select.value && seen[select.value]) twice = select.value;
        seen[select.value] = true;
      });
      selects.forEach(function (select) {
        const clash = twice && select.value === twice;
        select.setCustomValidity(clash ? twice + " is already in another place." : "");
        if (clash) select.setAttribute("aria-invalid", "true"); else select.removeAttribute("aria-invalid");
      });
      message.hidden = !twice;
      message.textContent = twice ? "Each " + group.dataset.agent + " can take only one place: " + twice + " is chosen twice." : "";
    }
    selects.forEach(function (select) { select.addEventListener("change", check); });
    check();
  });

  // Back to this page from the browser's history: the server shows the current screen (from the back/forward
  // cache, after asking it again), with a short notice saying why.
  window.addEventListener("pageshow", function (event) {
    if (!event.persisted || !form) return;
    try { window.sessionStorage.setItem("foil:back", "1"); } catch (e) { /* storage off: no notice */ }
    window.location.reload();
  });
  const backNotice = document.querySelector("[data-back-notice]");
  if (backNotice) {
    const navigation = performance.getEntriesByType ? performance.getEntriesByType("navigation")[0] : null;
    let reloadedAfterBack = false;
    try {
      reloadedAfterBack = window.sessionStorage.getItem("foil:back") === "1";
      window.sessionStorage.removeItem("foil:back");
    } catch (e) { reloadedAfterBack = false; }
    if (reloadedAfterBack || (navigation && navigation.type === "back_forward")) backNotice.hidden = false;
  }

  document.querySelectorAll("form[data-step-form]").forEach(function (stepForm) {
    stepForm.addEventListener("submit", function (event) {
      const time = stepForm.querySelector("[data-time]");
      if (time) time.value = String(Math.round(performance.now() - started));
      const viewport = stepForm.querySelector("[data-viewport]");
      if (viewport) viewport.value = window.innerWidth + "x" + window.innerHeight;
      if (stepForm.dataset.sent) { event.preventDefault(); return; }  // a double click sends once
      stepForm.dataset.sent = "1";
    });
  });

  const consent = document.querySelector("form[action='/consent']");
  if (consent) consent.addEventListener("submit", function () {  // a new participant starts with nothing kept
    const store = storage();
    if (!store) return;
    for (let i = store.length - 1; i >= 0; i--) {
      const key = store.key(i);
      if (key && key.indexOf("foil:") === 0) store.removeItem(key);
    }
  });

  const copy = document.querySelector("[data-copy]");
  if (copy) copy.addEventListener("click", function () {
    const code = document.getElementById("completion-code").textContent.trim();
    const done = function () { copy.textContent = "Copied"; };
    if (navigator.clipboard && navigator.clipboard.writeText) {
      navigator.clipboard.writeText(code).then(done, function () { selectCode(); });
    } else {
      selectCode();
    }
  });
  function selectCode() {
    const range = document.createRange();
    range.selectNodeContents(document.getElementById("completion-code"));
    const selection = window.getSelection();
    selection.removeAllRanges();
    selection.addRange(range);
    copy.textContent = "Selected: press Ctrl+C (or Copy)";
  }

  // The errors at the top, and under them the clip's Play button: where a phone's window is too short for both
  // below the title, the page scrolls just far enough to show the button, never past the errors' top.
  const summary = document.querySelector("[data-focus]");
  if (summary) {
    summary.focus();
    const play = document.querySelector("[data-play]");
    const below = play ? play.getBoundingClientRect().bottom - window.innerHeight : 0;
    if (below > 0) window.scrollBy(0, Math.min(below + 8, summary.getBoundingClientRect().top));
  }

  const redirect = document.querySelector("[data-redirect]");
  if (redirect) setTimeout(function () { window.location.href = redirect.href; }, 4000);
})();
