"""The paper's study as data: its published values, GRIM/GRIMMER, the consistency audit (with which extraction made
Table 3's loadings and whether SPSS's bootstrap printed Table 5's CIs), the reconstructed survey, the reference cohort,
the paper-shaped synthetic answers and the reproduction comparison (docs/paper_reproduction.md)."""
from analysis._exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, __path__, {
    "published": ("PAPER_STUDY_DIR", "paper_study", "load_published", "value"),
    "grim": ("grim_consistent", "grimmer_consistent"),
    "audit": ("run_audit", "findings", "write_audit"),
    "procedure": ("feasibility", "feasibility_table"),
    "bootstrap_check": ("check_printed_cis",),
    "reconstruct": ("N_IMPLIED",),
    "reference_cohort": ("Cohort", "make_cohort", "load_into_store"),
    "synthetic": ("simulate_paper_responses",),
    "reproduction": ("reproduce", "reproduce_files"),
})
