"""A small incremental pipeline: named steps whose results are reused while the hash of their inputs is unchanged.

A step declares its inputs (files, folders, free-form strings such as parameters, and callables giving a string when
the step is reached) and its outputs. Before running it the runner hashes the inputs (file bytes, folders recursively,
strings) together with the hashes of the steps it depends on; when the hash equals the one recorded after its last
successful run and every output still exists, the step is skipped.
A failing step names itself, leaves the outputs of earlier steps untouched and stops the run.
"""
from __future__ import annotations

import hashlib
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Sequence

_SKIP_PARTS = {"__pycache__", ".pytest_cache", "build"}


def hash_inputs(items: Iterable[Path | str | Callable[[], str]]) -> str:
    """sha256 over files (path + bytes), folders (recursively, sorted), plain strings, and the strings callables
    return when the step is reached (a digest of data an earlier step wrote, e.g. a part of the store)."""
    h = hashlib.sha256()
    for item in items:
        if callable(item):
            h.update(f"value:{item()}".encode())
        elif isinstance(item, Path):
            paths = [item] if item.is_file() else sorted(
                p for p in item.rglob("*") if p.is_file() and not _SKIP_PARTS.intersection(p.parts)
                and p.suffix not in {".pyc"}) if item.exists() else []
            h.update(f"path:{item.name}:{len(paths)}".encode())
            for p in paths:
                h.update(p.name.encode())
                h.update(p.read_bytes())
        else:
            h.update(f"str:{item}".encode())
    return h.hexdigest()


@dataclass
class Step:
    """One unit of the report. `run()` produces `outputs` (files or folders)."""

    name: str
    run: Callable[[], object]
    inputs: Sequence[Path | str | Callable[[], str]] = ()
    outputs: Sequence[Path] = ()
    after: Sequence[str] = ()
    always: bool = False  # rerun every time (cheap steps that read everything, e.g. the index)


@dataclass
class StepResult:
    name: str
    status: str  # ran | cached | failed
    seconds: float
    message: str = ""


@dataclass
class Pipeline:
    cache_dir: Path
    steps: list[Step] = field(default_factory=list)
    log: Callable[[str], None] = lambda msg: print(msg, file=sys.stderr, flush=True)

    def add(self, step: Step) -> Step:
        self.steps.append(step)
        return step

    def _state_file(self, name: str) -> Path:
        return self.cache_dir / f"{name}.json"

    def run(self, force: bool = False) -> list[StepResult]:
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        digests: dict[str, str] = {}
        results: list[StepResult] = []
        total = len(self.steps)
        for i, step in enumerate(self.steps, 1):
            digest = hash_inputs([*step.inputs, *(f"after:{a}:{digests[a]}" for a in step.after)])
            digests[step.name] = digest
            state = self._state_file(step.name)
            recorded = json.loads(state.read_text()).get("digest") if state.exists() else None
            fresh = recorded == digest and all(p.exists() for p in step.outputs)
            if fresh and not force and not step.always:
                results.append(StepResult(step.name, "cached", 0.0))
                self.log(f"[{i}/{total}] {step.name}: up to date")
                continue
            self.log(f"[{i}/{total}] {step.name} ...")
            t0 = time.perf_counter()
            try:
                step.run()
            except Exception as exc:
                dt = time.perf_counter() - t0
                state.unlink(missing_ok=True)
                results.append(StepResult(step.name, "failed", dt, str(exc)))
                raise StepFailed(step.name, exc) from exc
            dt = time.perf_counter() - t0
            state.write_text(json.dumps({"digest": digest, "seconds": round(dt, 3)}))
            results.append(StepResult(step.name, "ran", dt))
            self.log(f"[{i}/{total}] {step.name}: done in {dt:.1f} s")
        return results


class StepFailed(RuntimeError):
    def __init__(self, step: str, exc: BaseException) -> None:
        super().__init__(f"report step '{step}' failed: {' '.join(str(exc).split()) or type(exc).__name__}")
        self.step = step
