"""Acceptance statistics of a pEDAS survey in one call (paper Section 5.2, Tables 3-5).

Usage (a runnable example is in :class:`SurveyAnalysis`)::

    res = analyze_survey(responses)          # wide frame: participant_id + PU1..BI2, raw 1-5
    res.reliability, res.regressions, res.hypotheses
    print(res.to_markdown())                 # Tables 3, 4 and 5 as the paper prints them (to_latex: booktabs)
    res.write("out/")                        # the CSVs of docs/contracts.md + table3/4/5 .md, .tex and .csv
    SurveyAnalysis.read("out/")              # the same results back from those files

Pipeline: scoring (reverse PEoU3, listwise) -> item descriptives -> CFA stage ``initial`` (all items) with the
item flags -> CFA stage ``final`` (declared deletions, ``analysis/specs/cfa.json``) -> reliability/validity on the
final items -> composites (mean of retained items) -> composite correlations, Fornell-Larcker, HTMT ->
hierarchical regressions (``specs/models.json``) -> H1-H7 (``specs/hypotheses.json``).
"""
from __future__ import annotations

import json
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import pandas as pd

from analysis import cfa as _cfa
from analysis.descriptives import item_descriptives
from analysis.hypotheses import judge_hypotheses, load_hypotheses
from analysis.regression import ModelSpec, run_models, validate_models
from analysis.reliability import reliability_table
from analysis.scoring import check_not_constant, composites, resolve_instrument, score_responses
from analysis.tables_survey import PAPER_TABLES
from analysis.validity import composite_correlations, fornell_larcker, htmt

SPEC_DIR = Path(__file__).with_name("specs")

# Column contracts of docs/contracts.md "Analysis outputs" (extra columns follow these).
COLUMNS = {
    "descriptives": ["item", "n", "mean", "sd"],
    "loadings": ["stage", "construct", "item", "loading", "retained"],
    "fit": ["stage", "chi2", "df", "p", "cfi", "tli", "rmsea", "srmr"],
    "reliability": ["construct", "alpha", "alpha_ci_low", "alpha_ci_high", "cr", "ave", "sqrt_ave", "omega"],
    "correlations": ["a", "b", "r", "p"],
    "htmt": ["a", "b", "htmt"],
    "regressions": ["model", "step", "dv", "predictor", "r2", "adj_r2", "delta_r2", "f_change", "p_change", "b",
                    "se_b", "beta", "ci_low", "ci_high", "p", "boot_ci_low", "boot_ci_high"],
    "hypotheses": ["hypothesis", "path", "beta", "p", "supported"],
}


def _ordered(df: pd.DataFrame, name: str) -> pd.DataFrame:
    head = COLUMNS[name]
    return df[head + [c for c in df.columns if c not in head]]


def load_cfa_config(cfa_config=None) -> dict:
    """The item-deletion config: dict, JSON path, or the shipped default (``specs/cfa.json``) when None.

    Examples
    --------
    >>> from analysis.acceptance import load_cfa_config
    >>> cfg = load_cfa_config()                     # the paper's final model
    >>> cfg["drop"], cfg["rules"]
    (['PEoU3', 'ATT1', 'ATT2', 'ATT3', 'ATT4', 'ATT5'], {'min_loading': 0.7, 'cross_margin': 0.0})
    >>> load_cfa_config({"drop": []})["rules"]["min_loading"]
    0.7
    """
    if cfa_config is None:
        cfa_config = SPEC_DIR / "cfa.json"
    if isinstance(cfa_config, (str, Path)):
        cfa_config = json.loads(Path(cfa_config).read_text())
    cfg = {"constructs": None, "drop": [], "rules": {}}
    cfg.update(cfa_config)
    cfg["rules"] = {"min_loading": 0.7, "cross_margin": 0.0, **(cfg.get("rules") or {})}
    return cfg


def load_models(models=None) -> list[ModelSpec]:
    """Regression models: list of ModelSpec/dicts, a spec dict with 'models', a JSON path, or the default.

    Examples
    --------
    >>> from analysis.acceptance import load_models
    >>> [(m.name, m.dv, m.steps) for m in load_models()][:2]
    [('1', 'PU', (('PEoU',),)), ('2', 'ATT', (('PEoU',), ('PU',)))]
    """
    if models is None:
        models = SPEC_DIR / "models.json"
    if isinstance(models, (str, Path)):
        models = json.loads(Path(models).read_text())
    if isinstance(models, dict):
        models = models.get("models")
    if not isinstance(models, list) or not models:
        raise ValueError("regression models spec needs a non-empty list of models")
    return [m if isinstance(m, ModelSpec) else ModelSpec.from_dict(m) for m in models]


# 12 significant digits, and |x| < 1e-10 written as 0: the CFA optimiser's last bits (~1e-13, and variances at
# their bound ~1e-18) vary between runs; the files should not
CSV_FLOAT = "%.12g"


def _stable(frame: pd.DataFrame) -> pd.DataFrame:
    num = frame.select_dtypes("number").columns.difference(frame.select_dtypes("bool").columns)
    out = frame.copy()
    out[num] = out[num].mask(out[num].abs() < 1e-10, 0.0)
    return out


# text columns of the written CSVs (read back as strings, an empty cell as ""); every other column is numeric or
# boolean and an empty cell is NaN
TEXT_COLUMNS = {
    "descriptives": ["item", "construct"],
    "loadings": ["stage", "construct", "item", "cross_construct", "rule"],
    "fit": ["stage"],
    "reliability": ["construct"],
    "correlations": ["a", "b", "stars"],
    "fornell_larcker": ["a", "b"],
    "htmt": ["a", "b"],
    "regressions": ["model", "dv", "predictor", "label"],
    "hypotheses": ["hypothesis", "path", "model"],
    "composites": ["participant_id"],
}


def _read_csv(path: Path, text: list[str], **kw) -> pd.DataFrame:
    cols = pd.read_csv(path, nrows=0).columns
    return pd.read_csv(path, dtype={c: str for c in cols if c in text}, keep_default_na=False,
                       na_values={c: [""] for c in cols if c not in text}, **kw)


@dataclass
class SurveyAnalysis:
    """All acceptance statistics of one survey; each table a tidy DataFrame in the column contract of docs/contracts.md.

    The object renders itself (in the spirit of statsmodels' ``summary()``): :meth:`to_markdown` and
    :meth:`to_latex` give the paper-shaped Tables 3, 4 and 5 as one string, :meth:`write` saves every table as
    CSV, Markdown and LaTeX, and :meth:`read` loads a written analysis back.

    Examples
    --------
    The shipped reference survey (40 participants), without bootstrap resamples:

    >>> import tempfile
    >>> import pandas as pd
    >>> from analysis.acceptance import SurveyAnalysis, analyze_survey
    >>> from pedas.paths import REFERENCE_DIR
    >>> res = analyze_survey(pd.read_csv(REFERENCE_DIR / "survey.csv"), n_boot=0)
    >>> res.n, len(res.hypotheses)
    (40, 7)
    >>> print(res.to_markdown("table4").splitlines()[0])
    **Inter-construct correlation matrix of the TAM and TPB constructs**
    >>> print(res.to_latex("table4").splitlines()[2])
    \\caption{Inter-construct correlation matrix of the TAM and TPB constructs}

    Written and read back, it renders the same tables:

    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = res.write(d)
    ...     back = SurveyAnalysis.read(d)
    >>> back.to_markdown() == res.to_markdown() and back.to_latex() == res.to_latex()
    True
    """

    descriptives: pd.DataFrame
    loadings: pd.DataFrame
    fit: pd.DataFrame
    reliability: pd.DataFrame
    correlations: pd.DataFrame
    fornell_larcker: pd.DataFrame
    htmt: pd.DataFrame
    regressions: pd.DataFrame
    hypotheses: pd.DataFrame
    composites: pd.DataFrame
    latent_correlations: pd.DataFrame
    n: int
    n_input: int
    settings: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def tables(self) -> dict[str, pd.DataFrame]:
        """name -> frame of every CSV `write` produces."""
        return {"descriptives": self.descriptives, "loadings": self.loadings, "fit": self.fit,
                "reliability": self.reliability, "correlations": self.correlations,
                "fornell_larcker": self.fornell_larcker, "htmt": self.htmt, "regressions": self.regressions,
                "hypotheses": self.hypotheses}

    def write(self, out_dir) -> list[Path]:
        """Write the CSVs of docs/contracts.md, composites.csv, warnings.txt, settings.json and table3/4/5 + item_flags
        (.md, .tex, .csv; :func:`analysis.tables_survey.render_all`). :meth:`read` loads them back."""
        from analysis.tables_survey import render_all

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, frame in self.tables().items():
            p = out / f"{name}.csv"
            _stable(frame).to_csv(p, index=False, float_format=CSV_FLOAT)
            paths.append(p)
        p = out / "composites.csv"
        _stable(self.composites).to_csv(p, index=True, index_label="participant_id", float_format=CSV_FLOAT)
        paths.append(p)
        p = out / "warnings.txt"
        p.write_text("".join(w + "\n" for w in self.warnings))
        paths.append(p)
        p = out / "settings.json"
        p.write_text(json.dumps({**self.settings, "n": self.n, "n_input": self.n_input}, indent=2, default=str) + "\n")
        paths.append(p)
        for name, text in render_all(self).items():
            p = out / name
            p.write_text(text)
            paths.append(p)
        return paths

    def to_markdown(self, tables: str | Sequence[str] = PAPER_TABLES) -> str:
        """The paper-shaped tables as one Markdown string.

        Parameters
        ----------
        tables : str or sequence of str
            Which tables, in this order: "table3", "table4", "table5" (the default: all three) and/or
            "item_flags".

        Returns
        -------
        str
            Each table exactly as :meth:`write` saves it as ``<name>.md`` (bold title, table, notes; ending in a
            newline), joined by one blank line. ``to_markdown("table4")`` is the text of ``table4.md``.
        """
        return self._render(tables, "md")

    def to_latex(self, tables: str | Sequence[str] = PAPER_TABLES) -> str:
        """The paper-shaped tables as one LaTeX string: booktabs ``table`` environments, each exactly as
        :meth:`write` saves it as ``<name>.tex``, joined by one blank line (`tables` as in :meth:`to_markdown`).
        The preamble needs ``\\usepackage{booktabs}``."""
        return self._render(tables, "tex")

    def _render(self, tables, fmt: str) -> str:
        from analysis.tables_survey import render_table

        names = [tables] if isinstance(tables, str) else list(tables)
        return "\n".join(render_table(self, name, fmt) for name in names)

    @classmethod
    def read(cls, out_dir) -> "SurveyAnalysis":
        """Load an analysis that :meth:`write` saved in `out_dir`.

        The tables come from the CSV files (numbers as written: 12 significant digits), `n`, `n_input` and
        `settings` from ``settings.json`` (JSON types: the model steps come back as lists), `warnings` from
        ``warnings.txt``. ``latent_correlations`` is not written as such; it is rebuilt from the ``r_latent``
        column of ``correlations.csv`` (unit diagonal). A text cell written empty comes back as ``""``.
        ``read(d).to_markdown()`` / ``to_latex()`` equal the original's, and ``read(d).write(d2)`` writes the
        same files as ``d``. Raises FileNotFoundError when a file is missing.
        """
        d = Path(out_dir)
        names = list(COLUMNS) + ["fornell_larcker"]
        missing = [f for f in [f"{n}.csv" for n in names] + ["composites.csv", "settings.json", "warnings.txt"]
                   if not (d / f).is_file()]
        if missing:
            raise FileNotFoundError(f"{d} does not hold a written survey analysis: missing {', '.join(missing)}")
        frames = {n: _read_csv(d / f"{n}.csv", TEXT_COLUMNS[n]) for n in names}
        comp = _read_csv(d / "composites.csv", TEXT_COLUMNS["composites"], index_col="participant_id")
        settings = json.loads((d / "settings.json").read_text())
        n, n_input = int(settings.pop("n")), int(settings.pop("n_input"))
        lines = (d / "warnings.txt").read_text().split("\n")
        if lines[-1] == "":
            lines.pop()
        order = list(frames["reliability"]["construct"])
        latent = pd.DataFrame(float("nan"), index=order, columns=order)
        corr = frames["correlations"]
        if "r_latent" in corr.columns:
            for a, b, r in zip(corr["a"], corr["b"], corr["r_latent"]):
                if a in latent.index and b in latent.index:
                    latent.loc[a, b] = latent.loc[b, a] = r
        for c in order:
            latent.loc[c, c] = 1.0
        return cls(**frames, composites=comp, latent_correlations=latent, n=n, n_input=n_input, settings=settings,
                   warnings=lines)


def analyze_survey(responses: pd.DataFrame, *, instrument=None, cfa_config=None, models=None, hypotheses=None,
                   n_boot: int = 2000, seed: int = 20240101, listwise: bool = True,
                   boot_method: str = "percentile") -> SurveyAnalysis:
    """Run the whole acceptance analysis on a wide survey frame (docs/contracts.md "Survey CSV").

    instrument: codebook name or Instrument (default ``pedas_acceptance_v1``); cfa_config / models / hypotheses:
    dict, JSON path or None for the shipped specs; n_boot resamples (0 = none) seeded by `seed`; listwise:
    drop participants with any missing scaled answer (the default) -- otherwise composites average the answered
    items and CFA/alpha use complete rows. Raises ValueError (one line) on bad input.
    """
    with _single_threaded_blas():
        return _analyze(responses, instrument=instrument, cfa_config=cfa_config, models=models,
                        hypotheses=hypotheses, n_boot=n_boot, seed=seed, listwise=listwise, boot_method=boot_method)


@contextmanager
def _single_threaded_blas():
    """Run with one BLAS thread: every matrix here is tiny (<= 25 x 25, stacks of 4 x 4), where BLAS threads only
    add contention -- on a loaded 2-core machine they made a run ~8x slower in wall time. Results are unchanged."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


def _analyze(responses, *, instrument, cfa_config, models, hypotheses, n_boot, seed, listwise, boot_method
             ) -> SurveyAnalysis:
    if boot_method not in ("percentile", "bca"):
        raise ValueError(f"unknown bootstrap CI method {boot_method!r} (percentile or bca)")
    if int(n_boot) < 0:
        raise ValueError(f"n_boot must be >= 0, not {n_boot}")
    inst = resolve_instrument(instrument)
    sample = score_responses(responses, inst, listwise=listwise)
    scored = sample.scored
    warn: list[str] = []
    if sample.dropped:
        warn.append(f"listwise deletion: {len(sample.dropped)} of {sample.n_input} participants with missing answers "
                    f"left out ({', '.join(sample.dropped[:10])}{' ...' if len(sample.dropped) > 10 else ''})")
    if not listwise and scored.isna().any().any():
        n_cc = int(scored.notna().all(axis=1).sum())
        warn.append(f"available-case analysis: CFA, alpha and omega use the {n_cc} complete rows; descriptives, "
                    f"composites, correlations and regressions use the answers given")
    cfg = load_cfa_config(cfa_config)
    constructs = {c: list(v) for c, v in (cfg["constructs"] or sample.constructs).items()}
    all_items = [i for v in constructs.values() for i in v]
    unknown = [i for i in all_items if i not in scored.columns]
    if unknown:
        raise ValueError(f"CFA config names item(s) not in the instrument: {', '.join(unknown)}")
    bad_drop = [i for i in cfg["drop"] if i not in all_items]
    if bad_drop:
        raise ValueError(f"CFA config drops unknown item(s): {', '.join(bad_drop)}")
    specs = load_models(models)
    validate_models(specs, list(constructs))  # fail on a bad spec before the slow steps
    hyps, alpha = load_hypotheses(hypotheses)
    check_not_constant(scored[all_items])
    retained = {c: [i for i in v if i not in set(cfg["drop"])] for c, v in constructs.items()}
    for c, v in retained.items():
        if len(v) < 2:
            raise ValueError(f"CFA config leaves construct {c} with {len(v)} item(s); at least 2 are needed")

    descriptives = _ordered(item_descriptives(scored, sample.raw, constructs, sample.reverse_items), "descriptives")

    initial = _cfa.fit_cfa(scored, constructs, label="initial")
    final = _cfa.fit_cfa(scored, retained, label="final")
    warn += initial.warnings + final.warnings
    flagged = _cfa.flag_items(initial.loadings, scored, constructs, **cfg["rules"])
    flagged.insert(0, "stage", "initial")
    flagged["retained"] = ~flagged["item"].isin(cfg["drop"])
    fin = final.loadings.copy()
    fin.insert(0, "stage", "final")
    fin["retained"] = True
    loadings = _ordered(pd.concat([flagged, fin], ignore_index=True), "loadings")
    fit = _ordered(pd.DataFrame([{"stage": "initial", **initial.fit, "converged": initial.converged},
                                 {"stage": "final", **final.fit, "converged": final.converged}]), "fit")

    reliability = _ordered(reliability_table(scored, final), "reliability")
    comp = composites(scored, retained)
    check_not_constant(comp, "composite")
    corr = composite_correlations(comp)
    corr["r_latent"] = [float(final.latent_corr.loc[a, b]) for a, b in zip(corr["a"], corr["b"])]
    correlations = _ordered(corr, "correlations")
    fl = fornell_larcker(corr, reliability, final.latent_corr)
    ht = _ordered(htmt(scored, retained), "htmt")

    regressions = _ordered(run_models(comp, specs, n_boot=n_boot, seed=seed, boot_method=boot_method), "regressions")
    hyp = _ordered(judge_hypotheses(regressions, hyps, alpha), "hypotheses")

    for _, r in reliability.iterrows():
        if r["ave"] < 0.5:
            warn.append(f"{r['construct']}: AVE = {r['ave']:.3f} < 0.5 (convergent validity not met)")
    for _, r in fl[~fl["pass"]].iterrows():
        warn.append(f"Fornell-Larcker fails for {r['a']}-{r['b']}: |r| = {abs(r['r']):.3f} >= "
                    f"min sqrt(AVE) = {min(r['sqrt_ave_a'], r['sqrt_ave_b']):.3f}")
    settings = {"instrument": inst.name, "listwise": listwise, "n_boot": n_boot, "seed": seed,
                "boot_method": boot_method, "dropped_items": list(cfg["drop"]), "rules": cfg["rules"],
                "models": [m.__dict__ for m in specs], "hypothesis_alpha": alpha}
    return SurveyAnalysis(descriptives=descriptives, loadings=loadings, fit=fit, reliability=reliability,
                          correlations=correlations, fornell_larcker=fl, htmt=ht, regressions=regressions,
                          hypotheses=hyp, composites=comp, latent_correlations=final.latent_corr, n=sample.n,
                          n_input=sample.n_input, settings=settings, warnings=warn)


def responses_from_store(st, *, instrument=None) -> pd.DataFrame:
    """The wide survey frame of the included participants (exclusions scope 'subjective') from a store: the final
    answers as ``study.survey.final_responses`` resolves double entry."""
    from study.exclusions import included_participants
    from study.survey import final_responses

    inst = resolve_instrument(instrument)
    wide = final_responses(st, inst.name)
    keep = {str(p) for p in included_participants(st, "subjective")}
    wide = wide[wide["participant_id"].astype(str).isin(keep)]
    cols = ["participant_id"] + [c for c in inst.scaled_items if c in wide.columns]
    return wide[cols].reset_index(drop=True)
