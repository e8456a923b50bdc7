"""`pedas-study init [--study DIR [--new-version]]`: create the study store, upgrade its schema, store its study."""
from __future__ import annotations

from pedas_study.cli.common import db_path, open_store


def _init(args) -> None:
    from study.store.studies import register, version

    existed = db_path(args).exists()
    if not existed and not args.study:
        from study.common.errors import UserError

        raise UserError("a new store needs its study: pedas-study init --study DIR (e.g. studies/pedas_paper; "
                        "`pedas-study study new DIR` writes a template)")
    study = None
    if args.study:  # a folder with problems is refused before a new store is created (and checked only once)
        from study.folder.definition import load

        study = load(args.study)
    lines = []  # printed once the store is closed again
    with open_store(args, must_exist=False) as st:
        what = "created" if not existed else "upgraded" if st.applied else "up to date"
        lines.append(f"store {st.path} {what} (schema v{st.schema_version})")
        if args.study:
            done, ver = register(st, args.study, new_version=args.new_version, study=study)
            lines.append(f"study {st.one('SELECT study_id FROM study_definitions WHERE version = ?', [ver])} "
                         f"version {ver} {done}")
        elif version(st) is None:
            lines.append("the store has no study yet: run pedas-study init --study DIR")
    print("\n".join(lines))


def register(cli) -> None:
    """Declare `init`."""
    p = cli.command("init", "create the study store (or upgrade its schema) and store its study definition", _init)
    p.add_argument("--study", metavar="DIR", help="study folder to store (see docs/study_folder.md)")
    p.add_argument("--new-version", action="store_true", dest="new_version",
                   help="store a changed study as a new version while the store holds data")
