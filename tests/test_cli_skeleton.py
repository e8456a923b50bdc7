"""The CLI framework itself: help works, errors are one line and non-zero."""
from study.cli import COMMAND_MODULES, build_parser


def test_every_command_module_registers():
    parser = build_parser()
    assert parser.prog == "pedas-study"
    assert len(COMMAND_MODULES) == len(set(COMMAND_MODULES))


def test_unknown_command_is_usage_error(cli):
    r = cli("no-such-command")
    assert r.code == 2
