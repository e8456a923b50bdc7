"""Public names of an analysis room, declared once and loaded lazily (PEP 562).

Each room's ``__init__`` lists its public names by the module that defines them. A name's module is imported when
the name is first used, so importing a room, or one module of it, loads none of the room's other modules (the
command line stays quick; docs/architecture.md). A public name never equals a module's name: ``from
analysis.survey import cfa`` is the module, always.
"""
from __future__ import annotations

import importlib
import pkgutil


def lazy_exports(package: str, path, table: dict[str, tuple[str, ...]]):
    """(``__all__``, ``__getattr__``, ``__dir__``) of `package` (its ``__path__`` is `path`) for `table`: module
    name -> the public names it defines."""
    where = {name: module for module, names in table.items() for name in names}
    modules = {m.name for m in pkgutil.iter_modules(path)}
    if clash := sorted(set(where) & modules):
        raise ImportError(f"{package}: public name(s) {', '.join(clash)} shadow a module of the same name")
    if unknown := sorted(set(table) - modules):
        raise ImportError(f"{package}: no module(s) {', '.join(unknown)}")

    def __getattr__(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{where[name]}"), name)

    def __dir__() -> list[str]:
        return sorted(where)

    return sorted(where), __getattr__, __dir__
