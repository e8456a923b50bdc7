"""`pedas-study exclude`: exclude a participant from analyses, or withdraw the exclusion."""
from __future__ import annotations

from pedas_study.cli.common import open_store
from study.common.errors import UserError


def _exclude(args) -> None:
    from study.people.exclusions import REASONS, exclude, revoke

    if not args.revoke and not args.reason:  # refused before the store is opened
        raise UserError(f"--reason is required ({'|'.join(REASONS)})")
    with open_store(args) as st:
        if args.revoke:
            revoke(st, args.id, args.scope)
        else:
            exclude(st, args.id, args.scope, args.reason, note=args.note)
    print(f"{args.id}: exclusion ({args.scope}) revoked" if args.revoke else
          f"{args.id}: excluded ({args.scope}, {args.reason})")


def register(cli) -> None:
    """Declare `exclude`."""
    from study.people.exclusions import REASONS, SCOPES

    p = cli.command("exclude", "exclude a participant from analyses (scope all|objective|subjective)", _exclude)
    p.add_argument("id", metavar="ID")
    p.add_argument("--scope", choices=SCOPES, required=True,
                   help="all: no data used; objective: drive KPIs not used; subjective: survey not used")
    p.add_argument("--reason", choices=REASONS)
    p.add_argument("--note", default=None)
    p.add_argument("--revoke", action="store_true", help="withdraw the exclusion with this scope")
