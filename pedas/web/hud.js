// <pedas-hud>: the pEDAS head-up display (Sec. 3.8, Fig. 7) as one SVG web component, no build step.
//
// Give it a HUD frame (pedas.hud_frame.HudFrame as JSON) through the `frame` property or attribute:
//   {"speed": 45, "advice": 48, "limit": 50, "arrow": 1, "arrow_len": 0.3, "color": "green", "in_band": false,
//    "countdown": 7, "light": "green", "icon": "green_wave", "warning": false}
// speed/advice/limit km/h, arrow -1|0|1, arrow_len 0..1, countdown whole s (0..9) or null, light
// green|yellow|red|null (the phase counted down, its lamp lit), icon green_wave|stop_sign|yield_sign|curve|null,
// brake true|false (the explicit brake state: "BRAKE" over the full red arrow).
// The paper's three regions (Fig. 7a), left to right: 1. the current speed with the speed limit below it,
// 2. the arrow, 3. additional information (icon and warning at the top, the light and its countdown below).
// Three-digit speeds fit region 1: the digits are squeezed to its width when wider (textLength).
// With the `sound` attribute a warning that switches on plays a tone (WebAudio, 880 Hz, 0.35 s; browsers allow
// audio only after a click on the page). The drawn state is mirrored in data-* attributes of the element
// (data-arrow, data-color, data-countdown, data-light, data-icon, data-warning, data-speed, data-limit, data-tones)
// so that tests and other pages can read what is shown.
// Attributes: theme="light|dark" (pedas/hud_theme.py: the light panel, or black = see-through for a projected
// HUD); no-visual-warning (the tone without the warning triangle and blinking border).
(() => {
  const NS = "http://www.w3.org/2000/svg";
  // colours per theme (pedas/hud_theme.py, injected as PEDAS_HUD_THEMES); the `theme` attribute picks one
  const THEMES = window.PEDAS_HUD_THEMES || {};
  const ARROW_MIN = 30, ARROW_MAX = 190;   // px: the arrow's length at arrow_len 0 and 1
  const SPEED_W = 180;                     // px: the widest the speed digits may be (region 1 is 196 px)
  const LIMIT_W = 52;                      // px: the widest the limit digits may be (the disc's inside is 75 px)
  const FONT = "DejaVu Sans, Arial, sans-serif";
  // region 3 (x 308..472): icon and warning at 3/4 size, >= 9 px from each other, the divider and the border
  const TEMPLATE = `
<svg xmlns="${NS}" viewBox="0 0 480 270" width="100%" height="100%" role="img" aria-label="pEDAS head-up display">
  <rect id="panel" x="4" y="4" width="472" height="262" rx="18" stroke-width="3"/>
  <line class="divider" x1="208" y1="22" x2="208" y2="248" stroke-width="2"/>
  <line class="divider" x1="308" y1="22" x2="308" y2="248" stroke-width="2"/>
  <text id="speed" x="106" y="104" text-anchor="middle" font-size="92" font-weight="700" font-family="${FONT}"></text>
  <text id="unit" x="106" y="134" text-anchor="middle" font-size="20" font-family="${FONT}">km/h</text>
  <g id="limit" transform="translate(106 200)">
    <circle id="limit-disc" r="42" stroke-width="9"/>
    <text id="limit-text" y="12" text-anchor="middle" font-size="34" font-weight="700" font-family="${FONT}"></text>
  </g>
  <path id="arrow" fill="none" stroke-linecap="round" stroke-linejoin="round"/>
  <text id="brake" x="258" y="60" text-anchor="middle" font-size="20" font-weight="900" font-family="${FONT}">BRAKE</text>
  <g id="icon-green_wave" transform="translate(352 70) scale(.75)">
    <rect id="tile" x="-38" y="-38" width="76" height="76" rx="12"/>
    <text id="tile-text" y="21" text-anchor="middle" font-size="60" font-weight="700" font-family="${FONT}">G</text>
  </g>
  <g id="icon-stop_sign" transform="translate(352 70) scale(.75)">
    <polygon id="stop" points="-16,-39 16,-39 39,-16 39,16 16,39 -16,39 -39,16 -39,-16" stroke="#fff" stroke-width="4"/>
    <text id="stop-text" y="8" text-anchor="middle" font-size="21" font-weight="700" font-family="${FONT}">STOP</text>
  </g>
  <g id="icon-yield_sign" transform="translate(352 70) scale(.75)">
    <polygon id="yield" points="-40,-34 40,-34 0,38" stroke-width="9" stroke-linejoin="round"/>
  </g>
  <g id="icon-curve" transform="translate(352 70) scale(.75)">
    <polygon id="curve" points="0,-40 42,34 -42,34" stroke-width="8" stroke-linejoin="round"/>
    <path id="curve-arrow" d="M-8 26 L-8 8 Q-8 -6 6 -10 L6 -18 L18 -6 L6 6 L6 -2 Q2 0 2 8 L2 26 Z"/>
  </g>
  <g id="warning" transform="translate(428 70) scale(.75)">
    <polygon id="warn" points="0,-36 36,30 -36,30" stroke-width="4" stroke-linejoin="round"/>
    <text id="warn-text" y="24" text-anchor="middle" font-size="44" font-weight="900" font-family="${FONT}">!</text>
  </g>
  <g id="countdown" transform="translate(346 196)">
    <rect id="housing" x="-21" y="-52" width="42" height="104" rx="9"/>
    <circle id="lamp-red" cy="-32" r="12"/><circle id="lamp-yellow" cy="0" r="12"/><circle id="lamp-green" cy="32" r="12"/>
    <rect id="timer" x="38" y="-40" width="68" height="80" rx="9"/>
    <text id="countdown-text" x="72" y="24" text-anchor="middle" font-size="64" font-weight="700" font-family="${FONT}"></text>
  </g>
</svg>`;
  const STYLE = `:host{display:block;aspect-ratio:16/9;max-width:100%;}
:host([data-warning="true"]:not([no-visual-warning])) #panel{stroke:var(--alarm);stroke-width:10;animation:blink .5s step-start infinite;}
@keyframes blink{50%{stroke:var(--alarm-blink);}}`;

  class PedasHud extends HTMLElement {
    static get observedAttributes() { return ["frame", "theme"]; }

    constructor() {
      super();
      const root = this.attachShadow({ mode: "open" });
      root.innerHTML = `<style>${STYLE}</style>${TEMPLATE}`;
      this._svg = root.querySelector("svg");
      this._frame = null;
      this._warned = false;
      this._audio = null;
      this._tones = 0;   // attributes may not be set in a custom element's constructor: mirrored on connect
    }

    connectedCallback() {
      if (!this._frame) this.frame = { speed: 0, advice: 0, limit: null, arrow: 0, arrow_len: 0, color: "black",
                                       in_band: true, countdown: null, light: null, icon: null, warning: false };
      else this._draw(this._frame);
    }

    attributeChangedCallback(name, _old, value) {
      if (name === "frame" && value) this.frame = JSON.parse(value);
      if (name === "theme" && this._frame) this._draw(this._frame);
    }

    // the theme's colours (the `theme` attribute; light when absent or unknown)
    get _t() { return THEMES[this.getAttribute("theme")] || THEMES.light; }

    _paint(t) {
      const fill = (id, c) => this._el(id).setAttribute("fill", c);
      const stroke = (id, c) => this._el(id).setAttribute("stroke", c);
      fill("panel", t.panel); stroke("panel", t.border);
      for (const d of this._svg.querySelectorAll(".divider")) d.setAttribute("stroke", t.divider);
      fill("unit", t.label); fill("limit-disc", t.disc); stroke("limit-disc", t.ring); fill("limit-text", t.limit_text);
      fill("tile", t.tile); fill("tile-text", t.tile_text); fill("stop", t.stop); fill("stop-text", t.stop_text);
      fill("yield", t.sign); stroke("yield", t.ring); fill("curve", t.sign); stroke("curve", t.ring);
      fill("curve-arrow", t.curve_arrow); fill("warn", t.warn); stroke("warn", t.warn_text); fill("warn-text", t.warn_text);
      fill("housing", t.housing); fill("timer", t.timer);
      this._svg.style.setProperty("--alarm", t.alarm); this._svg.style.setProperty("--alarm-blink", t.alarm_blink);
    }

    get frame() { return this._frame; }

    set frame(f) { this._frame = f; this._draw(f); }

    _el(id) { return this._svg.getElementById ? this._svg.getElementById(id) : this.shadowRoot.getElementById(id); }

    _draw(f) {
      const t = this._t;
      this._paint(t);
      const color = t[f.color] || t.black;
      const speed = this._el("speed");
      speed.textContent = String(f.speed);
      speed.setAttribute("fill", color);
      speed.removeAttribute("textLength");
      speed.removeAttribute("lengthAdjust");
      // three digits at full size are wider than region 1: squeeze them to its width rather than overlap the arrow
      if (this.isConnected && speed.getComputedTextLength() > SPEED_W) {
        speed.setAttribute("textLength", String(SPEED_W));
        speed.setAttribute("lengthAdjust", "spacingAndGlyphs");
      }
      this._el("limit").style.display = f.limit == null ? "none" : "";
      const limit = this._el("limit-text");
      limit.textContent = f.limit == null ? "" : String(f.limit);
      limit.removeAttribute("textLength");
      limit.removeAttribute("lengthAdjust");
      // "100", "120" at full size touch the ring: squeezed to LIMIT_W, a margin left inside the disc
      if (this.isConnected && f.limit != null && limit.getComputedTextLength() > LIMIT_W) {
        limit.setAttribute("textLength", String(LIMIT_W));
        limit.setAttribute("lengthAdjust", "spacingAndGlyphs");
      }
      // the arrow: a vertical shaft with a head, pointing up (speed up) or down (slow down); its length grows
      // with |v - v_opt| (arrow_len), from ARROW_MIN (just outside the band) to ARROW_MAX (full scale)
      const arrow = this._el("arrow");
      if (f.arrow === 0) {
        arrow.setAttribute("d", "");
        arrow.style.display = "none";
      } else {
        // in the brake state the full arrow is shortened and moved down, under the word BRAKE
        const len = f.brake ? ARROW_MAX - 50 : ARROW_MIN + (ARROW_MAX - ARROW_MIN) * Math.min(Math.max(f.arrow_len, 0), 1);
        const x = 258, mid = f.brake ? 160 : 135, dir = f.arrow > 0 ? -1 : 1;   // SVG y grows downwards
        const tail = mid - dir * len / 2, tip = mid + dir * len / 2;
        arrow.setAttribute("d", `M${x} ${tail} L${x} ${tip} M${x - 18} ${tip - dir * 18} L${x} ${tip} ` +
                                `L${x + 18} ${tip - dir * 18}`);
        arrow.setAttribute("stroke", color);
        arrow.setAttribute("stroke-width", "14");
        arrow.style.display = "";
        arrow.dataset.length = len.toFixed(1);
      }
      // the brake state (pedas.hud_frame.cut_in_advice): the full red arrow under the word BRAKE
      this._el("brake").style.display = f.brake ? "" : "none";
      this._el("brake").setAttribute("fill", t.red);
      this._el("countdown").style.display = f.countdown == null ? "none" : "";
      this._el("countdown-text").textContent = f.countdown == null ? "" : String(f.countdown);
      // the lamp of the counted-down phase is lit (Fig. 7h green, 7i red), the digits in its colour
      for (const lamp of ["red", "yellow", "green"]) {
        this._el(`lamp-${lamp}`).setAttribute("fill", f.light === lamp ? t[`lamp_${lamp}`] : t.lamp_off);
      }
      // the digit on its own dark timer face, in the lit lamp's colour (yellow stays yellow on both themes)
      this._el("countdown-text").setAttribute("fill", t[`lamp_${f.light}`] || t.lamp_yellow);
      for (const icon of ["green_wave", "stop_sign", "yield_sign", "curve"]) {
        this._el(`icon-${icon}`).style.display = f.icon === icon ? "" : "none";
      }
      // the visual warning (triangle, blinking border) beside the tone; `no-visual-warning` switches it off
      this._el("warning").style.display = f.warning && !this.hasAttribute("no-visual-warning") ? "" : "none";
      if (f.warning && !this._warned && this.hasAttribute("sound")) this._tone();
      this._warned = !!f.warning;
      if (!this.isConnected) return;
      Object.assign(this.dataset, { tones: String(this._tones), arrow: String(f.arrow), color: f.color, countdown: String(f.countdown ?? ""),
                                    light: f.light ?? "", icon: f.icon ?? "", warning: String(!!f.warning),
                                    speed: String(f.speed), limit: String(f.limit ?? ""),
                                    brake: String(!!f.brake) });
    }

    _tone() {
      const Ctx = window.AudioContext || window.webkitAudioContext;
      if (!Ctx) return;
      this._audio = this._audio || new Ctx();
      const ctx = this._audio;
      if (ctx.state === "suspended") ctx.resume();
      const osc = ctx.createOscillator(), gain = ctx.createGain();
      osc.frequency.value = 880;
      gain.gain.setValueAtTime(0.25, ctx.currentTime);
      gain.gain.exponentialRampToValueAtTime(0.001, ctx.currentTime + 0.35);
      osc.connect(gain).connect(ctx.destination);
      osc.start();
      osc.stop(ctx.currentTime + 0.35);
      this._tones += 1;
    }
  }

  if (!customElements.get("pedas-hud")) customElements.define("pedas-hud", PedasHud);
})();
