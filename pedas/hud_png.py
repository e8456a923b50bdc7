"""HUD frames as PNG for figures: the web component ``<pedas-hud>`` (pedas/web/hud.js) drawn by headless Chromium.

One renderer for every use (live page, replay page, figures), so a figure shows exactly what the driver saw.
The browser is Debian's chromium (``/usr/bin/chromium`` or ``$PEDAS_CHROMIUM``) driven by Playwright.
"""
from __future__ import annotations

import html
import json
import os
from pathlib import Path

from pedas.hud_frame import FIG7, HudFrame

WEB = Path(__file__).resolve().parent / "web"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
WIDTH = 480  # px of one PNG (16:9)


def hud_script() -> str:
    """The source of the ``<pedas-hud>`` web component with its themes' colours (inlined by the pages that show
    the HUD)."""
    from pedas.hud_theme import THEMES

    return f"window.PEDAS_HUD_THEMES = {json.dumps(THEMES)};\n" + (WEB / "hud.js").read_text(encoding="utf-8")


def chromium_path() -> Path:
    """The browser binary: ``$PEDAS_CHROMIUM`` or /usr/bin/chromium; FileNotFoundError when it is missing."""
    path = Path(os.environ.get("PEDAS_CHROMIUM", "/usr/bin/chromium"))
    if not path.exists():
        raise FileNotFoundError(f"no Chromium at {path} (apt-get install chromium, or set PEDAS_CHROMIUM)")
    return path


def launch(playwright):
    """A headless Chromium browser of `playwright` (a sync_playwright() context)."""
    return playwright.chromium.launch(executable_path=str(chromium_path()), args=CHROMIUM_ARGS)


def _page_html(theme: str) -> str:
    from pedas.hud_theme import THEMES

    return (f"<!doctype html><html><head><meta charset='utf-8'>"
            f"<style>body{{margin:0;background:{THEMES[theme]['page']}}}</style><script>{hud_script()}</script></head>"
            f"<body><pedas-hud id='hud' theme='{theme}' style='width:{WIDTH}px'></pedas-hud></body></html>")


def render_png(frames: dict[str, HudFrame], out_dir: str | Path, theme: str = "light") -> dict[str, Path]:
    """Draw each frame with ``<pedas-hud theme=...>`` and write ``<name>.png`` (WIDTH px wide) into out_dir;
    name -> path."""
    from pedas.hud_theme import check_theme

    check_theme(theme)
    chromium_path()   # a missing browser is bad input (one line), found before anything is written
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise FileNotFoundError("drawing the HUD to PNG needs Playwright: pip install 'pedas-study[hud]'") from None

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    with sync_playwright() as p:
        browser = launch(p)
        try:
            page = browser.new_page(viewport={"width": WIDTH + 20, "height": 400})
            page.set_content(_page_html(theme))
            hud = page.locator("#hud")
            for name, frame in frames.items():
                hud.evaluate("(el, f) => { el.frame = f; }", frame.as_dict())
                paths[name] = out / f"{name}.png"
                hud.screenshot(path=str(paths[name]), animations="disabled")  # no blink phase
        finally:
            browser.close()
    return paths


def panel_text(s) -> str:
    """What is written beside a Fig. 7 panel's PNG: letter, the paper's caption and sentence, where we chose, and
    the controller state the frame comes from."""
    return (f"Fig. 7({s.key}) {s.caption}\n"
            f"The paper: \"{s.sentence}\"\n"
            f"Our choice: {s.choice}\n"
            f"State: {s.source()}\n"
            f"Frame: {json.dumps(s.frame().as_dict(), sort_keys=True)}\n")


def write_fig7(out_dir: str | Path, theme: str = "light") -> dict[str, Path]:
    """The nine Fig. 7 panels in a theme as ``fig7_<letter>.png``, beside each ``fig7_<letter>.txt``
    (:func:`panel_text`), plus ``fig7.html`` (the live component with the same texts); letter -> PNG path."""
    out = Path(out_dir)
    frames = {s.key: s.frame() for s in FIG7}
    pngs = render_png({f"fig7_{k}": f for k, f in frames.items()}, out, theme)
    for s in FIG7:
        (out / f"fig7_{s.key}.txt").write_text(panel_text(s), encoding="utf-8")
    cells = "".join(
        f"<figure><pedas-hud theme='{theme}' frame='{html.escape(json.dumps(frames[s.key].as_dict()))}'></pedas-hud>"
        f"<figcaption><b>({s.key}) {html.escape(s.caption)}</b><br><i>{html.escape(s.sentence)}</i><br>"
        f"Our choice: {html.escape(s.choice)}<br><small>{html.escape(s.source())}</small></figcaption></figure>"
        for s in FIG7)
    (out / "fig7.html").write_text(
        "<!doctype html><html><head><meta charset='utf-8'><title>pEDAS HUD, Fig. 7 panels</title>"
        "<style>body{font-family:sans-serif;display:grid;grid-template-columns:repeat(3,1fr);gap:12px;margin:12px}"
        f"figure{{margin:0}}figcaption{{font-size:13px}}</style><script>{hud_script()}</script></head>"
        f"<body>{cells}</body></html>",
        encoding="utf-8")
    return {k: pngs[f"fig7_{k}"] for k in frames}
