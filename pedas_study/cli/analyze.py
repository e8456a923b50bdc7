"""`pedas-study analyze survey | drives`: the acceptance statistics and the objective KPIs of the study data.
Handlers are thin; the work is in `analysis.acceptance` and `analysis.kpis_report`."""
from __future__ import annotations

from pedas_study.cli.common import db_path, open_store


def _survey(args) -> int:
    from pathlib import Path

    import pandas as pd

    from analysis.acceptance import analyze_survey, responses_from_store

    if args.bootstrap < 0:
        raise ValueError("--bootstrap must be >= 0")
    if args.responses:
        path = Path(args.responses)
        if not path.exists():
            raise FileNotFoundError(f"survey CSV not found: {path}")
        responses = pd.read_csv(path, dtype={"participant_id": str})
        source = str(path)
    else:
        db = db_path(args)
        if not db.exists():
            raise FileNotFoundError(f"store not found: {db} (run `pedas-study init` or pass --responses CSV)")
        with open_store(args, read_only=True) as st:
            responses = responses_from_store(st, instrument=args.instrument)
        source = f"store {db}"
    res = analyze_survey(responses, instrument=args.instrument, cfa_config=args.cfa_config, models=args.models,
                         hypotheses=args.hypotheses, n_boot=args.bootstrap, seed=args.seed,
                         listwise=not args.available_case, boot_method=args.boot_ci)
    paths = res.write(args.out)
    print(f"survey analysis of {res.n} participants ({source}) -> {args.out}: {len(paths)} files")
    for _, h in res.hypotheses.iterrows():
        verdict = "supported" if h["supported"] else "not supported"
        print(f"  {h['hypothesis']} {h['path']}: beta = {h['beta']:.3f}, p = {h['p']:.3g} -> {verdict}")
    for w in res.warnings:
        print(f"  warning: {w}")
    return 0


def _drives(args) -> int:
    from analysis.kpis_report import analyze_drives

    db = db_path(args)
    if not db.exists():
        raise FileNotFoundError(f"store not found: {db} (run `pedas-study init`)")
    with open_store(args, read_only=True) as st:
        rep = analyze_drives(st, args.out, participant=args.participant)
    print(rep.text())
    return 0


def register(cli) -> None:
    """Declare the `analyze` group."""
    g = cli.group("analyze", "analyses of the study data")
    p = g.command("survey", "acceptance statistics (Tables 3-5): descriptives, CFA, reliability, validity, "
                  "hierarchical regressions, H1-H7", _survey)
    p.add_argument("--responses", metavar="CSV", default=None,
                   help="wide survey CSV (participant_id + item columns, raw 1-5); default: the store")
    p.add_argument("--out", metavar="DIR", required=True, help="output directory for CSVs and tables")
    p.add_argument("--seed", type=int, default=20240101, help="bootstrap seed (default 20240101)")
    p.add_argument("--bootstrap", type=int, default=2000, metavar="N",
                   help="bootstrap resamples (default 2000; 0 = none)")
    p.add_argument("--boot-ci", choices=("percentile", "bca"), default="percentile", help="bootstrap CI method")
    p.add_argument("--instrument", default=None, help="codebook name (default pedas_acceptance_v1)")
    p.add_argument("--cfa-config", metavar="JSON", default=None, help="item-deletion config (default specs/cfa.json)")
    p.add_argument("--models", metavar="JSON", default=None, help="regression models (default specs/models.json)")
    p.add_argument("--hypotheses", metavar="JSON", default=None, help="hypotheses (default specs/hypotheses.json)")
    p.add_argument("--available-case", action="store_true",
                   help="keep participants with missing answers (composites over answered items) instead of listwise")

    p = g.command("drives", "objective KPIs per drive and driving style, effects of pEDAS, reproduction bands and "
                  "Figs. 9-12", _drives)
    p.add_argument("--out", metavar="DIR", required=True, help="output directory (tables, figures/, objective.md)")
    p.add_argument("--participant", default="P006", metavar="ID",
                   help="participant of Figs. 11 and 12 (default P006, as in the paper)")
