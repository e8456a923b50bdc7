"""The import rules of docs/architecture.md, read from the source: no two modules import each other and there is no
import cycle (imports inside functions count), the parts import one way (pedas_study -> analysis -> study -> pedas),
and the rooms of analysis/ and the packages of study/ import each other only downwards."""
from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PARTS = ("pedas", "study", "analysis", "pedas_study")   # each may import only the ones before it
ROOMS = ("analysis.apa", "analysis.ranks", "analysis.render", "analysis.survey", "analysis.paper", "analysis.drives",
         "analysis.within", "analysis.sweep", "analysis.report")                              # docs/architecture.md, "Code layout": downwards only
STUDY_ROOMS = ("study.common", "study.folder", "study.store", "study.people", "study.logs", "study.survey",
               "study.export", "study.webapp")                                  # the same, for study/


def _modules(root: Path) -> dict[str, Path]:
    out = {}
    for part in PARTS:
        for f in (root / part).rglob("*.py"):
            name = ".".join(f.relative_to(root).with_suffix("").parts)
            out[name.removesuffix(".__init__")] = f
    return out


def _imported(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Project modules that `name` imports anywhere in its source (a package import counts as its __init__)."""
    out = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parent, *([base] if base else [])])
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in modules:
                t = t.rpartition(".")[0]
            # a module's own package (its __init__) is imported by Python anyway: not an edge of the graph
            if t and t != name and not name.startswith(t + "."):
                out.add(t)
    return out


def import_graph(root: Path = REPO) -> dict[str, set[str]]:
    modules = _modules(root)
    return {name: _imported(name, path, modules) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def _room(module: str, rooms: tuple[str, ...] = ROOMS) -> str | None:
    return next((r for r in rooms if module == r or module.startswith(r + ".")), None)


@pytest.fixture(scope="module")
def graph():
    return import_graph()


def test_cycle_finder_finds_a_planted_cycle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e2"}, "e2": {"e"}}
    assert sorted(cycles(g)) == [["a", "b", "c"], ["e", "e2"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles(graph):
    mutual = sorted({tuple(sorted((a, b))) for a in graph for b in graph[a] if a in graph[b]})
    assert mutual == [], f"modules that import each other: {mutual}"
    assert cycles(graph) == []


def test_parts_import_one_way(graph):
    rank = {p: i for i, p in enumerate(PARTS)}
    against = [(a, b) for a in graph for b in graph[a] if rank[b.split(".")[0]] > rank[a.split(".")[0]]]
    assert against == [], f"imports against pedas_study -> analysis -> study -> pedas: {against}"
    # the study loader imports the modules that check a study's files by name: those are study's own
    from study.common.file_checks import CHECK_MODULES

    assert all(m.split(".")[0] == "study" and m in graph for m in CHECK_MODULES), CHECK_MODULES


def test_analysis_rooms_import_downwards(graph):
    rank = {r: i for i, r in enumerate(ROOMS)}
    against = [(a, b) for a in graph for b in graph[a]
               if _room(a) and _room(b) and rank[_room(b)] > rank[_room(a)]]
    assert against == [], f"analysis rooms importing upwards: {against}"
    loose = sorted(m for m in graph if m.startswith("analysis.") and _room(m) is None and m != "analysis._exports")
    assert loose == [], f"analysis modules outside a room: {loose}"


def test_study_packages_import_downwards(graph):
    rank = {r: i for i, r in enumerate(STUDY_ROOMS)}
    room = lambda m: _room(m, STUDY_ROOMS)  # noqa: E731
    against = [(a, b) for a in graph for b in graph[a] if room(a) and room(b) and rank[room(b)] > rank[room(a)]]
    assert against == [], f"study packages importing upwards: {against}"
    loose = sorted(m for m in graph if m.startswith("study.") and room(m) is None)
    assert loose == [], f"study modules outside a package: {loose}"
    for pkg in STUDY_ROOMS:  # each package says what it owns and what it may import
        doc = (importlib.import_module(pkg).__doc__ or "").strip()
        assert "Import" in doc or "import" in doc, pkg


def test_rooms_export_their_public_names_lazily():
    import importlib
    import subprocess
    import sys

    for room in [r for r in ROOMS if r not in ("analysis.apa", "analysis.ranks", "analysis.render")]:   # packages, not modules
        pkg = importlib.import_module(room)
        assert pkg.__all__, room
        for name in pkg.__all__:
            assert getattr(pkg, name) is not None, f"{room}.{name}"
    # importing a room (or one module of it) loads none of the room's other modules
    code = ("import sys, analysis.survey, analysis.drives.scenario_comparison; "
            "print(sorted(m for m in sys.modules if m.startswith(('analysis.survey.', 'analysis.drives.'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert out.stdout.strip() == "['analysis.drives.scenario_comparison']"
