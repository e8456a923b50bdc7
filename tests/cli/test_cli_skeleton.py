"""The CLI framework itself: one module per command group, help works, errors are one line with the right exit
code, only the CLI parses arguments."""
import argparse
import re
from pathlib import Path

import pytest

from pedas_study.cli import COMMAND_MODULES, Cli, build_cli, build_parser, main
from study.common.errors import UserError

REPO = Path(__file__).resolve().parents[2]
COMMANDS = ["init", "study", "participant", "session", "exclude", "drive", "export", "survey", "schedule", "simulate",
            "hud", "live", "kpi", "analyze", "paper", "report", "plan", "bench"]


def test_every_command_module_registers():
    parser = build_parser()
    assert parser.prog == "pedas-study"
    assert len(COMMAND_MODULES) == len(set(COMMAND_MODULES))


def test_each_command_is_declared_once_in_its_own_module():
    cli = build_cli()
    assert list(cli.owners) == COMMANDS
    for name, module in cli.owners.items():
        assert module == f"pedas_study.cli.{name}", name
    assert set(cli.groups) == {"study", "participant", "session", "drive", "survey", "schedule", "simulate", "kpi",
                               "analyze", "paper", "plan", "bench", "hud", "live"}


def test_a_second_declaration_is_refused():
    cli = Cli(argparse.ArgumentParser())
    cli.group("bench", "benchmarks")
    with pytest.raises(RuntimeError, match="declared twice"):
        cli.group("bench", "other help")
    with pytest.raises(RuntimeError, match="declared twice"):
        cli.command("bench", "other help")


def test_top_level_help_lists_every_command_in_order(cli, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    listed = re.findall(r"^    (\S+)", out, flags=re.M)
    assert listed == COMMANDS


@pytest.mark.parametrize("name", COMMANDS)
def test_every_command_help_works(name, capsys):
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: pedas-study {name} ")


def test_every_subcommand_help_works(capsys):
    for name, group in build_cli().groups.items():
        for sub in group.commands:
            with pytest.raises(SystemExit) as exc:
                main([name, sub, "--help"])
            assert exc.value.code == 0, (name, sub)
            assert capsys.readouterr().out.startswith(f"usage: pedas-study {name} {sub} ")


def test_unknown_command_is_usage_error(cli):
    r = cli("no-such-command")
    assert r.code == 2


def _failing_init(monkeypatch, exc: BaseException) -> None:
    import pedas_study.cli.init as init

    def handler(args):
        raise exc

    monkeypatch.setattr(init, "_init", handler)


@pytest.mark.parametrize("exc", [KeyError("no such column"), LookupError("nothing"), AttributeError("x has no y"),
                                 RuntimeError("boom")], ids=lambda e: type(e).__name__)
def test_a_bug_in_a_handler_exits_1_as_internal_error(cli, monkeypatch, exc):
    monkeypatch.delenv("PEDAS_STUDY_DEBUG", raising=False)
    _failing_init(monkeypatch, exc)
    r = cli("init")
    assert r.code == 1 and r.out == ""
    lines = r.err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith(f"pedas-study: error: internal error: {type(exc).__name__}: ")
    assert lines[0].endswith("(PEDAS_STUDY_DEBUG=1 shows the traceback)")


@pytest.mark.parametrize("exc", [UserError("unknown participant P999"), ValueError("--rows must be at least 2"),
                                 FileNotFoundError("trace file not found: x.csv")], ids=lambda e: type(e).__name__)
def test_bad_input_exits_2_with_its_message(cli, monkeypatch, exc):
    _failing_init(monkeypatch, exc)
    r = cli("init")
    assert r.code == 2 and r.out == ""
    assert r.err == f"pedas-study: error: {exc}\n"


def test_debug_shows_the_traceback(cli, monkeypatch):
    monkeypatch.setenv("PEDAS_STUDY_DEBUG", "1")
    _failing_init(monkeypatch, KeyError("no such column"))
    r = cli("init")
    assert r.code == 1
    assert "Traceback (most recent call last)" in r.err
    assert r.err.strip().splitlines()[-1] == "pedas-study: error: internal error: KeyError: 'no such column'"


def test_a_mistyped_store_is_not_created(cli, tmp_path):
    db = tmp_path / "typo.duckdb"
    for args in (("survey", "status"), ("survey", "link", "P001"), ("participant", "list")):
        r = cli(*args, db=db)
        assert r.code == 2
        assert r.err == f"pedas-study: error: no store at {db} (run `pedas-study init --study DIR` first)\n"
    assert not db.exists()


def _imports(package: str) -> list[tuple[Path, str]]:
    """(file, imported top-level module) of every import statement in a package."""
    found = []
    for path in sorted((REPO / package).rglob("*.py")):
        for m in re.finditer(r"^\s*(?:from|import)\s+([A-Za-z_][\w]*)", path.read_text(encoding="utf-8"), re.M):
            found.append((path.relative_to(REPO), m.group(1)))
    return found


@pytest.mark.parametrize("package", ["pedas", "study", "analysis", "pedas_study"])
def test_only_the_cli_parses_arguments(package):
    users = [str(f) for f, mod in _imports(package) if mod == "argparse"]
    assert all(f.startswith("pedas_study/cli/") for f in users), users


@pytest.mark.parametrize("package", ["pedas", "study", "analysis"])
def test_the_domain_packages_do_not_import_the_top_layer(package):
    assert [str(f) for f, mod in _imports(package) if mod == "pedas_study"] == []


def test_a_closed_pipe_ends_quietly(monkeypatch, capsys):
    """Output into a pipe whose reader stopped is no error: exit 0, nothing on stderr (a real pipe:
    tests/study/test_participants.py)."""
    import pedas_study.cli.init as init

    def handler(args):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(init, "_init", handler)
    assert main(["init"]) == 0
    assert capsys.readouterr().err == ""
