"""`pedas-study plan power`: sample size for the next study from this one (or a given population), by
Monte-Carlo simulation per hypothesis and by the RMSEA tests for the measurement model. The work is in
`analysis.survey.sample_size` (docs/power.md)."""
from __future__ import annotations

from pedas_study.cli.common import db_path, open_store


def _sizes(text: str) -> list[int]:
    """'20:300:20' -> 20, 40, ..., 300; '30,60,90' -> those."""
    try:
        if ":" in text:
            a, b, s = (int(x) for x in text.split(":"))
            if s < 1 or b < a:
                raise ValueError
            sizes = list(range(a, b + 1, s))
        else:
            sizes = [int(x) for x in text.split(",")]
    except ValueError:
        raise ValueError(f"--n {text!r}: give START:STOP:STEP or a comma-separated list of sizes") from None
    if not sizes or min(sizes) < 4:
        raise ValueError(f"--n {text!r}: sample sizes must be >= 4")
    return sorted(set(sizes))


def _power(args) -> int:
    from pathlib import Path

    import pandas as pd

    from analysis.survey import sample_size as ss
    from pedas_study.cli.analyze import _read_csv

    if not 0 < args.power < 1:
        raise ValueError(f"--power must be between 0 and 1, not {args.power}")
    sizes = _sizes(args.n)
    if args.population:
        if not args.study:
            raise ValueError("--population needs --study DIR (the study whose model and hypotheses are simulated)")
        from study.definition import load

        study = load(args.study)
        pop = ss.population_from_csv(args.population)
        plan, _ = ss.study_plan(study)
        source = f"population {args.population}"
    elif args.responses:
        if not args.study:
            raise ValueError("--responses needs --study DIR (the study folder of the CSV)")
        from study.definition import load

        study = load(args.study)
        attrs = _read_csv(args.attributes, "attributes") if args.attributes else None
        pop, plan = ss.population_of_responses(_read_csv(args.responses, "survey"), study, attrs)
        source = f"fitted to {args.responses}"
    else:
        db = db_path(args)
        if not db.exists():
            raise FileNotFoundError(f"store not found: {db} (run `pedas-study init`, or pass --responses/--population)")
        from analysis.survey.acceptance import attributes_from_store, responses_from_store
        from study.studies import definition

        with open_store(args, read_only=True) as st:
            study = definition(st)
            responses, attrs = responses_from_store(st), attributes_from_store(st)
        if responses.empty:
            raise ValueError("the store has no survey answers of included participants")
        pop, plan = ss.population_of_responses(responses, study, attrs)
        source = f"fitted to the store {db}"
    alpha = args.alpha if args.alpha is not None else plan.alpha
    tgts = ss.targets(plan.models, plan.hypotheses, pop.names)
    power = ss.mc_power(pop, tgts, sizes, reps=args.reps, alpha=alpha, seed=args.seed, workers=args.workers,
                        progress=not args.no_progress)
    need = ss.required_n(power, args.power, alpha)
    rmsea = pd.DataFrame([{"test": name, "df": plan.measurement_df, "eps0": 0.05, "eps_a": ea, "alpha": alpha,
                           "target_power": args.power,
                           "n_required": ss.rmsea_n(plan.measurement_df, args.power, 0.05, ea, alpha)}
                          for name, ea in (("close fit", args.rmsea_close), ("not-close fit", args.rmsea_not_close))])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    power.to_csv(out / "power.csv", index=False)
    need.to_csv(out / "sample_size.csv", index=False)
    rmsea.to_csv(out / "rmsea_n.csv", index=False)
    pop.frame().to_csv(out / "population.csv")
    ss.power_figure(power, args.power, out)
    print(f"power of {len(tgts)} hypotheses, population {source}; {args.reps} samples per N, seed {args.seed}, "
          f"alpha {alpha} -> {out}")
    for r in need.itertuples():
        n = "not reached" if pd.isna(r.n_required) else f"N = {int(r.n_required)} (power {r.power_at_n:.3f})"
        print(f"  {r.hypothesis} {r.path} ({r.sign} 0): {n} for power {args.power} (sizes {sizes[0]}-{sizes[-1]})")
    for r in rmsea.itertuples():
        print(f"  measurement model (df {r.df}), RMSEA test of {r.test} (H0 .05 vs {r.eps_a}): N = {r.n_required}")
    return 0


def register(cli) -> None:
    """Declare the `plan` group."""
    g = cli.group("plan", "plan the next study")
    p = g.command("power", "sample size per hypothesis by Monte-Carlo simulation (from the store's data, a survey "
                  "CSV or a given population covariance matrix) and the RMSEA-based N of the measurement model",
                  _power)
    p.add_argument("--responses", metavar="CSV", default=None, help="wide survey CSV; default: the store's answers")
    p.add_argument("--attributes", metavar="CSV", default=None, help="participant attributes of the --responses CSV")
    p.add_argument("--population", metavar="CSV", default=None,
                   help="population covariance (or correlation) matrix of the regression variables, names as header "
                        "and first column (instead of data)")
    p.add_argument("--study", metavar="DIR", default=None, help="study folder (with --responses or --population)")
    p.add_argument("--power", type=float, default=0.8, help="target power (default 0.8)")
    p.add_argument("--alpha", type=float, default=None, help="significance level (default: the study's alpha)")
    p.add_argument("--n", default="20:300:20", metavar="SIZES",
                   help="sample sizes to simulate: START:STOP:STEP or a list (default 20:300:20)")
    p.add_argument("--reps", type=int, default=1000, help="simulated samples per size (default 1000)")
    p.add_argument("--seed", type=int, default=20240101, help="seed (default 20240101)")
    p.add_argument("--workers", type=int, default=1, help="local worker processes (default 1; any number gives the "
                   "same result)")
    p.add_argument("--rmsea-close", type=float, default=0.08, help="RMSEA under the alternative of the close-fit "
                   "test (default .08)")
    p.add_argument("--rmsea-not-close", type=float, default=0.01, help="RMSEA under the alternative of the "
                   "not-close-fit test (default .01)")
    p.add_argument("--out", metavar="DIR", required=True, help="output folder (power.csv, sample_size.csv, "
                   "rmsea_n.csv, population.csv, power_curve.png/.pdf)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
