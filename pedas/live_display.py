"""The HUD page of the live server and its pairing: each page shows the frames of one session only.

A session (one WebSocket connection or one UDP peer of `pedas-study live serve`) gets a pairing code when it is
made; the server's ``ready`` answer carries it and the console prints the page's address ``/?pair=CODE``. The page
opens the feed ``/display?pair=CODE`` and receives the advice messages of that session alone, so a second simulator,
or a client that is not one, cannot draw on a participant's display.
"""
from __future__ import annotations

import secrets
from urllib.parse import parse_qs, urlsplit

PAIR_ALPHABET = "23456789ABCDEFGHJKLMNPQRSTUVWXYZ"   # 32 symbols without 0/O and 1/I: read off a console, typed
PAIR_LENGTH = 8                                      # 32**8 = 1.1e12 codes: not guessed by trying


def new_pair_code() -> str:
    """A fresh pairing code: PAIR_LENGTH symbols of PAIR_ALPHABET drawn by the OS's secure generator."""
    return "".join(secrets.choice(PAIR_ALPHABET) for _ in range(PAIR_LENGTH))


def pair_of(path: str) -> str:
    """The pairing code in a request path's query (``/display?pair=k7qm-2xfd`` -> ``K7QM2XFD``; "" when none):
    case, spaces and dashes do not matter, so a code typed by hand matches."""
    code = (parse_qs(urlsplit(path).query).get("pair") or [""])[0]
    return "".join(code.split()).replace("-", "").upper()[:64]


def hud_page(feed_path: str = "/display", theme: str = "light", visual_warning: bool = True) -> str:
    """The full-screen HUD page: ``<pedas-hud sound theme=...>`` fed by the frames of the session whose code is in
    the address (``/?pair=CODE``); a click enables the tone; visual_warning=False draws no warning triangle and
    blinking border (the tone alone).

    Its states (``data-state`` of ``<body>``), each but ``live`` a full-panel message in large text with the HUD
    hidden, so that no stale or empty frame reads as advice: ``waiting`` (no code yet: a field to type it),
    ``paired`` (the code is known, no frame yet), ``live`` (frames arrive), ``ended`` (the session ended, the last
    frame is taken away), ``wrong-code`` (no session has this code: the field again), ``reconnecting`` (the
    connection was lost; tried again each second). An empty data: favicon keeps the browser from asking the
    WebSocket port for /favicon.ico."""
    from pedas.hud_png import hud_script
    from pedas.hud_theme import THEMES, check_theme

    t = THEMES[check_theme(theme)]
    return f"""<!doctype html><html lang="en"><head><meta charset="utf-8"><title>pEDAS HUD</title>
<link rel="icon" href="data:,">
<style>html,body{{margin:0;height:100%;background:#000;overflow:hidden}}
pedas-hud{{width:100vw;max-height:100vh;margin:auto}}
body:not([data-state=live]) pedas-hud{{visibility:hidden}}
#status{{position:fixed;inset:0;display:flex;flex-direction:column;align-items:center;justify-content:center;
  background:{t['panel']};color:{t['black']};font:6vw sans-serif;text-align:center}}
body[data-state=live] #status{{display:none}}
body[data-state=ended] #status,body[data-state=wrong-code] #status{{background:#3a0d0d;color:#fff}}
#state{{font-weight:700}}#detail{{font-size:2.4vw;max-width:80vw;margin-top:1em}}
#pair{{font-size:2.4vw;margin-top:1.5em}}#pair input{{font:2.4vw monospace;width:10em;text-transform:uppercase}}
#pair button{{font:2.4vw sans-serif}}</style>
<script>{hud_script()}</script></head><body data-state="waiting">
<pedas-hud id="hud" sound theme="{theme}"{"" if visual_warning else " no-visual-warning"}></pedas-hud>
<div id="status"><div id="state">waiting</div><div id="detail"></div>
<form id="pair" hidden>pairing code (the console shows it) <input name="pair" autocomplete="off"> <button>show</button></form></div>
<script>
const hud = document.getElementById("hud"), state = document.getElementById("state"),
      detail = document.getElementById("detail"), form = document.getElementById("pair");
const pair = (new URLSearchParams(location.search).get("pair") || "").trim();
function show(name, word, text = "") {{
  document.body.dataset.state = name; state.textContent = word; detail.textContent = text;
  form.hidden = !(name === "waiting" || name === "wrong-code");
  if (!form.hidden) form.elements.pair.focus();
}}
document.body.addEventListener("click", e => {{ if (!form.contains(e.target)) document.documentElement.requestFullscreen?.().catch(() => {{}}); }});
function connect() {{
  const ws = new WebSocket(`ws://${{location.host}}{feed_path}?pair=${{encodeURIComponent(pair)}}`);
  let done = false;
  ws.onopen = () => show("paired", "paired", `session ${{pair}}: waiting for the simulator's first state`);
  ws.onmessage = e => {{
    const m = JSON.parse(e.data);
    if (m.type === "error") {{ done = true; show("wrong-code", "wrong pairing code", m.error); return; }}
    hud.frame = m.hud; hud.dataset.seq = String(m.seq);
    if (document.body.dataset.state !== "live") show("live", "live");
  }};
  ws.onclose = e => {{
    // 1000: the session ended, 1008: the code is unknown; only a lost connection is tried again
    if (done) return;   // the error stays on screen
    if (e.code === 1008) {{ show("wrong-code", "wrong pairing code", e.reason); return; }}
    if (e.code === 1000) {{ show("ended", "session ended", "the simulator's session is over; the HUD shows no advice"); return; }}
    show("reconnecting", "reconnecting", "the connection to the server was lost"); setTimeout(connect, 1000);
  }};
}}
if (pair) connect();
else show("waiting", "waiting", "type the session's pairing code");
</script></body></html>"""
