"""`pedas-study init`: create the study store or upgrade its schema."""
from __future__ import annotations

from pedas_study.cli.common import db_path, open_store


def _init(args) -> None:
    existed = db_path(args).exists()
    with open_store(args, must_exist=False) as st:
        what = "created" if not existed else "upgraded" if st.applied else "up to date"
        print(f"store {st.path} {what} (schema v{st.schema_version})")


def register(cli) -> None:
    """Declare `init`."""
    cli.command("init", "create the study store (or upgrade its schema)", _init)
