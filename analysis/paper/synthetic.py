"""Synthetic answers shaped like the paper's survey, for tests and benchmarks of the generic analysis.

A six-factor population (the paper's constructs, latent correlations loosely shaped like its Table 4), loadings 0.8,
discretised to the 1-5 scale with cut points that centre answers around 4 of 5 like the paper's item means; PEoU3
is generated negatively keyed (raw, as a participant ticks it) and ATT1-ATT5 lean on PU, so the data carry the
structure the paper's item deletions respond to. A test fixture, not a reconstruction of the paper's data (that is
:mod:`analysis.paper.reconstruct`).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.paper.published import paper_study
from analysis.survey.testing import simulate_study_responses

FACTORS = ("PU", "PEoU", "ATT", "PBC", "SN", "BI")
# Latent correlations loosely shaped like the paper's Table 4.
PHI = pd.DataFrame([
    [1.00, 0.45, 0.75, 0.38, 0.49, 0.62],
    [0.45, 1.00, 0.33, 0.55, 0.00, 0.31],
    [0.75, 0.33, 1.00, 0.11, 0.46, 0.40],
    [0.38, 0.55, 0.11, 1.00, 0.00, 0.50],
    [0.49, 0.00, 0.46, 0.00, 1.00, 0.35],
    [0.62, 0.31, 0.40, 0.50, 0.35, 1.00],
], index=FACTORS, columns=FACTORS)
# ATT1-ATT5 share variance with PU (the paper: they "were highly correlating with the items of PU")
SIGNALS = {f"ATT{k}": {"ATT": 0.5, "PU": 0.6} for k in range(1, 6)}
THRESHOLDS = np.array([-1.8, -1.0, -0.2, 0.9])


def simulate_paper_responses(n: int = 40, seed: int = 1, loading: float = 0.8) -> pd.DataFrame:
    """Wide survey frame (participant_id P001.. + every scaled item of the paper's codebook, raw 1-5) of `n`
    synthetic participants (:func:`analysis.survey.testing.simulate_study_responses` with the module's population)."""
    return simulate_study_responses(paper_study(), n, seed, loading=loading, phi=PHI, signals=SIGNALS,
                                    thresholds=THRESHOLDS)
