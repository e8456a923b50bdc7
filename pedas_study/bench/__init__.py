"""Benchmarks, one module per thing timed, each against a peer in the same process where there is one:
`mpc` (controller step vs cvxpy), `drive` (simulated drives, cohort speed-up), `robustness` (a sweep of drives,
failures by kind), `kpi` (drive KPIs in DuckDB vs pandas), `survey` (the acceptance statistics, the bootstrap vs
statsmodels), `store_import` (drive-log import vs a plain DuckDB load), `store_export` (time and peak memory of
exports and of a large drive import, each in its own process, vs plain DuckDB). The CLI runs them as
``pedas-study bench``."""
