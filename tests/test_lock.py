"""requirements.lock agrees with pyproject.toml: each dependency (runtime + every extra) is pinned inside its range."""
from __future__ import annotations

import functools
import tomllib
from pathlib import Path

import pytest

try:
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name
    from packaging.version import Version
except ImportError:  # pragma: no cover - packaging is in the lock; pip's vendored copy only as a last resort
    from pip._vendor.packaging.requirements import Requirement
    from pip._vendor.packaging.utils import canonicalize_name
    from pip._vendor.packaging.version import Version

REPO = Path(__file__).resolve().parents[1]
LOCK = REPO / "requirements.lock"
# the lock's target (`make lock`): CPython 3.11 on x86-64 Linux
TARGET = {
    "python_version": "3.11", "python_full_version": "3.11.0", "implementation_name": "cpython",
    "platform_python_implementation": "CPython", "sys_platform": "linux", "platform_system": "Linux",
    "platform_machine": "x86_64", "os_name": "posix", "extra": "",
}


def declared() -> list[Requirement]:
    project = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    extras = [r for group in project["optional-dependencies"].values() for r in group]
    reqs = list({str(r): r for r in map(Requirement, project["dependencies"] + extras)}.values())
    return [r for r in reqs if r.marker is None or r.marker.evaluate(TARGET)]


@functools.cache
def locked() -> dict[str, tuple[Requirement, list[str]]]:
    """name -> (pinned requirement, its hash options), read from the lock's joined continuation lines."""
    entries: dict[str, tuple[Requirement, list[str]]] = {}
    text = LOCK.read_text(encoding="utf-8").replace("\\\n", " ")
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line or line.startswith("-"):
            continue
        spec, *options = (part.strip() for part in line.split(" --"))
        req = Requirement(spec)
        name = canonicalize_name(req.name)
        assert name not in entries, f"{req.name} is locked twice"
        entries[name] = (req, [o for o in options if o.startswith("hash=")])
    return entries


def pinned_version(req: Requirement) -> Version:
    specs = list(req.specifier)
    assert len(specs) == 1 and specs[0].operator == "==", f"{req} is not pinned to one exact version"
    return Version(specs[0].version)


def test_lock_pins_every_entry_exactly_with_hashes():
    entries = locked()
    assert entries, "requirements.lock has no entries"
    for req, hashes in entries.values():
        pinned_version(req)
        assert hashes, f"{req} has no hash (the install uses --require-hashes)"


@pytest.mark.parametrize("req", declared(), ids=str)
def test_declared_dependency_is_locked_inside_its_range(req):
    entries = locked()
    name = canonicalize_name(req.name)
    if name not in entries:
        pytest.fail(f"{req.name} is in pyproject.toml but not in requirements.lock: run `make lock`")
    version = pinned_version(entries[name][0])
    assert req.specifier.contains(version, prereleases=True), (
        f"requirements.lock pins {req.name}=={version}, outside pyproject.toml's {req}: run `make lock`")


def test_project_itself_is_not_in_the_lock():
    # the project is installed editable after the lock, without resolving again
    assert "pedas-study" not in locked()
