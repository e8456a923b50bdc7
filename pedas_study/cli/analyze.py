"""`pedas-study analyze survey | drives | within | extended`: the acceptance statistics and the objective KPIs of the study data.
Handlers are thin; the work is in `analysis.survey.acceptance` and `analysis.drives.analyze`."""
from __future__ import annotations

from pedas_study.cli.common import db_path, open_store


def _read_csv(path_text: str, what: str):
    from pathlib import Path

    import pandas as pd

    from study.common.input_size import check_size

    path = Path(path_text)
    if not path.exists():
        raise FileNotFoundError(f"{what} CSV not found: {path}")
    check_size(path, f"{what} CSV")
    return pd.read_csv(path, dtype={"participant_id": str})


def _survey(args) -> int:
    import time
    from pathlib import Path

    from analysis.survey.acceptance import analyze_store, analyze_survey, attributes_from_store, covariates_of

    if args.bootstrap < 0:
        raise ValueError("--bootstrap must be >= 0")
    if args.extended and args.available_case:
        raise ValueError("--extended builds on the listwise analysis; it does not go with --available-case")
    if args.collapse_empty and not args.extended:
        raise ValueError("--collapse-empty is for the ordinal CFA of --extended; pass it with --extended")
    t0 = time.perf_counter()
    model = None
    if args.model:
        path = Path(args.model)
        if not path.is_file():
            raise FileNotFoundError(f"model file not found: {path}")
        model = path.read_text(encoding="utf-8")
    kw = dict(instrument=args.instrument, model=model, n_boot=args.bootstrap, seed=args.seed,
              listwise=not args.available_case, boot_method=args.boot_ci, loadings=args.loadings)
    db = db_path(args)
    if args.responses:
        responses = _read_csv(args.responses, "survey")
        attrs = _read_csv(args.attributes, "attributes") if args.attributes else None
        source = str(args.responses)
        if args.study:
            from study.folder.definition import load

            study = load(args.study, units=False)  # reads no drive log or route
        else:
            if not db.exists():
                raise FileNotFoundError(f"store not found: {db} (pass --study DIR with --responses, or run "
                                        f"`pedas-study init --study DIR`)")
            from study.store.studies import definition

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
            res, responses = analyze_store(st, **kw)
            if args.extended:
                from study.store.studies import definition

                study, attrs = definition(st), attributes_from_store(st)
        source = f"store {db}"
    ext = None
    if args.extended:  # computed before anything is written: a refusal leaves no half-written output
        from analysis.survey.extended import analyze_extended

        # the same answers, model and final CFA: `analyze extended` without a group, minus one start-up and one fit
        ext = analyze_extended(responses, study, attributes=attrs, instrument=args.instrument, model=model,
                               n_boot=args.bootstrap, seed=args.seed, survey=res, collapse_empty=args.collapse_empty)
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
    if ext is not None:
        _write_extended(ext, Path(args.out) / "extended", source, args.bootstrap, t0)
    return 0


def _drives(args) -> int:
    from analysis.drives.analyze import analyze_drives

    db = db_path(args)
    if not db.exists():
        raise FileNotFoundError(f"store not found: {db} (run `pedas-study init`)")
    with open_store(args, read_only=True) as st:
        rep = analyze_drives(st, args.out, participant=args.participant)
    print(rep.text())
    return 0


def _extended(args) -> int:
    import time

    from analysis.survey.acceptance import attributes_from_store, responses_from_store
    from analysis.survey.extended import analyze_extended

    if args.bootstrap < 0:
        raise ValueError("--bootstrap must be >= 0")
    if args.workers < 1:
        raise ValueError("--workers must be >= 1")
    t0 = time.perf_counter()
    if args.responses:
        responses = _read_csv(args.responses, "survey")
        attrs = _read_csv(args.attributes, "attributes") if args.attributes else None
        if not args.study:
            raise ValueError("--responses needs --study DIR (the study folder of the CSV)")
        from study.folder.definition import load

        study = load(args.study, units=False)  # reads no drive log or route
        source = str(args.responses)
    else:
        if args.study or args.attributes:
            raise ValueError("--study and --attributes go with --responses; without it the store's study, answers "
                             "and attributes are analysed")
        db = db_path(args)
        if not db.exists():
            raise FileNotFoundError(f"store not found: {db} (run `pedas-study init` or pass --responses CSV)")
        from study.store.studies import definition

        with open_store(args, read_only=True) as st:
            study = definition(st)
            responses = responses_from_store(st, instrument=args.instrument)
            attrs = attributes_from_store(st)
        if responses.empty:
            raise ValueError("the store has no survey answers of included participants")
        source = f"store {db}"
    ext = analyze_extended(responses, study, attributes=attrs, instrument=args.instrument, n_boot=args.bootstrap,
                           seed=args.seed, group=args.group, workers=args.workers,
                           collapse_empty=args.collapse_empty)
    _write_extended(ext, args.out, source, args.bootstrap, t0)
    return 0


def _collapse_option(p, what: str = "") -> None:
    p.add_argument("--collapse-empty", action="store_true",
                   help=f"merge an item's answer category that the complete rows do not use (refused by default, "
                        f"as lavaan refuses it) for the ordinal CFA{what}; a warning names it")


def _write_extended(ext, out, source: str, n_boot: int, t0: float) -> None:
    """Write `ext` into `out` and print its summary and timing lines."""
    import time

    paths = ext.write(out)
    print(f"extended survey statistics of {ext.n} participants ({source}) -> {out}: {len(paths)} files")
    ind = ext.indirect[~ext.indirect["chain"].str.contains("total", regex=False)]
    for r in ind.itertuples():
        print(f"  indirect {r.chain}: {r.std:.3f} [{r.ci_low:.3f}, {r.ci_high:.3f}] ({n_boot} BCa resamples"
              f"{f', {r.n_failed} failed' if r.n_failed else ''})")
    for r in ext.invariance.itertuples():
        d = "" if r.step == "configural" else f", dCFI = {r.delta_cfi:+.3f}, dchi2({int(r.delta_df)}) = " \
            f"{r.delta_chi2:.2f}, p = {r.p_delta:.3g}"
        print(f"  invariance {r.step}: CFI = {r.cfi:.3f}{d} -> {'holds' if r.holds else 'not supported'}")
    for w in ext.warnings:
        print(f"  warning: {w}")
    t = ext.timings
    print(f"  time: {time.perf_counter() - t0:.1f} s in all; analysis {t['total']:.1f} s (bootstrap of alpha/omega/"
          f"HTMT {t['bootstrap_reliability_htmt']:.1f} s, ordinal CFA {t['ordinal']:.1f} s, indirect effects "
          f"{t['indirect_bootstrap']:.2f} s)")


def _within(args) -> None:
    from analysis.within.analyze import analyze_store_within

    with open_store(args, read_only=True) as st:
        res, data = analyze_store_within(st)
    paths = res.write(args.out, data)
    print(f"within-subjects comparison of {len(res.variables)} variable(s) across {', '.join(res.conditions)} "
          f"-> {args.out}: {len(paths)} files")
    for v in res.variables["variable"]:
        print(f"  {result_sentence_short(res, v)}")
    for w in res.warnings:
        print(f"  warning: {w}")


def result_sentence_short(res, variable: str) -> str:
    a = res.anova[res.anova["variable"] == variable].iloc[0]
    f = res.friedman[res.friedman["variable"] == variable].iloc[0]
    return (f"{variable}: n = {int(a['n'])}, F({a['df1']:g}, {a['df2']:g}) = {a['f']:.2f}, p = {a['p']:.3g} "
            f"(GG p = {a['p_gg']:.3g}), partial eta2 = {a['np2']:.3f}; Friedman chi2({f['df']:g}) = {f['chi2']:.2f}, "
            f"p = {f['p']:.3g}, W = {f['kendall_w']:.3f}")


def register(cli) -> None:
    """Declare the `analyze` group."""
    g = cli.group("analyze", "analyses of the study data")
    p = g.command("survey", "statistics of the study's survey as its model file declares them: descriptives, CFA, "
                  "reliability, validity, hierarchical regressions, hypotheses", _survey)
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
    p.add_argument("--extended", action="store_true",
                   help="also the extended statistics of `analyze extended` (without a group) into OUT/extended, "
                        "built on this run's final CFA")
    p.add_argument("--loadings", choices=("cfa", "pca", "paf"), default="cfa",
                   help="loadings of Table 3 and CR/AVE: cfa (standardized CFA loadings, default), pca (first "
                        "principal component per construct, SPSS FACTOR's default) or paf (principal axis factoring)")
    _collapse_option(p, " of --extended")

    p = g.command("drives", "the drive KPIs the study declares, per drive and by group; with a declared comparison the "
                  "effects of the treatment, reproduction bands and figures", _drives)
    p.add_argument("--out", metavar="DIR", required=True, help="output directory (tables, figures/, objective.md)")
    p.add_argument("--participant", default=None, metavar="ID",
                   help="participant whose drives the single-participant figures and the replay page show "
                        "(default: the study's [comparison] participant in kpis.toml; none: not drawn)")

    p = g.command("within", "within-subjects comparison of the conditions as study.toml's [within] declares it: "
                  "scores and KPIs by condition, rm-ANOVA with sphericity corrections, Friedman, paired post-hocs, "
                  "mixed model, methods sentences", _within)
    p.add_argument("--out", metavar="DIR", required=True, help="output directory (tables, figures, methods.md)")

    p = g.command("extended", "extended acceptance statistics: ordinal CFA and omega, HTMT2, bootstrap CIs (BCa) of "
                  "alpha/omega/HTMT, the structural model as one SEM with indirect effects, VIF, full-collinearity "
                  "VIF, Harman's test and (with --group) measurement invariance", _extended)
    p.add_argument("--responses", metavar="CSV", default=None,
                   help="wide survey CSV (participant_id + item columns, raw answers); default: the store")
    p.add_argument("--study", metavar="DIR", default=None, help="study folder of the --responses CSV")
    p.add_argument("--attributes", metavar="CSV", default=None,
                   help="participant attributes of the --responses CSV (covariates and the --group attribute)")
    p.add_argument("--out", metavar="DIR", required=True, help="output directory for CSVs, model syntax, extended.md")
    p.add_argument("--seed", type=int, default=20240101, help="bootstrap seed (default 20240101)")
    p.add_argument("--bootstrap", type=int, default=2000, metavar="N",
                   help="bootstrap resamples (default 2000; 0 = none)")
    p.add_argument("--group", metavar="ATTR", default=None,
                   help="participant attribute whose groups are compared (configural/metric/scalar invariance)")
    p.add_argument("--instrument", default=None, help="instrument name (default: the study's instrument)")
    p.add_argument("--workers", type=int, default=2, metavar="N",
                   help="processes (default 2: the polychoric correlations beside the bootstrap; 1 = one process)")
    _collapse_option(p)
