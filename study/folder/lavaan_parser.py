"""semopy's lavaan line parser (``semopy.parser``: ``separate_token``, ``parse_rvalues``) without importing the
semopy package.

The model file of a study is read by semopy's own parser (:func:`study.folder.definition.parse_model`). ``import
semopy.parser`` first runs the package's ``__init__``, which imports the whole of semopy (sympy, scikit-learn: about
a second); the parser module itself needs only ``re`` and ``collections``. So, unless semopy is already imported
(then its module is used), the same file, ``semopy/parser.py``, is executed as a module of its own: the same code,
hence the same acceptance of every line, for the commands that check a model but fit nothing (``plan power``).
"""
from __future__ import annotations

import importlib.util
import sys
from functools import lru_cache
from pathlib import Path
from types import ModuleType

#: the name the standalone copy of semopy/parser.py is loaded under (not semopy.parser: semopy's own import of it
#: must not be affected)
STANDALONE = "study._semopy_parser"


@lru_cache(maxsize=1)
def _standalone() -> ModuleType:
    spec = importlib.util.find_spec("semopy")  # a top-level name: found without running semopy/__init__.py
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError("semopy is not installed (it reads the model file)")
    path = Path(next(iter(spec.submodule_search_locations))) / "parser.py"
    loader_spec = importlib.util.spec_from_file_location(STANDALONE, path)
    module = importlib.util.module_from_spec(loader_spec)
    sys.modules[STANDALONE] = module  # as an import would: the module is found by its name
    loader_spec.loader.exec_module(module)
    return module


def parser() -> ModuleType:
    """semopy's parser module: ``semopy.parser`` when semopy is imported already, else the standalone copy of its
    file (module docstring)."""
    return sys.modules.get("semopy.parser") or _standalone()
