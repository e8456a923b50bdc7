// The replay page of a participant's drives (analysis/replay.py embeds the data as JSON in #replay-data).
// One time slider for all drives; per drive: the HUD as the driver saw it (<pedas-hud>), speed with advice and
// right under it a timeline of what the HUD showed (arrow, band, countdown, icon, tone), then speed with advice
// and limit, leader gap, controller and a space-time strip with the signal states at the lights' stop lines. Under each drive's name: whether its HUD is the
// one stored with the drive (exactly what was shown) or rebuilt from its log.
// Every chart has a cursor at the slider's time; the state shown is the last sample at or before that time.
(() => {
  const NS = "http://www.w3.org/2000/svg";
  const data = JSON.parse(document.getElementById("replay-data").textContent);
  const W = 560, PAD = { l: 46, r: 8, t: 18, b: 22 };
  const SIGNAL = { green: "#0a9d3c", yellow: "#e8b500", red: "#d2161e" };
  const CTRL = { rt: "#4a77c9", cf: "#c97a1e", none: "#bbb" };
  const tEnd = Math.max(...data.drives.map(d => d.t[d.t.length - 1]));

  const el = (tag, attrs = {}, parent = null) => {
    const e = document.createElementNS(NS, tag);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (parent) parent.appendChild(e);
    return e;
  };
  const finite = a => a.filter(x => x !== null && Number.isFinite(x));

  // a chart: x = time (0..tEnd s), y from lo to hi; returns {svg, x, y, cursor}
  function chart(parent, title, h, lo, hi, unit) {
    const svg = el("svg", { viewBox: `0 0 ${W} ${h}`, width: "100%", class: "chart", "data-title": title }, parent);
    const x = t => PAD.l + (W - PAD.l - PAD.r) * t / tEnd;
    const y = v => h - PAD.b - (h - PAD.t - PAD.b) * (v - lo) / ((hi - lo) || 1);
    el("rect", { x: PAD.l, y: PAD.t, width: W - PAD.l - PAD.r, height: h - PAD.t - PAD.b, fill: "#fafafa",
                 stroke: "#ccc" }, svg);
    const lab = el("text", { x: PAD.l, y: 12, "font-size": 11 }, svg);
    lab.textContent = `${title} (${unit})`;
    for (const v of [lo, hi]) {
      const tick = el("text", { x: PAD.l - 4, y: y(v) + 4, "font-size": 10, "text-anchor": "end" }, svg);
      tick.textContent = Math.round(v);
    }
    const axis = el("text", { x: W - PAD.r, y: h - 6, "font-size": 10, "text-anchor": "end" }, svg);
    axis.textContent = `t (s), 0 - ${Math.round(tEnd)}`;
    const cursor = el("line", { class: "cursor", y1: PAD.t, y2: h - PAD.b, stroke: "#000", "stroke-width": 1.5 }, svg);
    return { svg, x, y, cursor };
  }

  function line(c, t, v, color, width = 1.5, dash = "") {
    let d = "", pen = false;
    for (let i = 0; i < t.length; i++) {
      if (v[i] === null) { pen = false; continue; }
      d += `${pen ? "L" : "M"}${c.x(t[i]).toFixed(1)} ${c.y(v[i]).toFixed(1)}`;
      pen = true;
    }
    return el("path", { d, fill: "none", stroke: color, "stroke-width": width, "stroke-dasharray": dash }, c.svg);
  }

  function frameAt(d, i) {
    const f = {};
    for (const k of Object.keys(d.frames)) f[k] = d.frames[k][i];
    return f;
  }

  function indexAt(d, t) {   // the last sample at or before t
    let lo = 0, hi = d.t.length - 1;
    if (t >= d.t[hi]) return hi;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (d.t[mid] <= t) lo = mid; else hi = mid - 1;
    }
    return lo;
  }

  const LANES = [
    ["arrow", f => f.arrow > 0 ? "#0a9d3c" : f.arrow < 0 ? "#d2161e" : null],
    ["band", f => f.in_band && f.advice !== null ? "#111" : null],
    ["countdown", f => f.countdown === null || f.countdown === undefined ? null : (SIGNAL[f.light] || "#777")],
    ["icon", f => ICON[f.icon] || null],
    ["tone", f => f.warning ? "#d2161e" : null],
  ];
  const ICON = { green_wave: "#0a9d3c", stop_sign: "#8b0000", yield_sign: "#e07b00", curve: "#6a4fb3" };
  const HUD_SOURCE = {
    stored: "HUD as shown: the drive's stored HUD channels",
    rebuilt: "HUD rebuilt from the drive log (no stored HUD channels: no green-wave or curve icon)",
  };
  function hudTimeline(parent, d) {
    const h = PAD.t + PAD.b + 4 + 14 * LANES.length;   // every lane inside the box, where the cursor crosses it
    const c = chart(parent, "HUD shown", h, 0, 1, "arrow, band, countdown, icon, tone");
    c.svg.classList.add("hud-timeline");
    for (const tick of [...c.svg.querySelectorAll("text")]) if (tick.getAttribute("x") === String(PAD.l - 4)) tick.remove();   // no 0..1 ticks
    const n = d.t.length, fr = i => frameAt(d, i);
    LANES.forEach(([name, colour], k) => {
      const y = PAD.t + 2 + 14 * k;
      const lab = el("text", { x: PAD.l - 4, y: y + 10, "font-size": 10, "text-anchor": "end" }, c.svg);
      lab.textContent = name === "countdown" ? "timer" : name;   // "countdown" does not fit the left margin
      for (let a = 0; a < n;) {
        const col = colour(fr(a));
        let b = a;
        while (b + 1 < n && colour(fr(b + 1)) === col) b++;
        if (col !== null) {
          const x0 = c.x(d.t[a]), x1 = c.x(d.t[Math.min(b + 1, n - 1)]);
          el("rect", { x: x0, y, width: Math.max(x1 - x0, 0.5), height: 11, fill: col, class: `lane-${name}`,
                       "data-t0": d.t[a], "data-t1": d.t[b] }, c.svg);
        }
        a = b + 1;
      }
    });
    c.svg.appendChild(c.cursor);
    return c;
  }

  // a legend under a chart: [colour, label, kind] with kind "line", "dash" or "box"
  function legend(parent, items) {
    const p = document.createElement("p");
    p.className = "legend";
    for (const [colour, label, kind = "box"] of items) {
      const s = document.createElement("span");
      const key = document.createElement("i");
      key.className = kind;
      key.style[kind === "box" ? "background" : "borderColor"] = colour;
      s.append(key, label);
      p.append(s);
    }
    parent.appendChild(p);
  }
  const NAMES = { pedas: "pEDAS", baseline: "baseline" };

  const views = data.drives.map(d => {
    const sec = document.createElement("section");
    sec.className = "drive";
    sec.dataset.condition = d.condition;
    sec.innerHTML = `<h2></h2><p class="hud-source"></p><pedas-hud></pedas-hud><p class="readout"></p>`;
    sec.querySelector("h2").textContent = NAMES[d.condition] || d.condition;   // a study's own name, as text
    if (data.theme) sec.querySelector("pedas-hud").setAttribute("theme", data.theme);
    const advised = d.advice.some(a => a !== null);
    // where the HUD comes from: the drive's stored HUD channels (exactly what was shown) or rebuilt from its log
    sec.dataset.hudSource = d.hud_source;
    sec.querySelector(".hud-source").textContent = !advised
      ? "no pEDAS HUD in this drive: the panel shows only the speed and the limit a speedometer would"
      : HUD_SOURCE[d.hud_source] ||
        `HUD as shown (stored HUD channels) ${d.hud_source.replace(/^stored /, "")}, rebuilt from the log elsewhere`;
    document.getElementById("drives").appendChild(sec);
    // what the HUD showed over time, right under the HUD (one lane per element, a coloured span per run of equal
    // values): the arrow (green up, red down), the band (black digits), the countdown (its phase's colour), the
    // icon, the tone
    const hudLanes = hudTimeline(sec, d);
    legend(sec, [["#0a9d3c", "arrow up"], ["#d2161e", "arrow down / tone"], ["#111", "band (coast)"],
                 [SIGNAL.green, "timer: green"], [SIGNAL.yellow, "yellow"], [SIGNAL.red, "red phase"],
                 [ICON.green_wave, "icon G"], [ICON.curve, "curve"], [ICON.stop_sign, "STOP"],
                 [ICON.yield_sign, "yield"]]);
    const vmax = Math.max(...finite(d.v), ...finite(d.limit), ...finite(d.advice), 10);
    const speed = chart(sec, "speed", 170, 0, vmax, "km/h");
    line(speed, d.t, d.limit, "#888", 1.2, "5 3");
    line(speed, d.t, d.advice, "#0a9d3c", 1.2);
    line(speed, d.t, d.v, "#111", 1.5);
    legend(sec, [["#111", "speed", "line"], ["#0a9d3c", "advice", "line"], ["#888", "limit", "dash"]]);
    const gaps = finite(d.gap);
    const gap = chart(sec, "leader gap", 110, 0, Math.max(...gaps, 10), "m");
    line(gap, d.t, d.gap, "#4a77c9");
    // controller: one coloured band per run of equal values
    const ctrl = chart(sec, "controller", 64, 0, 1, "reference tracking, car following, none");
    for (let a = 0; a < d.t.length;) {
      let b = a;
      while (b + 1 < d.t.length && d.controller[b + 1] === d.controller[a]) b++;
      const x0 = ctrl.x(d.t[a]), x1 = ctrl.x(d.t[Math.min(b + 1, d.t.length - 1)]);
      el("rect", { x: x0, y: PAD.t, width: Math.max(x1 - x0, 0.5), height: 64 - PAD.t - PAD.b,
                   fill: CTRL[d.controller[a]] || "#999" }, ctrl.svg);
      a = b + 1;
    }
    ctrl.svg.appendChild(ctrl.cursor);
    legend(sec, [[CTRL.rt, "reference tracking (rt)"], [CTRL.cf, "car following (cf)"], [CTRL.none, "none"]]);
    // space-time strip: the trajectory s(t) and, at each light's stop line, its state over time
    const sMax = Math.max(...d.s);
    const st = chart(sec, "space-time", 230, 0, sMax, "m");
    for (const sig of d.signals) {
      for (const [t0, t1, state] of sig.spans) {
        el("line", { x1: st.x(t0), x2: st.x(t1), y1: st.y(sig.s), y2: st.y(sig.s), stroke: SIGNAL[state] || "#999",
                     "stroke-width": 4, class: "signal", "data-tl": sig.id }, st.svg);
      }
    }
    line(st, d.t, d.s, "#111", 1.2);
    const dot = el("circle", { r: 4, fill: "#d2161e", class: "position" }, st.svg);
    return { d, sec, hud: sec.querySelector("pedas-hud"), readout: sec.querySelector(".readout"),
             charts: [speed, gap, ctrl, hudLanes, st], st, dot };
  });

  const slider = document.getElementById("slider");
  const clock = document.getElementById("clock");
  slider.max = tEnd.toFixed(1);

  function show(t) {
    clock.textContent = `t = ${t.toFixed(1)} s`;
    for (const v of views) {
      const i = indexAt(v.d, t);
      const f = frameAt(v.d, i);
      v.hud.frame = f;
      const ti = v.d.t[i];
      for (const c of v.charts) { c.cursor.setAttribute("x1", c.x(t)); c.cursor.setAttribute("x2", c.x(t)); }
      v.dot.setAttribute("cx", v.st.x(ti));
      v.dot.setAttribute("cy", v.st.y(v.d.s[i]));
      const adv = v.d.advice[i] === null ? "no advice" : `advice ${v.d.advice[i].toFixed(1)} km/h`;
      const gap = v.d.gap[i] === null ? "no leader" : `gap ${v.d.gap[i].toFixed(1)} m`;
      v.readout.textContent = `t ${ti.toFixed(1)} s, s ${v.d.s[i].toFixed(0)} m, v ${v.d.v[i].toFixed(1)} km/h, ` +
                              `${adv}, ${gap}, controller ${v.d.controller[i]}` +
                              (v.d.advice[i] === null ? "" : `; HUD: ${f.brake ? "BRAKE" : f.arrow > 0 ? "speed up"
                                : f.arrow < 0 ? "slow down" : "coast"}`);   // what the driver was told
      v.sec.dataset.index = String(i);
    }
  }

  // playback keeps its own clock: the slider snaps to its 0.2 s steps, smaller than one frame's advance
  let timer = null, last = 0, now_t = 0;
  const play = document.getElementById("play");
  const rate = document.getElementById("rate");
  function tick(now) {
    now_t = Math.min(now_t + (now - last) / 1000 * Number(rate.value), tEnd);
    last = now;
    slider.value = now_t;
    show(now_t);
    if (now_t >= tEnd) stop(); else timer = requestAnimationFrame(tick);
  }
  function stop() { cancelAnimationFrame(timer); timer = null; play.textContent = "Play"; }
  play.addEventListener("click", () => {
    if (timer !== null) { stop(); return; }
    now_t = Number(slider.value) >= tEnd ? 0 : Number(slider.value);
    play.textContent = "Pause";
    last = performance.now();
    timer = requestAnimationFrame(tick);
  });
  slider.addEventListener("input", () => { now_t = Number(slider.value); show(now_t); });
  show(0);
})();
