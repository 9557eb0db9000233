// The replay page's panel: one clock in log time drives viser's recorded scene (through its
// player's time box, which it then hides), the clock line, the plot's cursor and the attempt's
// gate table. Everything shown from the data goes through textContent (never parsed as HTML).
(function () {
  "use strict";
  const data = JSON.parse(document.getElementById("routefuse-replay-data").textContent);
  const $ = (id) => document.getElementById(id);
  const play = $("rf-play"), speedSelect = $("rf-speed"), slider = $("rf-time");
  const clock = $("rf-clock"), cursor = $("rf-cursor"), strip = $("rf-strip");
  const prevRefused = $("rf-prev-refused"), nextRefused = $("rf-next-refused");
  const attempts = data.attempts;
  const refused = attempts.filter((a) => !a.accepted);
  const refusedBefore = [0]; // refusedBefore[n]: refusals among the first n attempts
  for (const a of attempts) refusedBefore.push(refusedBefore.at(-1) + (a.accepted ? 0 : 1));
  const EPS = 0.01;
  const MAX_STEP_MS = 250; // after a stall (a shader compiling), step on instead of jumping
  let t = 0, playing = false, lastFrame = null, shownAttempt = undefined, viserInput = null;

  function findViserPlayer() {
    const track = document.querySelector(".mantine-Slider-root");
    if (!track) return null;
    const bar = track.closest(".mantine-Paper-root");
    const input = bar && bar.querySelector("input");
    if (!input) return null;
    bar.style.setProperty("display", "none", "important");
    return input;
  }

  function seekScene(time) {
    if (!viserInput) viserInput = findViserPlayer();
    if (!viserInput) return false;
    const setter = Object.getOwnPropertyDescriptor(HTMLInputElement.prototype, "value").set;
    setter.call(viserInput, (time + 0.0005).toFixed(4));
    viserInput.dispatchEvent(new Event("input", { bubbles: true }));
    return true;
  }

  function attemptsBy(time) {
    // how many attempts were made by ``time`` (they are in time order): a binary search
    let lo = 0, hi = attempts.length;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (attempts[mid].t <= time + EPS) lo = mid + 1;
      else hi = mid;
    }
    return lo;
  }

  function attemptAt(time) {
    const k = attemptsBy(time) - 1;
    if (k < 0 || time - attempts[k].t > data.max_age_s) return -1;
    return k;
  }

  function inOutage(time) {
    return data.outages.some(([a, b]) => a <= time && time <= b);
  }

  function showAttempt(k) {
    if (k === shownAttempt) return;
    shownAttempt = k;
    const title = $("rf-attempt-title"), body = $("rf-gates").tBodies[0], fit = $("rf-fit");
    body.replaceChildren();
    if (k < 0) {
      title.textContent = "No match attempt on screen";
      title.className = "";
      fit.textContent = "";
      return;
    }
    const a = attempts[k];
    title.textContent = `Attempt #${a.index} at ${a.t.toFixed(1)} s: ${a.verdict}`;
    title.className = a.accepted ? "rf-verdict-accepted" : "rf-verdict-refused";
    for (const g of a.gates) {
      const row = body.insertRow();
      if (!g.passed) row.className = "rf-failed";
      const value = g.no_rival ? "no rival" : g.value === null ? "n/a" : g.value.toFixed(3);
      for (const text of [g.name, value, g.comparison, g.threshold === null ? "n/a" : g.threshold.toFixed(3), g.passed ? "ok" : "FAILED"]) {
        row.insertCell().textContent = text;
      }
    }
    fit.textContent = a.fit;
  }

  function placeCursor(time) {
    const s = data.strip, scale = strip.clientWidth / s.width_px;
    const f = (time - s.t_lo) / (s.t_hi - s.t_lo);
    const x = s.x_left_px + Math.min(Math.max(f, 0), 1) * (s.x_right_px - s.x_left_px);
    cursor.style.left = `${x * scale}px`;
  }

  function show(time, { seek = true } = {}) {
    t = Math.min(Math.max(time, 0), data.duration);
    slider.value = String(t);
    const done = attemptsBy(t);
    clock.textContent =
      `log time ${t.toFixed(1)} s / ${data.duration.toFixed(1)} s · ` +
      `${inOutage(t) ? "GNSS outage" : "GNSS"} · attempts ${done} (${refusedBefore[done]} refused)`;
    placeCursor(t);
    showAttempt(attemptAt(t));
    prevRefused.disabled = !refused.some((a) => a.t < t - EPS);
    nextRefused.disabled = !refused.some((a) => a.t > t + EPS);
    if (seek) seekScene(t);
  }

  function setPlaying(on) {
    playing = on;
    play.textContent = on ? "Pause" : "Play";
    lastFrame = null;
  }

  function goTo(time) {
    setPlaying(false);
    show(time);
  }

  function tick(now) {
    if (playing) {
      if (lastFrame !== null) {
        const elapsed = Math.min(now - lastFrame, MAX_STEP_MS);
        let next = t + (elapsed / 1000) * Number(speedSelect.value);
        if (next > data.duration) next = 0;
        show(next);
      }
      lastFrame = now;
    }
    requestAnimationFrame(tick);
  }

  play.addEventListener("click", () => setPlaying(!playing));
  slider.addEventListener("input", () => goTo(Number(slider.value)));
  nextRefused.addEventListener("click", () => {
    const a = refused.find((r) => r.t > t + EPS);
    if (a) goTo(a.t);
  });
  prevRefused.addEventListener("click", () => {
    const before = refused.filter((r) => r.t < t - EPS);
    if (before.length) goTo(before[before.length - 1].t);
  });
  $("rf-strip-box").addEventListener("click", (event) => {
    const s = data.strip, scale = strip.clientWidth / s.width_px;
    const x = (event.clientX - strip.getBoundingClientRect().left) / scale;
    goTo(s.t_lo + ((x - s.x_left_px) / (s.x_right_px - s.x_left_px)) * (s.t_hi - s.t_lo));
  });
  window.addEventListener(
    "keydown",
    (event) => {
      if (event.code !== "Space") return;
      event.stopImmediatePropagation(); // viser's own player must not start beside this one
      const tag = document.activeElement && document.activeElement.tagName;
      if (["INPUT", "SELECT", "BUTTON", "TEXTAREA"].includes(tag)) return; // the control's own
      event.preventDefault();
      setPlaying(!playing);
    },
    true,
  );
  window.addEventListener("resize", () => placeCursor(t));

  show(0, { seek: false });
  const waitForPlayer = setInterval(() => {
    if (seekScene(t)) {
      clearInterval(waitForPlayer);
      document.body.dataset.replayReady = "true";
      setPlaying(data.autoplay);
    }
  }, 100);
  requestAnimationFrame(tick);
})();
