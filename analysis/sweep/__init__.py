"""The what-if sweep: its design (factors, Morris and Sobol samples, the reduced cohort), its run (every design
point's drives and KPIs) and what its points say (sensitivity indices, band shares, the region where the bands hold;
docs/sweep.md)."""
from analysis._exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, __path__, {
    "design": ("SweepSpec", "parse_factors", "morris_design", "sobol_design"),
    "run": ("run_sweep", "read_run"),
    "sensitivity": ("morris_indices", "sobol_indices", "region", "write_analysis"),
})
