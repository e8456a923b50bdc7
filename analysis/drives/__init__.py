"""Drive KPIs: the KPIs a study declares (read by :mod:`study.folder.kpi_spec`) computed from drive logs in DuckDB SQL,
savings and reproduction bands with their diagnostics, scenario comparison, the tables and figures of the objective
evaluation and the replay page (docs/kpis.md, docs/report.md)."""
from analysis._exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, __path__, {
    "kpis": ("kpis_from_frame", "kpis_from_relation", "store_kpis", "store_kpis_with_sources", "fill_acceleration"),
    "savings": ("ObjectiveResult", "objective_results", "participant_effects", "summarise", "reproduction_bands"),
    "band_diagnostics": ("why_missed", "diagnostics_markdown"),
    "scenario_comparison": ("write_comparison",),
    "tables": ("write_tables",),
    "figures": ("write_figures",),
    "replay": ("write_replay",),
    "analyze": ("analyze_drives",),
})
