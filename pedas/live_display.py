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


def hud_page(feed_path: str = "/display") -> str:
    """The full-screen HUD page: ``<pedas-hud sound>`` fed by the frames of the session whose code is in the
    address (``/?pair=CODE``); without a code, a field to type it (a click enables the tone)."""
    from pedas.hud_png import hud_script

    return f"""<!doctype html><html lang="en"><head><meta charset="utf-8"><title>pEDAS HUD</title>
<style>html,body{{margin:0;height:100%;background:#000}}pedas-hud{{width:100vw;max-height:100vh;margin:auto}}
pedas-hud[hidden]{{display:none}}
#state{{position:fixed;bottom:4px;left:6px;color:#888;font:12px sans-serif}}
#pair{{position:fixed;top:40%;width:100%;text-align:center;color:#ccc;font:24px sans-serif}}
#pair input{{font:24px monospace;width:10em;text-transform:uppercase}}</style>
<script>{hud_script()}</script></head><body><pedas-hud id="hud" sound></pedas-hud><div id="state">connecting</div>
<script>
const hud = document.getElementById("hud"), state = document.getElementById("state");
const pair = (new URLSearchParams(location.search).get("pair") || "").trim();
document.body.addEventListener("click", () => document.documentElement.requestFullscreen?.());
function connect() {{
  const ws = new WebSocket(`ws://${{location.host}}{feed_path}?pair=${{encodeURIComponent(pair)}}`);
  let ended = false;
  ws.onopen = () => {{ state.textContent = "live"; }};
  ws.onmessage = e => {{
    const m = JSON.parse(e.data);
    if (m.type === "error") {{ ended = true; state.textContent = m.error; return; }}
    hud.frame = m.hud; hud.dataset.seq = String(m.seq);
  }};
  ws.onclose = e => {{
    // 1000: the session ended, 1008: the code is unknown; only a lost connection is tried again
    if (ended) return;   // the error message stays on screen
    if (e.code === 1000 || e.code === 1008) {{ state.textContent = e.reason || "closed"; return; }}
    state.textContent = "reconnecting"; setTimeout(connect, 1000);
  }};
}}
if (pair) connect();
else {{
  state.textContent = "not paired";
  hud.hidden = true;   // no session, no frame: a blank HUD would look like advice to stand still
  document.body.insertAdjacentHTML("beforeend", '<form id="pair">pairing code (the console shows it) ' +
    '<input name="pair" autofocus autocomplete="off"> <button>show</button></form>');
}}
</script></body></html>"""
