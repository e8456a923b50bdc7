"""Build the study route's SUMO network (`.net.xml`) from the plain-XML sources in `data/network/`.

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

from pedas.paths import NETWORK_BUILD_DIR, NETWORK_DIR

CONFIG = "study.netccfg"
SOURCES = ("study.nod.xml", "study.edg.xml", "study.con.xml", "study.tll.xml", CONFIG)
# traffic inputs used at run time (not by netconvert)
ROUTES = "study.rou.xml"
VTYPES = "vtypes.add.xml"
DEMAND = "demand.json"


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


def source_hash(source_dir: Path = NETWORK_DIR) -> str:
    """SHA-256 over the netconvert inputs and the SUMO version (hex, first 16 characters)."""
    h = hashlib.sha256()
    for name in SOURCES:
        h.update(name.encode())
        h.update((Path(source_dir) / name).read_bytes())
    try:
        from importlib.metadata import version

        h.update(version("eclipse-sumo").encode())
    except Exception:  # pragma: no cover
        pass
    return h.hexdigest()[:16]


def build_network(source_dir: Path | None = None, build_dir: Path | None = None, force: bool = False) -> Path:
    """Path of the built `.net.xml`, running netconvert when no build for the current sources exists.

    `source_dir` defaults to ``NETWORK_DIR``, `build_dir` to ``NETWORK_BUILD_DIR``. `force` rebuilds even if cached.
    """
    source_dir = Path(source_dir or NETWORK_DIR)
    build_dir = Path(build_dir or NETWORK_BUILD_DIR)
    for name in SOURCES:
        if not (source_dir / name).exists():
            raise FileNotFoundError(f"network source missing: {source_dir / name}")
    target = build_dir / f"study-{source_hash(source_dir)}.net.xml"
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
                [str(binary("netconvert")), "-c", str(source_dir / CONFIG), "-o", tmp, "--no-warnings", "true"],
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
