"""The top layer of pedas-study: the `pedas-study` command line (`pedas_study.cli`) and the benchmarks
(`pedas_study.bench`). It may import `analysis`, `study` and `pedas`; none of them imports it."""

import pedas  # noqa: F401  (first: pins numpy's SIMD dispatch before numpy loads, see pedas/__init__.py)
