"""Checks of a study's declared files that the modules owning those files register (log mapping, route, [drives],
[export], KPIs), and running them all when a study is checked.

A module that owns a declared file or table calls :func:`register_file_check` when it is imported. The study
definition depends only on this registry, not on those modules: :func:`run_file_checks` imports them by name
(:data:`CHECK_MODULES`) so that a direct ``load`` checks every declared file as the CLI does.

A check that reads units (log mapping, route) registers with ``units=True``: it builds pint's unit registry (about
half a second with pint's import). A command that reads neither drive logs nor the route (``analyze``, ``plan
power``) may run the other checks only (``run_file_checks(..., units=False)``); ``study check`` and ``init`` run
them all.
"""
from __future__ import annotations

import importlib
from typing import Any

#: extra checks registered by modules that own a declared file (log mapping, route, KPIs): f(study, problems)
_FILE_CHECKS: list = []
#: the registered checks that read units with pint (skipped by run_file_checks(..., units=False))
_UNIT_CHECKS: set = set()
#: the modules that register them, imported by name before every check so that a direct `load` checks every declared
#: file as the CLI does
CHECK_MODULES = ("study.folder.logmap", "study.folder.route_file", "study.logs.importing", "study.export.writer",
                 "study.folder.kpi_spec", "study.folder.scores", "study.folder.within_spec")


def register_file_check(fn, units: bool = False) -> Any:
    """Register ``fn(study, problems)`` to be run by every parse (problems.add(file, line, field, message)); a
    function registered twice runs once. `units`: the check reads units (pint's unit registry)."""
    if fn not in _FILE_CHECKS:
        _FILE_CHECKS.append(fn)
    if units:
        _UNIT_CHECKS.add(fn)
    return fn


def run_file_checks(study, problems, units: bool = True) -> None:
    """Import every module of :data:`CHECK_MODULES` (each registers the check of the file or table it owns), then
    run every registered check on `study`, adding to `problems`; without `units`, not the checks that read units
    (for a command that uses neither the log mapping nor the route)."""
    for module in CHECK_MODULES:
        importlib.import_module(module)

    for hook in _FILE_CHECKS:
        if units or hook not in _UNIT_CHECKS:
            hook(study, problems)
