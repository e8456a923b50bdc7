"""Analysis of driving-simulator studies, in rooms (docs/architecture.md, "analysis/ in rooms"):
``survey`` (acceptance statistics), ``drives`` (drive KPIs), ``report`` (the report's pipeline and document),
``sweep`` (the what-if sweep), ``paper`` (the paper's study as data); ``render`` writes tables and figures for all."""

import pedas  # noqa: E402,F401  (first: pins numpy's SIMD dispatch before numpy loads, see pedas/__init__.py)
