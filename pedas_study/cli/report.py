"""`pedas-study report`: regenerate every table and figure, the audit and the reproduction verdict, and the report
document `index.html` for the store's study (`analysis.report`, `analysis.report.document`). Parts the study or its
store does not have are skipped with a reason (printed, and shown in the document). Exit code 3 when published values
are missed."""
from __future__ import annotations

import os
from pathlib import Path

from pedas.scenario import SCENARIOS, SINGLE_LANE
from pedas_study.cli.common import add_scenario_option, db_path, is_user_error, scenario_of
from study.common.errors import UserError


def _report(args) -> int:
    from analysis.report.build import ReportConfig, run_report
    from analysis.report.pipeline import StepFailed
    from pedas_study.extras import require

    lab_store = bool(args.db or os.environ.get("PEDAS_STUDY_DB"))
    reference = args.reference or not lab_store
    if not reference and not db_path(args).exists():
        raise UserError(f"no store at {db_path(args)} (run `pedas-study init`, or use --reference)")
    if args.scheduler is not None:
        require("distributed", "dask", "--scheduler")
    cfg = ReportConfig(out=Path(args.out), db=db_path(args), reference=reference,
                       compare_paper=reference or args.compare_paper, participants=args.participants,
                       workers=args.workers, scheduler=args.scheduler, seed=args.seed, n_boot=args.bootstrap,
                       force=args.force, scenario=scenario_of(args),
                       compare_scenario=(None if args.compare_scenario == "none"
                                         else scenario_of(args, "compare_scenario")),
                       **({"cache_dir": Path(args.cache_dir)} if args.cache_dir else {}))
    try:
        res = run_report(cfg)
    except StepFailed as exc:  # a step refused its input: bad input, not a bug
        if exc.__cause__ is not None and is_user_error(exc.__cause__):
            raise UserError(str(exc)) from exc
        raise
    ran = sum(s.status == "ran" for s in res.steps)
    print(f"report written to {res.out}/ ({len(res.files)} files; {ran} steps ran, "
          f"{len(res.steps) - ran} up to date); open {res.out}/index.html")
    if args.bundle is not None:
        _bundle(cfg, Path(args.bundle or Path(args.out) / "bundle.zip"))
    for part, reason in sorted(res.skipped.items()):
        print(f"skipped {part}: {reason}")
    if res.verdict:
        counts = ", ".join(f"{k} {v}" for k, v in sorted(res.verdict["counts"].items()))
        print(f"reproduction: {counts}")
        if res.verdict["miss"]:
            print(f"{res.verdict['miss']} published values missed: see {res.out}/reproduction.md")
            return 3
    return 0


def _bundle(cfg, path: Path) -> None:
    from analysis.report.bundle import write_bundle
    from study.store.store import Store

    settings = {"seed": cfg.seed, "n_boot": cfg.n_boot, "reference": cfg.reference,
                "compare_paper": cfg.compare_paper, "participants": cfg.participants,
                "survey_bootstrap_seed": cfg.seed or 20240101}
    with Store.open(cfg.db, read_only=True) as st:
        b = write_bundle(cfg.out, st, path, settings)
    print(f"bundle written to {b.path} ({len(b.files)} files)")


def register(cli) -> None:
    """Declare `report`."""
    p = cli.command("report", "regenerate every table and figure, the audit, the reproduction verdict and the "
                    "report document (index.html) for the store's study", _report)
    p.add_argument("--out", default="reports", help="output folder (default reports)")
    p.add_argument("--reference", action="store_true",
                   help="build the given --db from data/reference and simulate the reference cohort")
    p.add_argument("--compare-paper", action="store_true",
                   help="with a lab store: also audit the paper and compare with its published values")
    p.add_argument("--participants", type=int, default=None,
                   help="reference mode: only the first N participants (a quick, reduced cohort)")
    p.add_argument("--workers", type=int, default=None, help="simulation worker processes (default: all cores)")
    p.add_argument("--scheduler", default=None, help="Dask scheduler address for the simulation")
    p.add_argument("--seed", type=int, default=0, help="base seed of the simulated cohort and the bootstrap")
    p.add_argument("--bootstrap", type=int, default=2000, help="bootstrap resamples of the regressions")
    p.add_argument("--force", action="store_true", help="rerun every step")
    add_scenario_option(p)
    p.add_argument("--compare-scenario", default=SINGLE_LANE, metavar="NAME",
                   help=f"reference mode: also drive the cohort in this traffic scenario ({'|'.join(SCENARIOS)}) and "
                        f"show its bands beside the default's (default {SINGLE_LANE}; none: only --scenario)")
    p.add_argument("--cache-dir", default=None, help="step and drive cache (default .report-cache beside the --out folder)")
    p.add_argument("--bundle", nargs="?", const="", default=None, metavar="ZIP",
                   help="also write the submission bundle (tables as CSV/Markdown/LaTeX/DOCX, the study's model "
                        "files, seeds, package versions, input hashes) to ZIP (default OUT/bundle.zip)")
