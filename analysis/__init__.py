"""Analysis of pEDAS studies: objective KPIs, acceptance statistics (CFA, reliability, validity, hierarchical
regressions, H1-H7), the paper's published values with their audit and reconstruction, tables, figures, report."""

import pedas  # noqa: E402,F401  (first: pins numpy's SIMD dispatch before numpy loads, see pedas/__init__.py)
