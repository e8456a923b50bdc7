"""Hypotheses H1-H7 (paper Section 4.4) judged on the hierarchical regressions.

Each hypothesis is data (``analysis/specs/hypotheses.json``): the path, and the model/step whose coefficient the
paper reads in Section 5.2.2 (H1: model 1 step 1; H2 and H4: model 2 step 2; H3 and H5: model 3 step 2;
H6: model 4 step 2; H7: model 4 step 3). Verdict: supported when beta > 0 and p < alpha (.05).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

SPEC_DIR = Path(__file__).with_name("specs")


@dataclass(frozen=True)
class Hypothesis:
    hypothesis: str
    path: str
    predictor: str
    dv: str
    model: str
    step: int

    @classmethod
    def from_dict(cls, d: dict) -> "Hypothesis":
        try:
            return cls(hypothesis=str(d["hypothesis"]), path=str(d.get("path", f"{d['predictor']} -> {d['dv']}")),
                       predictor=str(d["predictor"]), dv=str(d["dv"]), model=str(d["model"]), step=int(d["step"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"bad hypothesis spec {d!r}: needs hypothesis, predictor, dv, model, step "
                             f"({exc})") from None


def load_hypotheses(spec=None) -> tuple[list[Hypothesis], float]:
    """Hypotheses and alpha from a spec dict, a JSON path, a list of dicts, or the shipped default when None.

    Examples
    --------
    >>> from analysis.hypotheses import load_hypotheses
    >>> hyps, alpha = load_hypotheses()                 # analysis/specs/hypotheses.json
    >>> [h.hypothesis for h in hyps], alpha
    (['H1', 'H2', 'H3', 'H4', 'H5', 'H6', 'H7'], 0.05)
    >>> hyps[0]
    Hypothesis(hypothesis='H1', path='PEoU -> PU', predictor='PEoU', dv='PU', model='1', step=1)
    """
    if spec is None:
        spec = SPEC_DIR / "hypotheses.json"
    if isinstance(spec, (str, Path)):
        spec = json.loads(Path(spec).read_text())
    if isinstance(spec, list):
        spec = {"hypotheses": spec}
    alpha = float(spec.get("alpha", 0.05))
    items = spec.get("hypotheses")
    if not isinstance(items, list):
        raise ValueError("hypotheses spec needs a list 'hypotheses'")
    return [h if isinstance(h, Hypothesis) else Hypothesis.from_dict(h) for h in items], alpha


def judge_hypotheses(regressions: pd.DataFrame, hypotheses: list[Hypothesis], alpha: float = 0.05) -> pd.DataFrame:
    """Verdicts on the hypotheses from the regression table: supported when beta > 0 and p < alpha.

    Parameters
    ----------
    regressions : DataFrame
        The hierarchical regressions (columns model, step, dv, predictor, b, se_b, beta, t, p, n).
    hypotheses : list of Hypothesis
        Each names the predictor, dv, model and step whose coefficient it reads.
    alpha : float
        Significance level, default .05 (strict: p = alpha is not significant).

    Returns
    -------
    DataFrame
        hypothesis, path, beta, p, supported, model, step, b, se_b, t, n; one row per hypothesis.

    Raises
    ------
    ValueError
        A hypothesis names a model/step/predictor the regressions do not contain, or the model's dv differs.

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.hypotheses import Hypothesis, judge_hypotheses
    >>> reg = pd.DataFrame({"model": ["1", "1"], "step": [1, 1], "dv": ["PU", "PU"],
    ...                     "predictor": ["(Constant)", "PEoU"], "b": [2.06, 0.48], "se_b": [0.73, 0.18],
    ...                     "beta": [float("nan"), 0.40], "t": [2.83, 2.70], "p": [0.008, 0.010], "n": [40, 40]})
    >>> h1 = Hypothesis("H1", "PEoU -> PU", predictor="PEoU", dv="PU", model="1", step=1)
    >>> judge_hypotheses(reg, [h1])[["hypothesis", "path", "beta", "p", "supported"]]
      hypothesis        path  beta     p  supported
    0         H1  PEoU -> PU   0.4  0.01       True
    >>> bool(judge_hypotheses(reg, [h1], alpha=0.01).loc[0, "supported"])      # p = .01 is not < .01
    False
    """
    rows = []
    for h in hypotheses:
        sel = regressions[(regressions["model"].astype(str) == h.model) & (regressions["step"] == h.step)
                          & (regressions["predictor"] == h.predictor)]
        if sel.empty:
            raise ValueError(f"{h.hypothesis}: no coefficient of {h.predictor} in model {h.model} step {h.step}")
        r = sel.iloc[0]
        if r["dv"] != h.dv:
            raise ValueError(f"{h.hypothesis}: model {h.model} predicts {r['dv']}, not {h.dv}")
        rows.append({"hypothesis": h.hypothesis, "path": h.path, "beta": float(r["beta"]), "p": float(r["p"]),
                     "supported": bool(r["beta"] > 0 and r["p"] < alpha), "model": h.model, "step": h.step,
                     "b": float(r["b"]), "se_b": float(r["se_b"]), "t": float(r["t"]), "n": int(r["n"])})
    return pd.DataFrame(rows, columns=["hypothesis", "path", "beta", "p", "supported", "model", "step", "b", "se_b",
                                       "t", "n"])
