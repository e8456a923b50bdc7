"""Hypotheses judged on the hierarchical regressions.

A hypothesis is a labelled regression path of the study's model file (docs/study_folder.md): ``BI ~ ATT + H5*PU``
marks H5 on the coefficient of PU in that model at that step, and ``H5 > 0`` declares its expected sign
(:class:`study.folder.definition.Hypothesis`). Verdicts, with p the coefficient's two-tailed t-test p as printed and alpha
the study's ``[analysis] alpha``:

* ``>``  supported when beta > 0 and p < alpha;
* ``<``  supported when beta < 0 and p < alpha;
* ``!=`` (a label without a sign) supported when p < alpha, whatever the sign.
"""
from __future__ import annotations

import pandas as pd

from study.folder.definition import Hypothesis

SIGNS = (">", "<", "!=")
COLUMNS = ["hypothesis", "path", "beta", "p", "supported", "model", "step", "b", "se_b", "t", "n"]


def supported(beta: float, p: float, sign: str, alpha: float) -> bool:
    """The verdict rule of the module docstring (p = alpha is not significant).

    Examples
    --------
    >>> from analysis.survey.hypotheses import supported
    >>> supported(0.4, 0.01, ">", 0.05), supported(-0.4, 0.01, ">", 0.05), supported(-0.4, 0.01, "<", 0.05)
    (True, False, True)
    >>> supported(-0.4, 0.01, "!=", 0.05), supported(0.4, 0.05, "!=", 0.05)
    (True, False)
    """
    if sign not in SIGNS:
        raise ValueError(f"unknown hypothesis sign {sign!r} (one of {', '.join(SIGNS)})")
    significant = p < alpha
    if sign == ">":
        return bool(beta > 0 and significant)
    if sign == "<":
        return bool(beta < 0 and significant)
    return bool(significant)


def load_hypotheses(model) -> list[Hypothesis]:
    """The hypotheses of a parsed model file (:class:`study.folder.definition.AnalysisModel`), in declaration order.

    Examples
    --------
    >>> from analysis.survey.hypotheses import load_hypotheses
    >>> from study.folder.definition import parse_model
    >>> from study.common.problems import Problems
    >>> model = parse_model("Y =~ y1 + y2\\nX =~ x1 + x2\\nY ~ H1*X\\nH1 < 0", "model.lav", Problems())
    >>> load_hypotheses(model)
    [Hypothesis(hypothesis='H1', predictor='X', dv='Y', model='1', step=1, sign='<')]
    """
    return list(model.hypotheses)


def judge_hypotheses(regressions: pd.DataFrame, hypotheses: list[Hypothesis], alpha: float = 0.05) -> pd.DataFrame:
    """Verdicts on the hypotheses from the regression table (rule of the module docstring).

    Parameters
    ----------
    regressions : DataFrame
        The hierarchical regressions (columns model, step, dv, predictor, b, se_b, beta, t, p, n).
    hypotheses : list of Hypothesis
        Each names the predictor, dv, model and step whose coefficient it reads, and its expected sign.
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
    >>> from analysis.survey.hypotheses import judge_hypotheses
    >>> from study.folder.definition import Hypothesis
    >>> reg = pd.DataFrame({"model": ["1", "1"], "step": [1, 1], "dv": ["Y", "Y"],
    ...                     "predictor": ["(Constant)", "X"], "b": [2.06, 0.48], "se_b": [0.73, 0.18],
    ...                     "beta": [float("nan"), 0.40], "t": [2.83, 2.70], "p": [0.008, 0.010], "n": [40, 40]})
    >>> h1 = Hypothesis("H1", predictor="X", dv="Y", model="1", step=1, sign=">")
    >>> judge_hypotheses(reg, [h1])[["hypothesis", "path", "beta", "p", "supported"]]
      hypothesis    path  beta     p  supported
    0         H1  X -> Y   0.4  0.01       True
    >>> bool(judge_hypotheses(reg, [h1], alpha=0.01).loc[0, "supported"])      # p = .01 is not < .01
    False
    """
    rows = []
    for h in hypotheses:
        sel = regressions[(regressions["model"].astype(str) == str(h.model)) & (regressions["step"] == h.step)
                          & (regressions["predictor"] == h.predictor)]
        if sel.empty:
            raise ValueError(f"{h.hypothesis}: no coefficient of {h.predictor} in model {h.model} step {h.step}")
        r = sel.iloc[0]
        if r["dv"] != h.dv:
            raise ValueError(f"{h.hypothesis}: model {h.model} predicts {r['dv']}, not {h.dv}")
        rows.append({"hypothesis": h.hypothesis, "path": h.path, "beta": float(r["beta"]), "p": float(r["p"]),
                     "supported": supported(float(r["beta"]), float(r["p"]), h.sign, alpha), "model": str(h.model),
                     "step": h.step, "b": float(r["b"]), "se_b": float(r["se_b"]), "t": float(r["t"]),
                     "n": int(r["n"])})
    return pd.DataFrame(rows, columns=COLUMNS)
