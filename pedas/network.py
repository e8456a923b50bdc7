"""Build the study route's SUMO network (`.net.xml`) of a scenario (:mod:`pedas.scenario`) from the plain-XML
sources in `data/network/`.

The network is never committed: :func:`build_network` runs ``netconvert`` of the installed ``eclipse-sumo`` wheel on
first use and caches the result under ``NETWORK_BUILD_DIR`` by a hash of the sources (and the netconvert version), so
editing a source file triggers a rebuild and an unchanged checkout reuses the file. Concurrent first use from several
worker processes is safe: builders serialise on a file lock and the file appears by an atomic rename.
"""
from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from pedas.paths import NETWORK_BUILD_DIR

CONFIG = "study.netccfg"
SOURCES = ("study.nod.xml", "study.edg.xml", "study.con.xml", "study.tll.xml", CONFIG)  # the single-lane layout
# traffic inputs of the single-lane scenario used at run time (not by netconvert)
ROUTES = "study.rou.xml"
VTYPES = "vtypes.add.xml"


def sumo_home() -> Path:
    """The SUMO installation of the `eclipse-sumo` wheel (``sumo.SUMO_HOME``), else ``$SUMO_HOME``."""
    try:
        import sumo  # the eclipse-sumo wheel

        return Path(sumo.SUMO_HOME)
    except ImportError:  # pragma: no cover - a system SUMO instead of the wheel
        home = os.environ.get("SUMO_HOME")
        if not home:
            raise FileNotFoundError("SUMO not found: install eclipse-sumo or set SUMO_HOME")
        return Path(home)


def binary(name: str) -> Path:
    """Path of a SUMO tool (``netconvert``, ``sumo``) of the installation found by :func:`sumo_home`."""
    path = sumo_home() / "bin" / name
    if not path.exists():
        found = shutil.which(name)
        if not found:
            raise FileNotFoundError(f"SUMO binary {name!r} not found under {sumo_home()}")
        path = Path(found)
    return path


def _sources(source_dir: Path | None, scenario) -> tuple[Path, tuple[Path, ...]]:
    """(netconvert configuration, every netconvert input): the study.* files of `source_dir` (a copy of the
    single-lane sources), else those of the scenario."""
    if source_dir is not None:
        # in the scenario's order (configuration first, then its inputs), so that a copy hashes like the original
        return Path(source_dir) / CONFIG, tuple(Path(source_dir) / name for name in (CONFIG, *SOURCES[:-1]))
    from pedas.scenario import get_scenario

    sc = get_scenario(scenario)
    return sc.netccfg, sc.sources


def source_hash(source_dir: Path | None = None, scenario=None) -> str:
    """SHA-256 over the netconvert inputs (of `source_dir`'s study.* files, else of the scenario, default
    :data:`pedas.scenario.DEFAULT_SCENARIO`) and the SUMO version (hex, first 16 characters)."""
    h = hashlib.sha256()
    for path in _sources(source_dir, scenario)[1]:
        h.update(path.name.encode())
        h.update(path.read_bytes())
    try:
        from importlib.metadata import version

        h.update(version("eclipse-sumo").encode())
    except Exception:  # pragma: no cover
        pass
    return h.hexdigest()[:16]


def build_network(source_dir: Path | None = None, build_dir: Path | None = None, force: bool = False,
                  scenario=None) -> Path:
    """Path of the built `.net.xml`, running netconvert when no build for the current sources exists.

    `scenario`: name or :class:`pedas.scenario.Scenario` (default :data:`pedas.scenario.DEFAULT_SCENARIO`);
    `source_dir`: instead, a folder with the single-lane layout's study.* files. `build_dir` defaults to
    ``NETWORK_BUILD_DIR``. `force` rebuilds even if cached. The file is named after the scenario and the hash.
    """
    config, sources = _sources(source_dir, scenario)
    build_dir = Path(build_dir or NETWORK_BUILD_DIR)
    for path in sources:
        if not path.exists():
            raise FileNotFoundError(f"network source missing: {path}")
    from pedas.scenario import get_scenario

    prefix = "study" if source_dir is not None else get_scenario(scenario).name
    target = build_dir / f"{prefix}-{source_hash(source_dir, scenario)}.net.xml"
    if target.exists() and not force:
        return target
    build_dir.mkdir(parents=True, exist_ok=True)
    with open(build_dir / ".build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if target.exists() and not force:  # another process built it while we waited
            return target
        fd, tmp = tempfile.mkstemp(prefix=".netconvert-", suffix=".net.xml", dir=build_dir)
        os.close(fd)
        try:
            proc = subprocess.run(
                [str(binary("netconvert")), "-c", str(config), "-o", tmp, "--no-warnings", "true"],
                capture_output=True, text=True, env={**os.environ, "SUMO_HOME": str(sumo_home())},
            )
            if proc.returncode != 0:
                msg = (proc.stderr or proc.stdout).strip().splitlines()
                raise RuntimeError(f"netconvert failed: {msg[-1] if msg else proc.returncode}")
            os.replace(tmp, target)  # atomic: readers see the old state or the complete file
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return target
