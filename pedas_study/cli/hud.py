"""`pedas-study hud`: the head-up display (Sec. 3.8): the nine panels of Fig. 7 as PNG and HTML (`fig7`), and the
search of the reference cohort's drives for the controller states they are drawn from (`search`)."""
from __future__ import annotations

import json
from pathlib import Path


def _fig7(args) -> None:
    from pedas.hud_frame import FIG7
    from pedas.hud_png import write_fig7

    from pedas.hud_theme import check_theme
    from study.common.errors import UserError

    try:
        check_theme(args.theme)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    paths = write_fig7(args.out, args.theme)
    for s in FIG7:
        print(f"({s.key}) {paths[s.key]}  {s.caption}")
        print(f"    the paper: \"{s.sentence}\"")
        print(f"    our choice: {s.choice}")
        print(f"    state: {s.source()}")
    print(f"page: {Path(args.out) / 'fig7.html'} (each PNG has its text beside it: fig7_<letter>.txt)")


def _search(args) -> None:
    from pedas.hud_search import search
    from pedas_study.cli.common import open_store
    from study.common.errors import UserError

    if args.drives < 1:
        raise UserError(f"--drives must be at least 1, got {args.drives}")
    with open_store(args, read_only=True) as st:
        rows = st.df("SELECT participant_id, meta FROM drives WHERE condition = 'pedas' AND source = 'simulation' "
                     "ORDER BY participant_id").to_dict("records")
    if not rows:
        raise UserError("the store has no simulated pedas drives to search (simulate cohort first)")
    people = []
    for r in rows[:args.drives]:
        m = json.loads(r["meta"])
        people.append((r["participant_id"], int(m["participant_seed"]), m["style"], int(m["traffic_seed"]),
                       m["scenario"]))
    try:
        found = search(people, progress=print)
    except RuntimeError as exc:
        raise UserError(str(exc)) from None
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(found, indent=1) + "\n", encoding="utf-8")
    for f in found:
        print(f"({f['key']}) {f['drive']} t = {f['t']:.1f} s")
    print(f"written: {out}")


def register(cli) -> None:
    """Declare the `hud` group."""
    g = cli.group("hud", "the head-up display")
    p = g.command("fig7", "draw the HUD in the nine panels of Fig. 7 (PNG + text + HTML, headless Chromium)", _fig7)
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--theme", default="light", metavar="NAME",
                   help="light (opaque panel, default) or dark (black = see-through, for a projected HUD)")
    p = g.command("search", "find a controller state for each Fig. 7 panel in the store's simulated pedas drives "
                            "(re-simulates them; writes the states pedas/hud_fig7.json holds)", _search)
    p.add_argument("--out", required=True, metavar="FILE", help="JSON file of the nine states")
    p.add_argument("--drives", type=int, default=6, metavar="N",
                   help="search the first N pedas drives in participant order (default 6)")
