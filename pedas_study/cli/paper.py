"""`pedas-study paper audit | reconstruct | cohort | reproduce`: the paper as data - audit, reconstruction,
reference cohort, reproduction comparison."""
from __future__ import annotations

import argparse


def _audit(args: argparse.Namespace) -> int:
    from analysis.paper.audit import findings, write_audit

    audit = write_audit(args.out)
    f = findings(audit)
    counts = audit["status"].value_counts()
    print(f"{len(audit)} checks (" + ", ".join(f"{k} {v}" for k, v in counts.items()) + f"), {len(f)} findings "
          f"-> {args.out}/audit.csv, audit.md")
    for r in f.itertuples():
        print(f"  #{r.finding} {r.title} ({r.n_rows} rows, first {r.first_row})")
    return 0


def _reconstruct(args: argparse.Namespace) -> int:
    import time

    from analysis.paper.reconstruct import reconstruct

    t0 = time.perf_counter()
    result = reconstruct(seed=args.seed)
    result.write(args.out)
    dt = time.perf_counter() - t0
    print(f"{len(result.data)} respondents, seed {args.seed}, {dt:.1f} s -> {args.out}")
    print(result.summary_text())
    return 0


def _cohort(args: argparse.Namespace) -> int:
    from analysis.paper.reference_cohort import make_cohort

    cohort = make_cohort(seed=args.seed)
    paths = cohort.write(args.out)
    print(f"{len(cohort.participants)} participants, {len(cohort.events)} events -> " + ", ".join(map(str, paths)))
    return 0


def _reproduce(args: argparse.Namespace) -> int:
    """Exit code 1 when a published value is missed."""
    from analysis.paper.reproduction import reproduce_files

    table = reproduce_files(args.responses, args.out, n_boot=args.n_boot, seed=args.seed)
    counts = table["status"].value_counts()
    print(", ".join(f"{k}: {v}" for k, v in counts.items()) + f" -> {args.out}/reproduction.csv, reproduction.md")
    return 1 if (table["status"] == "miss").any() else 0


def register(cli) -> None:
    """Declare the `paper` group."""
    g = cli.group("paper", "the paper's published values: audit, reconstruction, reproduction")
    p = g.command("audit", "check the published statistics for internal consistency (audit.csv, audit.md)", _audit)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p = g.command("reconstruct", "generate the reconstructed survey dataset (survey CSV of docs/contracts.md)", _reconstruct)
    p.add_argument("--out", required=True, metavar="CSV", help="output survey CSV")
    p.add_argument("--seed", type=int, default=20240, help="random seed (default 20240)")
    p = g.command("cohort", "generate the reference cohort (participants.csv, events.csv)", _cohort)
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--seed", type=int, default=20240, help="random seed (default 20240)")
    p = g.command("reproduce", "compare our analysis of a survey CSV with Tables 3-5 (reproduction.csv/.md)",
                  _reproduce)
    p.add_argument("--responses", default=None, metavar="CSV",
                   help="survey CSV (default: the reconstructed data/reference/survey.csv)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--n-boot", type=int, default=2000, help="bootstrap resamples for the CIs (default 2000)")
    p.add_argument("--seed", type=int, default=1, help="bootstrap seed (default 1)")
