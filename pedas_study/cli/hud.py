"""`pedas-study hud fig7`: the HUD (Sec. 3.8) in the nine situations of Fig. 7 as PNG and as an HTML page."""
from __future__ import annotations

from pathlib import Path


def _fig7(args) -> None:
    from pedas.hud_frame import FIG7
    from pedas.hud_png import write_fig7

    paths = write_fig7(args.out)
    for s in FIG7:
        print(f"({s.key}) {paths[s.key]}  {s.caption}")
    print(f"page: {Path(args.out) / 'fig7.html'}")


def register(cli) -> None:
    """Declare the `hud` group."""
    g = cli.group("hud", "the head-up display")
    p = g.command("fig7", "draw the HUD in the nine situations of Fig. 7 (PNG + HTML, headless Chromium)", _fig7)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
