"""`pedas-study plan power`: sample size for the next study from this one (or a given population): per hypothesis
its effect size (Cohen's f²), its power at the current N and the N for the target power, analytic (noncentral F,
the default) or by Monte-Carlo simulation; and the RMSEA-based N of the measurement model. The work is in
`analysis.survey.sample_size` (docs/power.md)."""
from __future__ import annotations

from pedas_study.cli.common import db_path, open_store

#: the power curve's sizes of the analytic method when --n is not given
ANALYTIC_CURVE = "20:300:20"


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


def _population(args):
    """(population, study plan, where the population comes from) of the command's source."""
    from analysis.survey import sample_size as ss
    from pedas_study.cli.analyze import _read_csv

    if args.population:
        if not args.study:
            raise ValueError("--population needs --study DIR (the study whose model and hypotheses are planned)")
        from study.folder.definition import load

        study = load(args.study, units=False)  # reads no drive log or route
        pop = ss.population_from_csv(args.population)
        plan, _ = ss.study_plan(study)
        return pop, plan, f"population {args.population}"
    if args.responses:
        if not args.study:
            raise ValueError("--responses needs --study DIR (the study folder of the CSV)")
        from study.folder.definition import load

        study = load(args.study, units=False)  # reads no drive log or route
        attrs = _read_csv(args.attributes, "attributes") if args.attributes else None
        pop, plan = ss.population_of_responses(_read_csv(args.responses, "survey"), study, attrs)
        return pop, plan, f"fitted to {args.responses}"
    db = db_path(args)
    if not db.exists():
        raise FileNotFoundError(f"store not found: {db} (run `pedas-study init`, or pass --responses/--population)")
    from analysis.survey.acceptance import attributes_from_store, responses_from_store
    from study.store.studies import definition

    with open_store(args, read_only=True) as st:
        study = definition(st)
        responses, attrs = responses_from_store(st), attributes_from_store(st)
    if responses.empty:
        raise ValueError("the store has no survey answers of included participants")
    pop, plan = ss.population_of_responses(responses, study, attrs)
    return pop, plan, f"fitted to the store {db}"


def _power(args) -> int:
    from pathlib import Path

    import pandas as pd

    from analysis.survey import sample_size as ss

    if not 0 < args.power < 1:
        raise ValueError(f"--power must be between 0 and 1, not {args.power}")
    if args.n_current is not None and args.n_current < 4:
        raise ValueError(f"--n-current must be >= 4, not {args.n_current}")
    if args.n_max < 4:
        raise ValueError(f"--n-max must be >= 4, not {args.n_max}")
    simulate = args.method == "simulation"
    if simulate and args.reps < 1:
        raise ValueError(f"--reps must be >= 1, not {args.reps}")
    if simulate and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, not {args.workers}")
    sizes = _sizes(args.n) if args.n else ([] if simulate else _sizes(ANALYTIC_CURVE))
    pop, plan, source = _population(args)
    alpha = args.alpha if args.alpha is not None else plan.alpha
    tgts = ss.targets(plan.models, plan.hypotheses, pop.names)
    if simulate:
        power, need = ss.simulated_power(pop, tgts, target=args.power, reps=args.reps, alpha=alpha, seed=args.seed,
                                         n_current=args.n_current, sizes=sizes, n_max=args.n_max,
                                         workers=args.workers, progress=not args.no_progress)
    else:
        power, need = ss.analytic_power(pop, tgts, target=args.power, alpha=alpha, n_current=args.n_current,
                                        sizes=sizes, n_max=args.n_max)
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
    how = (f"Monte-Carlo, {args.reps} samples per N, seed {args.seed}" if simulate
           else "analytic (Cohen's f², noncentral F)")
    print(f"power of {len(tgts)} hypotheses, population {source}; {how}, alpha {alpha} -> {out}")
    for r in need.itertuples():
        head = f"  {r.hypothesis} {r.path} ({r.sign} 0): f2 = {r.f2:.4f} (beta = {r.beta:.3f})"
        now = "" if pd.isna(r.n_current) or pd.isna(r.power_current) else \
            f"; power {r.power_current:.3f} at N = {int(r.n_current)}"
        n = f"N = {int(r.n_required)} (power {r.power_at_n:.3f}) for power {args.power}" \
            if not pd.isna(r.n_required) else f"not reached: {r.note}"
        print(f"{head}{now}; {n}")
    for r in rmsea.itertuples():
        print(f"  measurement model (df {r.df}), RMSEA test of {r.test} (H0 .05 vs {r.eps_a}): N = {r.n_required}")
    return 0


def register(cli) -> None:
    """Declare the `plan` group."""
    g = cli.group("plan", "plan the next study")
    p = g.command("power", "effect size, power at the current N and N for the target power per hypothesis "
                  "(analytic: Cohen's f2 with the noncentral F; or Monte-Carlo simulation), from the store's data, a "
                  "survey CSV or a given population covariance matrix, and the RMSEA-based N of the measurement "
                  "model", _power)
    p.add_argument("--method", choices=("analytic", "simulation"), default="analytic",
                   help="analytic: Cohen's f2 and the noncentral F, as G*Power and R pwr.f2.test (default); "
                        "simulation: Monte-Carlo power of the study's own rule")
    p.add_argument("--responses", metavar="CSV", default=None, help="wide survey CSV; default: the store's answers")
    p.add_argument("--attributes", metavar="CSV", default=None, help="participant attributes of the --responses CSV")
    p.add_argument("--population", metavar="CSV", default=None,
                   help="population covariance (or correlation) matrix of the regression variables, names as header "
                        "and first column (instead of data)")
    p.add_argument("--study", metavar="DIR", default=None, help="study folder (with --responses or --population)")
    p.add_argument("--power", type=float, default=0.8, help="target power (default 0.8)")
    p.add_argument("--alpha", type=float, default=None, help="significance level (default: the study's alpha)")
    p.add_argument("--n-current", type=int, default=None, metavar="N",
                   help="the N whose power is reported (default: the complete rows of the data; none with "
                        "--population)")
    p.add_argument("--n-max", type=int, default=10_000, metavar="N",
                   help="largest N searched; a hypothesis whose power is below the target there is 'not reached' "
                        "(default 10000)")
    p.add_argument("--n", default=None, metavar="SIZES",
                   help="sizes of the power curve (power.csv, power_curve.png): START:STOP:STEP or a list; default "
                        f"{ANALYTIC_CURVE} analytic, none with --method simulation (the sizes its search simulates)")
    p.add_argument("--reps", type=int, default=1000, help="simulated samples per size (simulation; default 1000)")
    p.add_argument("--seed", type=int, default=20240101, help="seed of the simulation (default 20240101)")
    p.add_argument("--workers", type=int, default=1, help="local worker processes of the simulation, one hypothesis "
                   "each (default 1; any number gives the same result)")
    p.add_argument("--rmsea-close", type=float, default=0.08, help="RMSEA under the alternative of the close-fit "
                   "test (default .08)")
    p.add_argument("--rmsea-not-close", type=float, default=0.01, help="RMSEA under the alternative of the "
                   "not-close-fit test (default .01)")
    p.add_argument("--out", metavar="DIR", required=True, help="output folder (power.csv, sample_size.csv, "
                   "rmsea_n.csv, population.csv, power_curve.png/.pdf)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
