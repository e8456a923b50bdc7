"""The report: the incremental pipeline that regenerates every table and figure of a study's store, the study-level
figures, the HTML document (`index.html`) and the submission bundle (docs/report.md)."""
from analysis._exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, __path__, {
    "build": ("ReportConfig", "ReportResult", "run_report"),
    "pipeline": ("Pipeline", "Step", "StepResult", "StepFailed"),
    "document": ("render_document",),
    "figures": ("participant_flow", "plot_participant_flow", "plot_likert"),
    "bundle": ("write_bundle",),
})
