"""Experiment management for pEDAS driving-simulator studies: the DuckDB store, participants, protocol,
exclusions, drive logs, the survey instrument and its web form, import/export, scheduling."""

import pedas  # noqa: E402,F401  (first: pins numpy's SIMD dispatch before numpy loads, see pedas/__init__.py)
