"""Within-subjects studies: every declared score and drive KPI compared across the conditions each participant
went through (the statistics are :func:`analysis.survey.within.compare_within`'s), the protocol orders, the
figures of individual lines and the generated methods sentences (docs/report.md, "Within-subjects studies")."""
from analysis._exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, __path__, {
    "analyze": ("WithinStudy", "analyze_within", "analyze_store_within", "methods_markdown", "result_sentence"),
    "data": ("within_data", "periods"),
    "figures": ("plot_variable",),
})
