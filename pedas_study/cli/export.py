"""`pedas-study export`: every table as CSV, Parquet or SPSS .sav."""
from __future__ import annotations

from pedas_study.cli.common import open_store


def _export(args) -> None:
    from study.export.writer import export

    # what the writers load, loaded before the store is held: pyreadstat and the route file's reader (a study's route
    # names the segments a .sav labels), pyarrow's Parquet writer
    if args.format == "sav":
        import pyreadstat  # noqa: F401
        import study.folder.route_file  # noqa: F401
    elif args.format == "parquet":
        import pyarrow.parquet  # noqa: F401
    with open_store(args) as st:
        r = export(st, args.format, args.outdir, deidentify=args.deidentify)
    total = sum(r.files.values())
    left = f"; left out: {', '.join(r.skipped)}" if r.skipped else ""
    print(f"exported {len(r.files)} files ({total} rows) to {r.outdir}{left}")


def register(cli) -> None:
    """Declare `export`."""
    p = cli.command("export", "export every table as CSV, Parquet or SPSS .sav", _export)
    p.add_argument("format", choices=("csv", "parquet", "sav"))
    p.add_argument("outdir", metavar="OUTDIR")
    p.add_argument("--deidentify", action="store_true",
                   help="attributes as the bands study.toml declares ([export.bands]); times as seconds after the "
                        "participant's first event; no notes, names, file names or free text; no audit log")
