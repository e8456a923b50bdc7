"""`pedas-study analyze survey | drives`: the acceptance statistics and the objective KPIs of the study data.
Handlers are thin; the work is in `analysis.acceptance` and `analysis.kpis_report`."""
from __future__ import annotations

from pedas_study.cli.common import db_path, open_store


def _read_csv(path_text: str, what: str):
    from pathlib import Path

    import pandas as pd

    path = Path(path_text)
    if not path.exists():
        raise FileNotFoundError(f"{what} CSV not found: {path}")
    return pd.read_csv(path, dtype={"participant_id": str})


def _survey(args) -> int:
    from pathlib import Path

    from analysis.acceptance import analyze_store, analyze_survey, attributes_from_store, covariates_of

    if args.bootstrap < 0:
        raise ValueError("--bootstrap must be >= 0")
    model = None
    if args.model:
        path = Path(args.model)
        if not path.is_file():
            raise FileNotFoundError(f"model file not found: {path}")
        model = path.read_text(encoding="utf-8")
    kw = dict(instrument=args.instrument, model=model, n_boot=args.bootstrap, seed=args.seed,
              listwise=not args.available_case, boot_method=args.boot_ci)
    db = db_path(args)
    if args.responses:
        responses = _read_csv(args.responses, "survey")
        attrs = _read_csv(args.attributes, "attributes") if args.attributes else None
        source = str(args.responses)
        if args.study:
            from study.definition import load

            study = load(args.study)
        else:
            if not db.exists():
                raise FileNotFoundError(f"store not found: {db} (pass --study DIR with --responses, or run "
                                        f"`pedas-study init --study DIR`)")
            from study.studies import definition

            with open_store(args, read_only=True) as st:
                study = definition(st)
                if attrs is None and covariates_of(study, args.instrument, model):
                    attrs = attributes_from_store(st)
        res = analyze_survey(responses, study, attributes=attrs, **kw)
    else:
        if args.study or args.attributes:
            raise ValueError("--study and --attributes go with --responses; without it the store's study, answers "
                             "and attributes are analysed")
        if not db.exists():
            raise FileNotFoundError(f"store not found: {db} (run `pedas-study init` or pass --responses CSV)")
        with open_store(args, read_only=True) as st:
            res, _ = analyze_store(st, **kw)
        source = f"store {db}"
    paths = res.write(args.out)
    print(f"survey analysis of {res.n} participants ({source}) -> {args.out}: {len(paths)} files")
    signs = res.settings.get("hypothesis_signs", {})
    for _, h in res.hypotheses.iterrows():
        verdict = "supported" if h["supported"] else "not supported"
        sign = signs.get(h["hypothesis"], "")
        expect = f" (expected {'beta > 0' if sign == '>' else 'beta < 0' if sign == '<' else 'beta != 0'})" \
            if sign else ""
        print(f"  {h['hypothesis']} {h['path']}{expect}: beta = {h['beta']:.3f}, p = {h['p']:.3g} -> {verdict}")
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
    p = g.command("survey", "acceptance statistics of the study's survey (Tables 3-5 of the paper's study): "
                  "descriptives, CFA, reliability, validity, hierarchical regressions, hypotheses", _survey)
    p.add_argument("--responses", metavar="CSV", default=None,
                   help="wide survey CSV (participant_id + item columns, raw answers); default: the store")
    p.add_argument("--study", metavar="DIR", default=None,
                   help="study folder of the --responses CSV (default: the store's study)")
    p.add_argument("--attributes", metavar="CSV", default=None,
                   help="participant attributes of the --responses CSV (participant_id + one column per attribute) "
                        "for covariates in the model; default: the store's participants")
    p.add_argument("--out", metavar="DIR", required=True, help="output directory for CSVs and tables")
    p.add_argument("--seed", type=int, default=20240101, help="bootstrap seed (default 20240101)")
    p.add_argument("--bootstrap", type=int, default=2000, metavar="N",
                   help="bootstrap resamples (default 2000; 0 = none)")
    p.add_argument("--boot-ci", choices=("percentile", "bca"), default="percentile", help="bootstrap CI method")
    p.add_argument("--instrument", default=None, help="instrument name (default: the study's instrument)")
    p.add_argument("--model", metavar="LAV", default=None,
                   help="a model file in lavaan syntax instead of the study's (docs/study_folder.md)")
    p.add_argument("--available-case", action="store_true",
                   help="keep participants with missing answers (composites over answered items) instead of listwise")

    p = g.command("drives", "objective KPIs per drive and driving style, effects of pEDAS, reproduction bands and "
                  "Figs. 9-12", _drives)
    p.add_argument("--out", metavar="DIR", required=True, help="output directory (tables, figures/, objective.md)")
    p.add_argument("--participant", default="P006", metavar="ID",
                   help="participant of Figs. 11 and 12 (default P006, as in the paper)")
