// <pedas-hud>: the pEDAS head-up display (Sec. 3.8, Fig. 7) as one SVG web component, no build step.
//
// Give it a HUD frame (pedas.hud_frame.HudFrame as JSON) through the `frame` property or attribute:
//   {"speed": 45, "advice": 48, "limit": 50, "arrow": 1, "arrow_len": 0.3, "color": "green", "in_band": false,
//    "countdown": 7, "light": "green", "icon": "green_wave", "warning": false}
// speed/advice/limit km/h, arrow -1|0|1, arrow_len 0..1, countdown whole s (0..9) or null, light
// green|yellow|red|null (the phase counted down, its lamp lit), icon green_wave|stop_sign|yield_sign|curve|null.
// The paper's three regions (Fig. 7a), left to right: 1. the current speed with the speed limit below it,
// 2. the arrow, 3. additional information (icon and warning at the top, the light and its countdown below).
// Three-digit speeds fit region 1: the digits are squeezed to its width when wider (textLength).
// With the `sound` attribute a warning that switches on plays a tone (WebAudio, 880 Hz, 0.35 s; browsers allow
// audio only after a click on the page). The drawn state is mirrored in data-* attributes of the element
// (data-arrow, data-color, data-countdown, data-light, data-icon, data-warning, data-speed, data-limit, data-tones)
// so that tests and other pages can read what is shown.
(() => {
  const NS = "http://www.w3.org/2000/svg";
  const COLORS = { black: "#111", green: "#0a9d3c", red: "#d2161e" };
  const LAMPS = { red: "#e0191f", yellow: "#f2b705", green: "#19b34a" };   // lit lamps; unlit ones are dark
  const ARROW_MIN = 30, ARROW_MAX = 190;   // px: the arrow's length at arrow_len 0 and 1
  const SPEED_W = 180;                     // px: the widest the speed digits may be (region 1 is 196 px)
  const FONT = "DejaVu Sans, Arial, sans-serif";
  const TEMPLATE = `
<svg xmlns="${NS}" viewBox="0 0 480 270" width="100%" height="100%" role="img" aria-label="pEDAS head-up display">
  <rect id="panel" x="4" y="4" width="472" height="262" rx="18" fill="#eef1f4" stroke="#c9ced4" stroke-width="3"/>
  <line x1="208" y1="22" x2="208" y2="248" stroke="#d5d9de" stroke-width="2"/>
  <line x1="308" y1="22" x2="308" y2="248" stroke="#d5d9de" stroke-width="2"/>
  <text id="speed" x="106" y="104" text-anchor="middle" font-size="92" font-weight="700" font-family="${FONT}"></text>
  <text x="106" y="134" text-anchor="middle" font-size="20" font-family="${FONT}" fill="#555">km/h</text>
  <g id="limit" transform="translate(106 200)">
    <circle r="42" fill="#fff" stroke="#d2161e" stroke-width="9"/>
    <text id="limit-text" y="12" text-anchor="middle" font-size="34" font-weight="700" font-family="${FONT}" fill="#111"></text>
  </g>
  <path id="arrow" fill="none" stroke-linecap="round" stroke-linejoin="round"/>
  <g id="icon-green_wave" transform="translate(352 70)">
    <rect x="-38" y="-38" width="76" height="76" rx="12" fill="#0a9d3c"/>
    <text y="21" text-anchor="middle" font-size="60" font-weight="700" font-family="${FONT}" fill="#fff">G</text>
  </g>
  <g id="icon-stop_sign" transform="translate(352 70)">
    <polygon points="-16,-39 16,-39 39,-16 39,16 16,39 -16,39 -39,16 -39,-16" fill="#d2161e" stroke="#fff" stroke-width="4"/>
    <text y="8" text-anchor="middle" font-size="21" font-weight="700" font-family="${FONT}" fill="#fff">STOP</text>
  </g>
  <g id="icon-yield_sign" transform="translate(352 70)">
    <polygon points="-40,-34 40,-34 0,38" fill="#fff" stroke="#d2161e" stroke-width="9" stroke-linejoin="round"/>
  </g>
  <g id="icon-curve" transform="translate(352 70)">
    <polygon points="0,-40 42,34 -42,34" fill="#fff" stroke="#d2161e" stroke-width="8" stroke-linejoin="round"/>
    <path d="M-8 26 L-8 8 Q-8 -6 6 -10 L6 -18 L18 -6 L6 6 L6 -2 Q2 0 2 8 L2 26 Z" fill="#111"/>
  </g>
  <g id="warning" transform="translate(432 70)">
    <polygon points="0,-36 36,30 -36,30" fill="#e8b500" stroke="#111" stroke-width="4" stroke-linejoin="round"/>
    <text y="24" text-anchor="middle" font-size="44" font-weight="900" font-family="${FONT}" fill="#111">!</text>
  </g>
  <g id="countdown" transform="translate(346 196)">
    <rect x="-21" y="-52" width="42" height="104" rx="9" fill="#222"/>
    <circle id="lamp-red" cy="-32" r="12"/><circle id="lamp-yellow" cy="0" r="12"/><circle id="lamp-green" cy="32" r="12"/>
    <text id="countdown-text" x="72" y="24" text-anchor="middle" font-size="68" font-weight="700" font-family="${FONT}" fill="#111"></text>
  </g>
</svg>`;
  const STYLE = `:host{display:block;aspect-ratio:16/9;max-width:100%;}
:host([data-warning="true"]) #panel{stroke:#d2161e;stroke-width:10;animation:blink .5s step-start infinite;}
@keyframes blink{50%{stroke:#f3a5a8;}}`;

  class PedasHud extends HTMLElement {
    static get observedAttributes() { return ["frame"]; }

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

    attributeChangedCallback(name, _old, value) { if (name === "frame" && value) this.frame = JSON.parse(value); }

    get frame() { return this._frame; }

    set frame(f) { this._frame = f; this._draw(f); }

    _el(id) { return this._svg.getElementById ? this._svg.getElementById(id) : this.shadowRoot.getElementById(id); }

    _draw(f) {
      const color = COLORS[f.color] || COLORS.black;
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
      this._el("limit-text").textContent = f.limit == null ? "" : String(f.limit);
      // the arrow: a vertical shaft with a head, pointing up (speed up) or down (slow down); its length grows
      // with |v - v_opt| (arrow_len), from ARROW_MIN (just outside the band) to ARROW_MAX (full scale)
      const arrow = this._el("arrow");
      if (f.arrow === 0) {
        arrow.setAttribute("d", "");
        arrow.style.display = "none";
      } else {
        const len = ARROW_MIN + (ARROW_MAX - ARROW_MIN) * Math.min(Math.max(f.arrow_len, 0), 1);
        const x = 258, mid = 135, dir = f.arrow > 0 ? -1 : 1;   // SVG y grows downwards
        const tail = mid - dir * len / 2, tip = mid + dir * len / 2;
        arrow.setAttribute("d", `M${x} ${tail} L${x} ${tip} M${x - 18} ${tip - dir * 18} L${x} ${tip} ` +
                                `L${x + 18} ${tip - dir * 18}`);
        arrow.setAttribute("stroke", color);
        arrow.setAttribute("stroke-width", "14");
        arrow.style.display = "";
        arrow.dataset.length = len.toFixed(1);
      }
      this._el("countdown").style.display = f.countdown == null ? "none" : "";
      this._el("countdown-text").textContent = f.countdown == null ? "" : String(f.countdown);
      // the lamp of the counted-down phase is lit (Fig. 7h green, 7i red), the digits in its colour
      for (const lamp of ["red", "yellow", "green"]) {
        this._el(`lamp-${lamp}`).setAttribute("fill", f.light === lamp ? LAMPS[lamp] : "#4a4a4a");
      }
      this._el("countdown-text").setAttribute("fill", LAMPS[f.light] ? (f.light === "yellow" ? "#8a6a00" : LAMPS[f.light]) : "#111");
      for (const icon of ["green_wave", "stop_sign", "yield_sign", "curve"]) {
        this._el(`icon-${icon}`).style.display = f.icon === icon ? "" : "none";
      }
      this._el("warning").style.display = f.warning ? "" : "none";
      if (f.warning && !this._warned && this.hasAttribute("sound")) this._tone();
      this._warned = !!f.warning;
      if (!this.isConnected) return;
      Object.assign(this.dataset, { tones: String(this._tones), arrow: String(f.arrow), color: f.color, countdown: String(f.countdown ?? ""),
                                    light: f.light ?? "", icon: f.icon ?? "", warning: String(!!f.warning),
                                    speed: String(f.speed), limit: String(f.limit ?? "") });
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
