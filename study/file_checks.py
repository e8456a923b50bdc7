"""Checks of a study's declared files that the modules owning those files register (log mapping, route, [drives],
[export], KPIs), and running them all when a study is checked.

A module that owns a declared file or table calls :func:`register_file_check` when it is imported. The study
definition depends only on this registry, not on those modules: :func:`run_file_checks` imports them by name
(:data:`CHECK_MODULES`) so that a direct ``load`` checks every declared file as the CLI does.
"""
from __future__ import annotations

import importlib
from typing import Any

#: extra checks registered by modules that own a declared file (log mapping, route, KPIs): f(study, problems)
_FILE_CHECKS: list = []
#: the modules that register them, imported by name before every check so that a direct `load` checks every declared
#: file as the CLI does
CHECK_MODULES = ("study.logmap", "study.route_file", "study.drives", "study.export", "study.kpi_spec",
                 "study.scores", "study.within_spec")


def register_file_check(fn) -> Any:
    """Register ``fn(study, problems)`` to be run by every parse (problems.add(file, line, field, message)); a
    function registered twice runs once."""
    if fn not in _FILE_CHECKS:
        _FILE_CHECKS.append(fn)
    return fn


def run_file_checks(study, problems) -> None:
    """Import every module of :data:`CHECK_MODULES` (each registers the check of the file or table it owns), then
    run every registered check on `study`, adding to `problems`."""
    for module in CHECK_MODULES:
        importlib.import_module(module)

    for hook in _FILE_CHECKS:
        hook(study, problems)
