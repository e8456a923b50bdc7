"""`pedas-study participant add | list`: register and list participants."""
from __future__ import annotations

from pedas_study.cli.common import add_format_option, format_frame, open_store


def _add(args) -> None:
    from study.participants import add_participant

    with open_store(args) as st:
        row = add_participant(st, args.id, age=args.age, gender=args.gender, license_years=args.license_years,
                              style=args.style, eco_familiarity=args.eco_familiarity, protocol=args.protocol)
    print(f"participant {row['participant_id']} added")


def _list(args) -> None:
    from study.participants import list_participants

    with open_store(args) as st:
        print(format_frame(list_participants(st), args.format))


def register(cli) -> None:
    """Declare the `participant` group."""
    from pedas.vocabulary import STYLES
    from study.participants import GENDERS

    g = cli.group("participant", "register and list participants")
    p = g.command("add", "register a participant (pseudonymous ID such as P001)", _add)
    p.add_argument("id", metavar="ID")
    p.add_argument("--age", type=int)
    p.add_argument("--gender", choices=GENDERS)
    p.add_argument("--license-years", type=int, dest="license_years")
    p.add_argument("--style", choices=STYLES, help="self-reported driving style")
    p.add_argument("--eco-familiarity", type=int, choices=range(1, 6), dest="eco_familiarity",
                   metavar="1-5", help="1 never heard of eco-driving ... 5 uses a similar system regularly")
    p.add_argument("--protocol", default=None, help="protocol file name (default paper_v1)")
    p = g.command("list", "list participants with protocol position and exclusions", _list)
    add_format_option(p)
