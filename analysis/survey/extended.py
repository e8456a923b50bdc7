"""The extended acceptance statistics of a study's survey in one call, from its study definition (docs/
acceptance_statistics.md, sections "Ordinal CFA" to "Measurement invariance").

Usage::

    study = study.folder.definition.load("studies/lane_keeping")
    ext = analyze_extended(responses, study, attributes=participants, n_boot=2000, group="gender")
    ext.ordinal_loadings, ext.omega, ext.htmt, ext.reliability_boot, ext.sem_paths, ext.indirect, ...
    ext.write("out/extended")                 # one CSV per table, the model syntax, extended.md, settings.json

Everything comes from the study's AnalysisModel (measurement, regressions, hypotheses) and instrument: the final
measurement model is the one the ordinal CFA, omega, HTMT2, the SEM and the invariance steps use; the structural
model is the union of the regressions' last steps (:func:`analysis.survey.sem.structural_paths`).
"""
from __future__ import annotations

import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.survey import cfa as _cfa
from analysis.survey import method_bias as mb
from analysis.survey import ordinal as _ord
from analysis.survey import sem as _sem
from analysis.survey.htmt import htmt2, reliability_bootstrap
from analysis.survey.invariance import invariance
from analysis.survey.reliability import omega_semtools

CSV_FLOAT = "%.10g"  # 10 significant digits: the SEM optimiser's last bits (~1e-12 relative) vary between runs
TABLES = ("ordinal_loadings", "ordinal_fit", "omega", "reliability_boot", "htmt2", "sem_paths", "sem_r2",
          "sem_fit", "indirect", "vif", "full_vif", "harman", "invariance")


@dataclass
class ExtendedAnalysis:
    """Each table a tidy DataFrame (columns in docs/contracts.md "Analysis outputs"); `specs`: name -> model syntax
    (lavaan/semopy text); `timings`: step -> seconds; `invariance` is empty without a group variable."""

    ordinal_loadings: pd.DataFrame
    ordinal_fit: pd.DataFrame
    omega: pd.DataFrame
    reliability_boot: pd.DataFrame
    htmt2: pd.DataFrame
    sem_paths: pd.DataFrame
    sem_r2: pd.DataFrame
    sem_fit: pd.DataFrame
    indirect: pd.DataFrame
    vif: pd.DataFrame
    full_vif: pd.DataFrame
    harman: pd.DataFrame
    invariance: pd.DataFrame
    invariance_groups: pd.DataFrame
    specs: dict[str, str]
    n: int
    settings: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def tables(self) -> dict[str, pd.DataFrame]:
        return {name: getattr(self, name) for name in TABLES}

    def write(self, out_dir) -> list[Path]:
        """<table>.csv for every table (10 significant digits), <spec>.lav for every model syntax, extended.md,
        settings.json (study, seed, resamples, group, structural paths), warnings.txt and timings.json (seconds per
        step; every other file is byte-identical between reruns)."""
        from analysis.survey.acceptance import stable_frame

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, frame in self.tables().items():
            if name == "invariance" and frame.empty:  # no group variable: no invariance table
                continue
            p = out / f"{name}.csv"
            stable_frame(frame).to_csv(p, index=False, float_format=CSV_FLOAT)
            paths.append(p)
        if len(self.invariance_groups):
            p = out / "invariance_groups.csv"
            self.invariance_groups.to_csv(p, index=False)
            paths.append(p)
        for name, text in self.specs.items():
            p = out / f"{name}.lav"
            p.write_text(text + "\n")
            paths.append(p)
        p = out / "extended.md"
        p.write_text(self.to_markdown())
        paths.append(p)
        p = out / "settings.json"
        p.write_text(json.dumps({**self.settings, "n": self.n}, indent=2, default=str) + "\n")
        paths.append(p)
        # wall-clock seconds per step: the one file that differs between reruns
        p = out / "timings.json"
        p.write_text(json.dumps(self.timings, indent=2) + "\n")
        paths.append(p)
        p = out / "warnings.txt"
        p.write_text("".join(w + "\n" for w in self.warnings))
        paths.append(p)
        return paths

    def to_markdown(self) -> str:
        """All tables as Markdown sections (three decimals)."""
        titles = {"ordinal_loadings": "Standardized loadings: ML vs ordinal (polychoric) ULS and DWLS",
                  "ordinal_fit": "Ordinal CFA fit", "omega": "omega: ML (semTools convention) and ordinal",
                  "reliability_boot": "Bootstrap confidence intervals of alpha, omega, HTMT and HTMT2",
                  "htmt2": "HTMT and HTMT2", "sem_paths": "Structural model (one SEM) beside the regressions",
                  "sem_r2": "R^2 of the endogenous constructs", "sem_fit": "Fit of the structural model",
                  "indirect": "Indirect effects (standardized, bootstrap CI)",
                  "vif": "VIF of the regression predictors", "full_vif": "Full-collinearity VIF (Kock)",
                  "harman": "Harman's single-factor test", "invariance": "Measurement invariance"}
        parts = []
        for name, frame in self.tables().items():
            if frame.empty:
                continue
            parts.append(f"**{titles[name]}**\n\n{_md(frame)}\n")
        return "\n".join(parts)


def _md(frame: pd.DataFrame) -> str:
    cols = list(frame.columns)
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for _, r in frame.iterrows():
        cells = []
        for c in cols:
            v = r[c]
            if isinstance(v, (bool, np.bool_)):
                cells.append("yes" if v else "no")
            elif isinstance(v, (float, np.floating)):
                cells.append("" if not np.isfinite(v) else f"{v:.3f}")
            else:
                cells.append(str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def group_series(attributes: pd.DataFrame | None, name: str) -> pd.Series:
    """participant_id -> group from a column `name` of the participant attributes (ValueError when absent)."""
    if attributes is None:
        raise ValueError(f"invariance by {name}: pass the participants' attributes (participant_id + {name})")
    a = attributes.set_index("participant_id") if "participant_id" in attributes.columns else attributes
    if name not in a.columns:
        raise ValueError(f"invariance: the participants have no attribute {name!r} "
                         f"({', '.join(map(str, a.columns)) or 'none'})")
    s = a[name]
    s.index = s.index.astype(str)
    return s.where(s.notna() & (s.astype(str).str.strip() != ""))


def analyze_extended(responses: pd.DataFrame, study, *, attributes: pd.DataFrame | None = None, instrument=None,
                     model=None, n_boot: int = 2000, seed: int = 20240101, group: str | None = None,
                     groups: pd.Series | None = None, level: float = 0.95, workers: int = 2,
                     survey=None, collapse_empty: bool = False) -> ExtendedAnalysis:
    """Run the extended statistics (module docstring) on a wide survey frame of `study`.

    `group` names a participant attribute (of `attributes`) for the invariance steps; `groups` gives the grouping
    directly (participant_id -> group, e.g. a driving style derived from the drives). Raises ValueError (one line)
    on bad input, before any slow step: a too-small group refuses the whole call. ``workers`` = 2 computes the
    polychoric correlations in a second process while the bootstrap runs (same results with 1).

    `survey`: the :class:`analysis.survey.acceptance.SurveyAnalysis` of the same answers (listwise, the same
    final measurement model) this builds on; its final-stage ML CFA is taken instead of fitting it again (the
    results are those of a fresh fit). ValueError when it was fitted to other answers or another model.

    `collapse_empty`: an item category that the analysed (complete) rows do not use although the data set has it
    (answered only by a participant left out for a missing answer) is refused, as lavaan refuses it, unless this
    merges it for the ordinal CFA (a warning names it; :func:`analysis.survey.ordinal.check_categories`).
    """
    from analysis.survey.acceptance import _model, _study, covariate_frame, survey_plan
    from analysis.survey.scoring import check_not_constant, resolve_instrument, score_responses

    if int(n_boot) < 0:
        raise ValueError(f"n_boot must be >= 0, not {n_boot}")
    t_all = time.perf_counter()
    timings: dict[str, float] = {}
    study = _study(study)
    inst = resolve_instrument(study, instrument)
    amodel = _model(study, model)
    plan = survey_plan(study, inst, amodel)
    sample = score_responses(responses, inst, listwise=True)
    scored = sample.scored
    retained = plan.retained
    items = [i for v in retained.values() for i in v]
    check_not_constant(scored[items])
    # the items' categories are the answers of the whole data set (lavaan's ordered= levels, before listwise
    # deletion); an empty one is refused here, before any slow step, unless collapsed
    full = score_responses(responses, inst, listwise=False).scored
    categories = {it: sorted(full[it].dropna().unique()) for it in items}
    cat_warn = _ord.check_categories(scored, items, categories, collapse_empty=collapse_empty)
    ml = None
    if survey is not None:
        if survey.fits is None:
            raise ValueError("the survey analysis to build on has no fitted models (it was read from files)")
        survey.fits.check(scored, True, retained)
        ml = survey.fits.final
    warn: list[str] = list(cat_warn)
    group_var = group
    if group is not None and groups is None:
        groups = group_series(attributes, group)
    if groups is not None:
        group_var = group_var or (groups.name if groups.name else "group")
        g = groups.copy()
        g.index = g.index.astype(str)
        g = g.reindex(scored.index)
        sizes = g.dropna().value_counts()
        p = len(items)
        small = [f"{lv} ({n})" for lv, n in sizes.items() if n <= p]
        if len(sizes) < 2:
            raise ValueError(f"invariance by {group_var}: {len(sizes)} group(s) among the participants; at least 2 "
                             f"are needed")
        if small:
            raise ValueError(f"invariance by {group_var}: group(s) {', '.join(map(str, small))} too small; the model "
                             f"has {p} items, so every group needs at least {p + 1} participants")
        groups = g
    covars, cov_cols = covariate_frame(attributes, study, plan.covariates, scored.index)
    paths = _sem.structural_paths(amodel)
    paths_cols = {dv: [c for p_ in preds for c in cov_cols.get(p_, [p_])] for dv, preds in paths.items()}

    pool = ProcessPoolExecutor(max_workers=1) if workers > 1 else None
    try:
        # the polychoric correlations run beside the bootstrap in a second process when there is a second core
        pending = pool.submit(_ordinal_part, scored, retained, categories) if pool else None
        return _run(pending, scored, retained, items, study, inst, amodel, plan, sample, covars, cov_cols, paths,
                    paths_cols, groups, group_var, n_boot, seed, level, warn, timings, t_all, ml, categories)
    finally:
        if pool:
            pool.shutdown(cancel_futures=True)


def _ordinal_part(scored, retained, categories=None):
    from analysis.survey.acceptance import _single_threaded_blas

    with _single_threaded_blas():
        t = time.perf_counter()
        items = [i for v in retained.values() for i in v]
        # empty categories were refused or their warnings taken by the caller: collapse what is left
        poly = _ord.polychoric(scored, items, categories=categories, collapse_empty=True)
        uls = _ord.fit_ordinal_cfa(scored, retained, estimator="ULS", poly=poly)
        dwls = _ord.fit_ordinal_cfa(scored, retained, estimator="DWLS", poly=poly)
        return uls, dwls, time.perf_counter() - t


def _run(pending, scored, retained, items, study, inst, amodel, plan, sample, covars, cov_cols, paths, paths_cols,
         groups, group_var, n_boot, seed, level, warn, timings, t_all, ml=None, categories=None):
    from analysis.survey.acceptance import _single_threaded_blas
    from analysis.survey.hypotheses import judge_hypotheses
    from analysis.survey.regression import ModelSpec, run_models
    from analysis.survey.scoring import composites

    with _single_threaded_blas():
        t = time.perf_counter()
        if ml is None:  # not given by the survey analysis this builds on
            ml = _cfa.fit_cfa(scored, retained, label="final")
        warn += ml.warnings
        timings["ml_cfa"] = time.perf_counter() - t

        t = time.perf_counter()
        ht = htmt2(scored, retained)
        for r in ht[ht["htmt2"].isna()].itertuples():
            warn.append(f"HTMT2 {r.a}-{r.b}: undefined (two items of {r.a} or of {r.b} correlate 0, so the geometric "
                        f"mean of its monotrait correlations is 0)")
        boot = reliability_bootstrap(scored, retained, n_boot=n_boot, seed=seed, level=level)
        timings["bootstrap_reliability_htmt"] = time.perf_counter() - t

        t = time.perf_counter()
        uls, dwls, t_ord = pending.result() if pending is not None else _ordinal_part(scored, retained, categories)
        warn += uls.warnings + dwls.warnings
        lo = ml.loadings[["construct", "item", "loading"]].rename(columns={"loading": "loading_ml"})
        lo["loading_uls"] = uls.loadings["loading"].to_numpy()
        lo["loading_dwls"] = dwls.loadings["loading"].to_numpy()
        ofit = pd.DataFrame([{**f.fit, "converged": f.converged, "admissible": f.admissible} for f in (uls, dwls)])
        om_ml = [omega_semtools(ml.loadings.set_index("item").loc[its, "estimate"], ml.psi.loc[c, c],
                                ml.S.loc[its, its]) for c, its in retained.items()]
        omega = pd.DataFrame({"construct": list(retained), "omega_ml": om_ml,
                              "omega_ordinal_dwls": _ord.ordinal_omega(dwls)["omega_ordinal"].to_numpy(),
                              "omega_ordinal_uls": _ord.ordinal_omega(uls)["omega_ordinal"].to_numpy(),
                              "n_items": [len(v) for v in retained.values()]})
        timings["ordinal"] = t_ord
        timings["ordinal_wait"] = time.perf_counter() - t

        t = time.perf_counter()
        comp = composites(scored, retained)
        data = scored.join(covars) if len(covars.columns) else scored
        sem = _sem.fit_sem(data, retained, paths_cols, amodel.hypotheses)
        warn += sem.warnings
        comp_all = comp.join(covars) if len(covars.columns) else comp
        specs = [ModelSpec(m.name, m.dv, tuple(tuple(c for p_ in b for c in cov_cols.get(p_, [p_])) for b in m.steps),
                           m.label) for m in plan.models]
        reg = run_models(comp_all, specs, n_boot=0, seed=seed)
        hyp = judge_hypotheses(reg, plan.hypotheses, plan.alpha)
        sp = sem.paths.merge(_sem.composite_path_std(comp_all, paths_cols), on=["dv", "predictor"], how="left")
        hb = {(r.hypothesis): (r.beta, r.p) for r in hyp.itertuples()}
        sp["beta_regression"] = [hb.get(h, (np.nan, np.nan))[0] if h else np.nan for h in sp["hypothesis"]]
        sp["p_regression"] = [hb.get(h, (np.nan, np.nan))[1] if h else np.nan for h in sp["hypothesis"]]
        sem_fit = pd.DataFrame([{**sem.fit, "converged": sem.converged, "admissible": sem.admissible}])
        timings["sem"] = time.perf_counter() - t

        t = time.perf_counter()
        ind = _sem.indirect_effects(comp_all, paths_cols, latent=sem, n_boot=n_boot, seed=seed, level=level)
        timings["indirect_bootstrap"] = time.perf_counter() - t

        t = time.perf_counter()
        vif = mb.regression_vif(comp_all, specs)
        full = mb.full_collinearity_vif(comp)
        harm = pd.DataFrame([mb.harman(scored, items)])
        for r in full[full["above_3_3"]].itertuples():
            warn.append(f"full-collinearity VIF of {r.construct} = {r.vif:.2f} > 3.3 (collinearity or "
                        f"common-method bias)")
        if bool(harm.loc[0, "above_50"]):
            warn.append(f"Harman's test: one factor explains {harm.loc[0, 'first_share']:.1%} (> 50 %) of the "
                        f"item variance")
        timings["method_bias"] = time.perf_counter() - t

        t = time.perf_counter()
        if groups is not None:
            inv = invariance(scored, retained, groups, group_var=str(group_var))
            inv_steps, inv_groups = inv.steps, inv.groups
            warn += inv.warnings
        else:
            inv_steps = pd.DataFrame(columns=["step", "chi2", "df", "p", "cfi", "tli", "rmsea", "n_params",
                                              "converged", "delta_chi2", "delta_df", "p_delta", "delta_cfi", "holds",
                                              "delta_rmsea", "reason"])
            inv_groups = pd.DataFrame(columns=["group", "n"])
        timings["invariance"] = time.perf_counter() - t
    failed = boot[boot["n_failed"] > 0]
    if len(failed):
        worst = failed.loc[failed["n_failed"].idxmax()]
        warn.append(f"bootstrap: {len(failed)} statistic(s) with failed resamples (at most {int(worst['n_failed'])} "
                    f"of {n_boot}, {worst['statistic']} {worst['a']}{'-' + worst['b'] if worst['b'] else ''}); "
                    f"their intervals use the other resamples")
    timings["total"] = time.perf_counter() - t_all
    settings = {"study": study.study_id, "study_hash": study.hash, "instrument": inst.name, "n_boot": int(n_boot),
                "seed": int(seed), "level": level, "group": group_var, "boot_method": "bca",
                "structural_paths": paths_cols}
    model_specs = {"measurement": _cfa.model_description(retained), "sem": sem.description,
                   "path_model": path_model_syntax(paths_cols)}
    return ExtendedAnalysis(ordinal_loadings=lo, ordinal_fit=ofit, omega=omega, reliability_boot=boot, htmt2=ht,
                            sem_paths=sp, sem_r2=sem.r2, sem_fit=sem_fit, indirect=ind, vif=vif, full_vif=full,
                            harman=harm, invariance=inv_steps, invariance_groups=inv_groups, specs=model_specs,
                            n=sample.n, settings=settings, timings={k: round(v, 3) for k, v in timings.items()},
                            warnings=warn)


def path_model_syntax(paths: dict[str, list[str]]) -> str:
    """lavaan syntax of the composite path model with labelled paths and one ``:=`` line per indirect chain
    (unstandardized product), the specification a reviewer reruns.

    Examples
    --------
    >>> from analysis.survey.extended import path_model_syntax
    >>> print(path_model_syntax({"M": ["X"], "Y": ["M", "X"]}))
    M ~ b_M_X*X
    Y ~ b_Y_M*M + b_Y_X*X
    X_M_Y := b_M_X*b_Y_M
    """
    lines = [f"{dv} ~ " + " + ".join(f"b_{dv}_{p}*{p}" for p in preds) for dv, preds in paths.items()]
    for ch in _sem.chains(paths):
        lines.append("_".join(ch) + " := " + "*".join(f"b_{ch[i + 1]}_{ch[i]}" for i in range(len(ch) - 1)))
    return "\n".join(lines)
