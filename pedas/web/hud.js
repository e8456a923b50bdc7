// <pedas-hud>: the pEDAS head-up display (Sec. 3.8, Fig. 7) as one SVG web component, no build step.
//
// Give it a HUD frame (pedas.hud_frame.HudFrame as JSON) through the `frame` property or attribute:
//   {"speed": 45, "advice": 48, "limit": 50, "arrow": 1, "arrow_len": 0.3, "color": "green", "in_band": false,
//    "countdown": 7, "icon": "green_wave", "warning": false}
// speed/advice/limit km/h, arrow -1|0|1, arrow_len 0..1, countdown whole s or null, icon
// green_wave|stop_sign|curve|null. With the `sound` attribute a warning that switches on plays a tone (WebAudio,
// 880 Hz, 0.35 s; browsers allow audio only after a click on the page). The drawn state is mirrored in data-*
// attributes of the element (data-arrow, data-color, data-countdown, data-icon, data-warning, data-tones) so that
// tests and other pages can read what is shown.
(() => {
  const NS = "http://www.w3.org/2000/svg";
  const COLORS = { black: "#111", green: "#0a9d3c", red: "#d2161e" };
  const ARROW_MIN = 28, ARROW_MAX = 120;   // px: the arrow's length at arrow_len 0 and 1
  const TEMPLATE = `
<svg xmlns="${NS}" viewBox="0 0 480 270" width="100%" height="100%" role="img" aria-label="pEDAS head-up display">
  <rect id="panel" x="4" y="4" width="472" height="262" rx="18" fill="#eef1f4" stroke="#c9ced4" stroke-width="3"/>
  <g id="limit" transform="translate(66 70)">
    <circle r="44" fill="#fff" stroke="#d2161e" stroke-width="10"/>
    <text id="limit-text" y="13" text-anchor="middle" font-size="36" font-weight="700" font-family="DejaVu Sans, Arial, sans-serif" fill="#111"></text>
  </g>
  <text id="speed" x="230" y="160" text-anchor="middle" font-size="112" font-weight="700" font-family="DejaVu Sans, Arial, sans-serif"></text>
  <text x="230" y="196" text-anchor="middle" font-size="22" font-family="DejaVu Sans, Arial, sans-serif" fill="#555">km/h</text>
  <path id="arrow" fill="none" stroke-linecap="round" stroke-linejoin="round"/>
  <g id="countdown" transform="translate(50 200)">
    <rect x="-22" y="-44" width="44" height="88" rx="9" fill="#222"/>
    <circle cy="-24" r="10" fill="#555"/><circle cy="0" r="10" fill="#e8b500"/><circle cy="24" r="10" fill="#555"/>
    <text id="countdown-text" x="58" y="16" text-anchor="middle" font-size="44" font-weight="700" font-family="DejaVu Sans, Arial, sans-serif" fill="#111"></text>
  </g>
  <g id="icon-green_wave" transform="translate(412 64)">
    <circle r="40" fill="#0a9d3c"/>
    <path d="M-28 -4 q7 -12 14 0 t14 0 t14 0 t14 0 M-28 14 q7 -12 14 0 t14 0 t14 0 t14 0" fill="none" stroke="#fff" stroke-width="6" stroke-linecap="round"/>
  </g>
  <g id="icon-stop_sign" transform="translate(412 64)">
    <polygon points="-17,-41 17,-41 41,-17 41,17 17,41 -17,41 -41,17 -41,-17" fill="#d2161e" stroke="#fff" stroke-width="4"/>
    <text y="9" text-anchor="middle" font-size="23" font-weight="700" font-family="DejaVu Sans, Arial, sans-serif" fill="#fff">STOP</text>
  </g>
  <g id="icon-curve" transform="translate(412 64)">
    <polygon points="0,-42 44,36 -44,36" fill="#fff" stroke="#d2161e" stroke-width="8" stroke-linejoin="round"/>
    <path d="M-8 26 L-8 8 Q-8 -6 6 -10 L6 -18 L18 -6 L6 6 L6 -2 Q2 0 2 8 L2 26 Z" fill="#111"/>
  </g>
  <g id="warning" transform="translate(412 200)">
    <polygon points="0,-44 46,36 -46,36" fill="#e8b500" stroke="#111" stroke-width="5" stroke-linejoin="round"/>
    <text y="28" text-anchor="middle" font-size="54" font-weight="900" font-family="DejaVu Sans, Arial, sans-serif" fill="#111">!</text>
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
                                       in_band: true, countdown: null, icon: null, warning: false };
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
        const x = 350, mid = 120, dir = f.arrow > 0 ? -1 : 1;   // SVG y grows downwards
        const tail = mid - dir * len / 2, tip = mid + dir * len / 2;
        arrow.setAttribute("d", `M${x} ${tail} L${x} ${tip} M${x - 18} ${tip - dir * 18} L${x} ${tip} ` +
                                `L${x + 18} ${tip - dir * 18}`);
        arrow.setAttribute("stroke", color);
        arrow.setAttribute("stroke-width", "12");
        arrow.style.display = "";
        arrow.dataset.length = len.toFixed(1);
      }
      this._el("countdown").style.display = f.countdown == null ? "none" : "";
      this._el("countdown-text").textContent = f.countdown == null ? "" : String(f.countdown);
      for (const icon of ["green_wave", "stop_sign", "curve"]) {
        this._el(`icon-${icon}`).style.display = f.icon === icon ? "" : "none";
      }
      this._el("warning").style.display = f.warning ? "" : "none";
      if (f.warning && !this._warned && this.hasAttribute("sound")) this._tone();
      this._warned = !!f.warning;
      if (!this.isConnected) return;
      Object.assign(this.dataset, { tones: String(this._tones), arrow: String(f.arrow), color: f.color, countdown: String(f.countdown ?? ""),
                                    icon: f.icon ?? "", warning: String(!!f.warning), speed: String(f.speed) });
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
