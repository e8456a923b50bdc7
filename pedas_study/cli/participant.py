"""`pedas-study participant add | import | list | completeness`: register (one, or a roster) and list participants of
the store's study, and what data each still lacks."""
from __future__ import annotations

from pedas_study.cli.bulk import add_ignore_option
from pedas_study.cli.common import add_format_option, format_frame, open_store
from study.common.errors import UserError

#: options kept from the paper's fixed demographics; each names the study attribute it fills
ALIASES = (("age", "--age"), ("gender", "--gender"), ("license_years", "--license-years"), ("style", "--style"),
           ("eco_familiarity", "--eco-familiarity"))


def attributes_of(args) -> dict[str, str]:
    """{attribute: raw text} from ``--attr NAME=VALUE`` (repeatable) and the alias options."""
    out: dict[str, str] = {}
    for item in args.attr or []:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise UserError(f"--attr {item!r}: use NAME=VALUE, e.g. --attr age=30")
        if name in out:
            raise UserError(f"attribute {name} given twice")
        out[name] = value
    for name, option in ALIASES:
        value = getattr(args, name, None)
        if value is None:
            continue
        if name in out:
            raise UserError(f"attribute {name} given twice ({option} and --attr)")
        out[name] = value
    return out


def _add(args) -> None:
    from study.people.participants import add_participant
    from study.store.studies import definition

    with open_store(args) as st:
        study = definition(st)
        for name, option in ALIASES:  # an alias of an attribute this study does not declare is bad input
            if getattr(args, name, None) is not None and name not in {a.name for a in study.attributes}:
                raise UserError(f"{option}: study {study.study_id} has no attribute {name} (attributes: "
                                f"{', '.join(a.name for a in study.attributes) or 'none'})")
        row = add_participant(st, args.id, attributes_of(args), protocol=args.protocol)
    print(f"participant {row['participant_id']} added (protocol {row['protocol']})")


def _import(args) -> int | None:
    from pedas_study.cli.bulk import apply_file
    from study.people.participants import import_roster

    return apply_file(args, "roster", import_roster, lambda n: f"registered {n} participants from {args.roster}")


def _list(args) -> None:
    from pedas_study.cli.rows_text import format_rows
    from study.people.participants import participant_rows

    with open_store(args) as st:  # rows, not a DataFrame: a listing loads no pandas (tests/cli/test_cli_imports.py)
        columns, rows = participant_rows(st)
    print(format_rows(columns, rows, args.format))  # formatted after closing: the store is held only while read


def _completeness(args) -> None:
    from study.survey.completeness import completeness

    with open_store(args, read_only=True) as st:
        df = completeness(st, args.instrument)
    print(format_frame(df, args.format))


def register(cli) -> None:
    """Declare the `participant` group."""
    g = cli.group("participant", "register and list participants")
    p = g.command("add", "register a participant (a pseudonymous id matching the study's id pattern)", _add)
    p.add_argument("id", metavar="ID")
    p.add_argument("--attr", action="append", metavar="NAME=VALUE",
                   help="a participant attribute the study declares (repeatable), e.g. --attr age=30")
    p.add_argument("--protocol", default=None, help="one of the study's protocols (default: the first declared)")
    # the paper's demographics as options; each is an attribute of that name, refused by studies without it
    p.add_argument("--age", help="same as --attr age=AGE")
    p.add_argument("--gender", help="same as --attr gender=GENDER")
    p.add_argument("--license-years", dest="license_years", help="same as --attr license_years=N")
    p.add_argument("--style", help="same as --attr style=STYLE (self-reported driving style)")
    p.add_argument("--eco-familiarity", dest="eco_familiarity", metavar="N",
                   help="same as --attr eco_familiarity=N")
    p = g.command("import", "register the participants of a roster CSV, all or nothing (participant_id, the "
                            "study's attribute columns, optionally protocol and order)", _import)
    p.add_argument("roster", metavar="ROSTER.csv")
    add_ignore_option(p)
    p = g.command("list", "list participants with their attributes, protocol position and exclusions", _list)
    add_format_option(p)
    p = g.command("completeness", "per participant: the protocol phases, drives and survey answers still missing",
                  _completeness)
    p.add_argument("--instrument", default=None, help="instrument name (default: the study's instrument)")
    add_format_option(p)
