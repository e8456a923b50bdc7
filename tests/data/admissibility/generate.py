"""Write the two small improper-solution data sets of tests/analysis/test_admissibility.py (README.md beside this file).

    .venv/bin/python tests/data/admissibility/generate.py

Both are 35 answers to the paper's 25 scaled items (five-point scale, studies/pedas_paper/codebook.csv) with 4 %
of the cells missing (35 of 875: three participants who stopped early, as incomplete submissions look), so the
analysis keeps 32 complete rows. The answers are a latent normal model cut at fixed thresholds:

* factors PEoU, PBC, SN exogenous (correlations .3); PU = .6 PEoU; ATT = .95 PU (+ disturbance): PU and ATT nearly
  the same construct, as in the paper's data; BI = .5 ATT + .3 PBC + .2 SN;
* item = loading x factor + unique part, loadings .75, except in ``heywood``: PBC1 = PBC exactly (loading 1,
  no unique part) and PBC2, PBC3 weak (.45): the ML estimate of PBC1's error variance falls to its bound 0;
* ``empty_category``: PU1's answer 1 is given once, by a participant who stopped early, so the complete rows do
  not use PU1's category 1.

Every draw comes from numpy's default_rng with the seed below; the files are written with "\\n" line ends.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
SEED = {"heywood": 20261126, "empty_category": 20261127}
N = 35
ITEMS = {"PU": ["PU1", "PU2", "PU3", "PU4"], "PEoU": ["PEoU1", "PEoU2", "PEoU3", "PEoU4"],
         "ATT": [f"ATT{i}" for i in range(1, 10)], "PBC": ["PBC1", "PBC2", "PBC3"], "SN": ["SN1", "SN2", "SN3"],
         "BI": ["BI1", "BI2"]}
CUTS = np.array([-1.6, -0.8, 0.0, 0.9])   # z -> answers 1..5 (shifted towards agreement, as Likert answers are)
# the three participants who stopped early: their last 12, 12 and 11 items are missing (35 cells = 4 %)
STOPPED = {32: 12, 33: 12, 34: 11}


def _factors(rng: np.random.Generator) -> dict[str, np.ndarray]:
    exo = rng.multivariate_normal(np.zeros(3), [[1, .3, .3], [.3, 1, .3], [.3, .3, 1]], size=N)
    peou, pbc, sn = exo.T
    pu = .6 * peou + np.sqrt(1 - .36) * rng.standard_normal(N)
    att = .95 * pu + np.sqrt(1 - .9025) * rng.standard_normal(N)
    bi = .5 * att + .3 * pbc + .2 * sn
    bi = bi / bi.std() * .8 + .6 * rng.standard_normal(N)
    return {"PU": pu, "PEoU": peou, "ATT": att, "PBC": pbc, "SN": sn, "BI": bi}


def _answers(kind: str) -> pd.DataFrame:
    rng = np.random.default_rng(SEED[kind])
    f = _factors(rng)
    cols = {}
    for c, items in ITEMS.items():
        z = (f[c] - f[c].mean()) / f[c].std()
        for it in items:
            lam = .75
            if kind == "heywood" and c == "PBC":
                lam = 1.0 if it == "PBC1" else .45
            x = lam * z + np.sqrt(1 - lam ** 2) * rng.standard_normal(N)
            cols[it] = 1 + np.searchsorted(CUTS, x)
    df = pd.DataFrame(cols)
    if kind == "empty_category":
        df.loc[df["PU1"] == 1, "PU1"] = 2          # nobody else ticks 1 ...
        df.loc[34, "PU1"] = 1                      # ... but the participant who stopped early
    order = [i for its in ITEMS.values() for i in its]
    df = df[order].astype("Int64")
    for row, k in STOPPED.items():
        df.loc[row, order[-k:]] = pd.NA
    df.insert(0, "participant_id", [f"B{i + 1:03d}" for i in range(N)])
    return df


def main() -> None:
    for kind in SEED:
        _answers(kind).to_csv(HERE / f"set_b_{kind}.csv", index=False, lineterminator="\n")


if __name__ == "__main__":
    main()
