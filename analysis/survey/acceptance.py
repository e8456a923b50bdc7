"""Acceptance statistics of a study's survey in one call (the paper's Section 5.2 and Tables 3-5 for its study).

Usage (a runnable example is in :class:`SurveyAnalysis`)::

    study = study.folder.definition.load("studies/lane_keeping")     # or study.store.studies.definition(store)
    res = analyze_survey(responses, study, attributes=participants)   # wide frame: participant_id + item columns
    res.reliability, res.regressions, res.hypotheses
    print(res.to_markdown())                 # Tables 3, 4 and 5 (to_latex: booktabs)
    res.write("out/")                        # the CSVs of docs/contracts.md + table3/4/5 .md, .tex and .csv
    SurveyAnalysis.read("out/")              # the same results back from those files

Everything the analysis is about comes from the study definition (docs/study_folder.md): the instrument (items,
constructs, scales, reverse-scored items), the model file (final measurement model, hierarchical regressions,
hypotheses with their expected signs) and ``[analysis]`` of study.toml (alpha, min_loading, cross_margin,
regression_title, optional correlation_title and construct_labels).

Pipeline: scoring (reverse-scored items, listwise) -> item descriptives -> CFA stage ``initial`` (every scaled
item of the instrument on its construct) with the item flags -> CFA stage ``final`` (the model file's measurement
model; the items it leaves out are the dropped ones) -> reliability/validity on the final items -> composites (mean
of retained items) -> composite correlations, Fornell-Larcker, HTMT -> hierarchical regressions on the composites
and participant attributes (covariates, :func:`covariate_frame`) -> hypotheses.
"""
from __future__ import annotations

import json
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import pandas as pd

from analysis.survey import cfa as _cfa
from analysis.survey.descriptives import item_descriptives
from analysis.survey.hypotheses import judge_hypotheses
from analysis.survey.regression import ModelSpec, run_models, validate_models
from analysis.survey.reliability import reliability_table
from analysis.survey.scoring import ID_COL, check_not_constant, composites, resolve_instrument, score_responses
from analysis.survey.tables import PAPER_TABLES
from analysis.survey.validity import composite_correlations, fornell_larcker, htmt

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


# 12 significant digits, and |x| < 1e-10 written as 0: the CFA optimiser's last bits (~1e-13, and variances at
# their bound ~1e-18) vary between runs; the files should not
CSV_FLOAT = "%.12g"


def stable_frame(frame: pd.DataFrame) -> pd.DataFrame:
    """A copy of `frame` with every numeric (non-boolean) value below 1e-10 in magnitude set to 0 (see CSV_FLOAT)."""
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
    Synthetic answers and ages of the lane-keeping example study (24 participants, 7-point items, age as a
    control), without bootstrap resamples:

    >>> import tempfile
    >>> from analysis.survey.acceptance import SurveyAnalysis, analyze_survey
    >>> from analysis.survey.testing import simulate_study_participants, simulate_study_responses
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> study = load(REPO_ROOT / "studies" / "lane_keeping")
    >>> answers = simulate_study_responses(study, 24, seed=3)
    >>> res = analyze_survey(answers, study, attributes=simulate_study_participants(study, 24, seed=3), n_boot=0)
    >>> res.n, list(res.hypotheses["hypothesis"]), sorted(set(res.regressions["predictor"]))
    (24, ['H1', 'H2', 'H3'], ['(Constant)', 'EE', 'PE', 'SI', 'age'])
    >>> print(res.to_markdown("table5").splitlines()[0])
    **Hierarchical regression analysis on UTAUT models**
    >>> print(next(ln for ln in res.to_latex("table4").splitlines() if ln.startswith("\\\\caption")))
    \\caption{Inter-construct correlation matrix of the UTAUT constructs}

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
    # the fitted models behind the tables, for other analyses of the same answers (not written; None when read)
    fits: "SurveyFits | None" = field(default=None, repr=False, compare=False)

    def tables(self) -> dict[str, pd.DataFrame]:
        """name -> frame of every CSV `write` produces."""
        return {"descriptives": self.descriptives, "loadings": self.loadings, "fit": self.fit,
                "reliability": self.reliability, "correlations": self.correlations,
                "fornell_larcker": self.fornell_larcker, "htmt": self.htmt, "regressions": self.regressions,
                "hypotheses": self.hypotheses}

    def write(self, out_dir) -> list[Path]:
        """Write the CSVs of docs/contracts.md, composites.csv, warnings.txt, settings.json and table3/4/5 + item_flags
        (.md, .tex, .csv; :func:`analysis.survey.tables.render_all`). :meth:`read` loads them back."""
        from analysis.survey.tables import render_all

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, frame in self.tables().items():
            p = out / f"{name}.csv"
            stable_frame(frame).to_csv(p, index=False, float_format=CSV_FLOAT)
            paths.append(p)
        p = out / "composites.csv"
        stable_frame(self.composites).to_csv(p, index=True, index_label="participant_id", float_format=CSV_FLOAT)
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
        from analysis.survey.tables import render_table

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


@dataclass(frozen=True, eq=False)
class SurveyFits:
    """The fitted models of one survey analysis that another analysis of the same answers reuses instead of fitting
    them again (:func:`analyze_survey` with ``reuse=``, :func:`analysis.survey.extended.analyze_extended` with
    ``survey=``).

    scored: the scored answers the models were fitted to; listwise: whether incomplete participants were left out;
    initial, final: the CFA of both stages (standardized CFA loadings, before any SPSS-style extraction).
    """

    scored: pd.DataFrame
    listwise: bool
    initial: "_cfa.CFAResult"
    final: "_cfa.CFAResult"

    def check(self, scored: pd.DataFrame, listwise: bool, retained: dict, constructs: dict | None = None) -> None:
        """ValueError unless these fits are of the same answers (`scored`, `listwise`) and measurement models (the
        final stage's `retained`; the initial stage's `constructs` when given)."""
        if listwise != self.listwise or not scored.equals(self.scored):
            raise ValueError("the survey analysis to reuse was fitted to other answers (another instrument, "
                             "deletion or participants)")
        if dict(retained) != self.final.constructs or (constructs is not None
                                                       and dict(constructs) != self.initial.constructs):
            raise ValueError("the survey analysis to reuse was fitted to another measurement model")


def analyze_survey(responses: pd.DataFrame, study, *, attributes: pd.DataFrame | None = None, instrument=None,
                   model=None, n_boot: int = 2000, seed: int = 20240101, listwise: bool = True,
                   boot_method: str = "percentile", loadings: str = "cfa",
                   reuse: SurveyAnalysis | None = None) -> SurveyAnalysis:
    """Run the whole acceptance analysis of `study` on a wide survey frame (docs/contracts.md "Survey CSV").

    Parameters
    ----------
    responses : DataFrame
        participant_id + one column per scaled item of the instrument, raw answers as ticked.
    study : StudyDefinition, str or Path
        The study (``study.store.studies.definition(store)``) or a study folder to load.
    attributes : DataFrame, optional
        Participant attributes, wide and typed (participant_id as a column or the index, one column per attribute;
        ``study.people.participants.participant_attributes(store)``). Needed when the model's regressions use
        covariates; a participant missing from it, or without a value, is left out of the models that use that
        covariate (warned).
    instrument : str or Instrument, optional
        The instrument to analyse (default: the study's only one).
    model : AnalysisModel or str, optional
        A model in the model file's lavaan syntax (text) or parsed, instead of the study's model file.
    n_boot, seed, boot_method
        Bootstrap resamples of the regression CIs (0 = none), their seed, "percentile" or "bca".
    listwise : bool
        Drop participants with any missing scaled answer (default); otherwise composites average the answered
        items and CFA/alpha use complete rows.
    loadings : str
        The λ reported in Table 3 and used for CR/AVE/√AVE and the item rules: "cfa" (default, standardized
        loadings of the CFA), or SPSS FACTOR's extractions per construct, "pca" (first principal component) or
        "paf" (principal axis factoring) - to compare with papers that report those (:mod:`analysis.survey.extraction`).
        The CFA is fitted either way (fit indices, latent correlations, omega).
    reuse : SurveyAnalysis, optional
        An analysis of the same answers (same instrument, deletion and measurement models) whose CFA fits
        (``reuse.fits``) this one takes instead of fitting them again, e.g. the CFA-loadings analysis when the PCA
        loadings are wanted beside it; the results are those of a fresh fit. ValueError when it was fitted to other
        answers or models, or has no fits (read from files).

    Raises ValueError (one line) on bad input.
    """
    if reuse is not None and reuse.fits is None:
        raise ValueError("the survey analysis to reuse has no fitted models (it was read from files)")
    with _single_threaded_blas():
        return _analyze(responses, _study(study), attributes=attributes, instrument=instrument, model=model,
                        n_boot=n_boot, seed=seed, listwise=listwise, boot_method=boot_method,
                        loading_method=loadings, fits=reuse.fits if reuse is not None else None)


def _study(study):
    from study.folder.definition import StudyDefinition, load

    if isinstance(study, StudyDefinition):
        return study
    if isinstance(study, (str, Path)):
        return load(study)
    raise ValueError("analyze_survey needs the study: a StudyDefinition or a study folder")


def _model(study, model):
    """The AnalysisModel to run: the study's, or `model` (parsed or lavaan text)."""
    from study.folder.definition import AnalysisModel, parse_model
    from study.common.problems import Problems, StudyError

    if model is None:
        if study.model is None:
            raise ValueError(f"study {study.study_id} declares no model file ([files] model): nothing to analyse")
        return study.model
    if isinstance(model, AnalysisModel):
        return model
    if isinstance(model, (str, Path)) and Path(str(model)).suffix == ".lav" and Path(str(model)).is_file():
        model = Path(model).read_text(encoding="utf-8")
    try:
        return parse_model(str(model), "model", Problems(), strict=True)
    except StudyError as exc:
        raise ValueError(str(exc)) from None


@dataclass(frozen=True)
class SurveyPlan:
    """What the analysis of one study runs, derived from its instrument, model file and settings.

    constructs: initial CFA stage (construct -> every scaled item of the instrument); retained: final stage (the
    model file's measurement model); dropped: initial items not in the final stage; models: the hierarchical
    regressions (blocks = predictors entered per step); covariates: regression predictors that are participant
    attributes; rules: item-flag thresholds; alpha: significance level of the hypotheses.
    """

    constructs: dict[str, list[str]]
    retained: dict[str, list[str]]
    dropped: list[str]
    models: list[ModelSpec]
    hypotheses: list
    covariates: list[str]
    rules: dict[str, float]
    alpha: float


def survey_plan(study, instrument, model) -> SurveyPlan:
    """The :class:`SurveyPlan` of `study` for `instrument` and the parsed `model`; ValueError (one line) when the
    model names an item that is not a scaled item of the instrument, a construct it does not measure, an
    undeclared attribute, a construct with fewer than 2 items, or a hypothesis on a choice/text attribute.

    Examples
    --------
    >>> from analysis.survey.acceptance import survey_plan
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> study = load(REPO_ROOT / "studies" / "lane_keeping")
    >>> plan = survey_plan(study, study.instrument(), study.model)
    >>> plan.dropped, plan.covariates, plan.rules
    ([], ['age'], {'min_loading': 0.7, 'cross_margin': 0.0})
    >>> [(m.name, m.dv, m.steps) for m in plan.models]
    [('1', 'BI', (('age',), ('PE', 'EE', 'SI')))]
    """
    settings = study.settings.get("analysis", {})
    constructs = {c: list(v) for c, v in instrument.constructs.items()}
    items = [i for v in constructs.values() for i in v]
    retained = {c: list(v) for c, v in model.measurement.items()}
    final_items = [i for v in retained.values() for i in v]
    unknown = [i for i in final_items if i not in items]
    if unknown:
        raise ValueError(f"the measurement model names item(s) that are not scaled items of instrument "
                         f"{instrument.name}: {', '.join(unknown)}")
    for c, v in retained.items():
        if len(v) < 2:
            raise ValueError(f"the measurement model leaves construct {c} with {len(v)} item(s); at least 2 are needed")
    attrs = {a.name: a for a in study.attributes}
    covariates: list[str] = []
    for m in model.regressions:
        for name in (m.dv, *m.steps[-1]):
            if name in retained:
                continue
            if name == m.dv or name not in attrs:
                raise ValueError(f"model {m.name}: {name!r} is neither a construct of the measurement model"
                                 f"{'' if name == m.dv else ' nor a participant attribute of the study'}")
            if name not in covariates:
                covariates.append(name)
    for h in model.hypotheses:
        if h.predictor in attrs and attrs[h.predictor].categorical:
            raise ValueError(f"{h.hypothesis}: {h.predictor} is a {attrs[h.predictor].type} attribute, entered as "
                             f"dummy columns; a hypothesis needs one coefficient (a numeric predictor)")
    models = [ModelSpec(name=m.name, dv=m.dv, steps=tuple(tuple(b) for b in m.blocks), label=m.label)
              for m in model.regressions]
    rules = {"min_loading": float(settings.get("min_loading", 0.7)),
             "cross_margin": float(settings.get("cross_margin", 0.0))}
    return SurveyPlan(constructs=constructs, retained=retained,
                      dropped=[i for i in items if i not in set(final_items)], models=models,
                      hypotheses=list(model.hypotheses), covariates=covariates, rules=rules, alpha=study.alpha)


def covariate_frame(attributes: pd.DataFrame | None, study, names: list[str], index: pd.Index
                    ) -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """The covariate columns of the regressions for the participants in `index`.

    A numeric attribute (integer, number) enters as is. A choice or text attribute is dummy-coded: one 0/1
    column ``<attribute>_<level>`` per level that occurs among these participants, against a reference level
    left out -- the first declared choice (text: the alphabetically first value) that occurs. A participant
    absent from `attributes`, or without a value, gets NaN (left out of the models using it).

    Returns (frame indexed like `index`, {attribute: its column names}).

    Examples
    --------
    >>> import pandas as pd
    >>> from analysis.survey.acceptance import covariate_frame
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> study = load(REPO_ROOT / "studies" / "lane_keeping")
    >>> attrs = pd.DataFrame({"participant_id": ["LK-01", "LK-02", "LK-03"], "age": [34, 51, None],
    ...                       "gender": ["male", "female", "diverse"]})
    >>> frame, cols = covariate_frame(attrs, study, ["age", "gender"], pd.Index(["LK-01", "LK-02", "LK-03"]))
    >>> cols
    {'age': ['age'], 'gender': ['gender_male', 'gender_diverse']}
    >>> frame
                     age  gender_male  gender_diverse
    participant_id
    LK-01           34.0          1.0             0.0
    LK-02           51.0          0.0             0.0
    LK-03            NaN          0.0             1.0
    """
    out = pd.DataFrame(index=pd.Index(index, name=ID_COL))
    columns: dict[str, list[str]] = {}
    if not names:
        return out, columns
    if attributes is None:
        raise ValueError(f"the model uses participant attribute(s) {', '.join(names)}: pass the participants' "
                         f"attributes (participant_id + one column per attribute)")
    attrs = attributes.copy()
    if ID_COL in attrs.columns:
        attrs = attrs.set_index(ID_COL)
    attrs.index = attrs.index.astype(str)
    if attrs.index.duplicated().any():
        raise ValueError(f"duplicate participant_id in the attributes: {attrs.index[attrs.index.duplicated()][0]}")
    attrs = attrs.reindex(out.index)
    for name in names:
        if name not in attrs.columns:
            raise ValueError(f"the model uses participant attribute {name}: the attributes have no column {name}")
        a = study.attribute(name)
        col = attrs[name]
        if not a.categorical:
            try:
                out[name] = pd.to_numeric(col, errors="raise").astype(float)
            except (TypeError, ValueError):
                raise ValueError(f"attribute {name} ({a.type}) must be numeric: "
                                 f"{col.dropna().iloc[0]!r} is not") from None
            columns[name] = [name]
            continue
        values = pd.Series([None if pd.isna(v) else (str(v).strip() or None) for v in col], index=col.index,
                           dtype=object)
        seen = set(values.dropna())
        levels = [c for c in a.choices if c in seen] if a.type == "choice" else sorted(seen)
        odd = sorted(seen - set(levels))
        if odd:
            raise ValueError(f"attribute {name}: {odd[0]!r} is not one of {'|'.join(a.choices)}")
        columns[name] = []
        for level in levels[1:]:
            c = f"{name}_{level}"
            out[c] = values.map(lambda v, lv=level: float("nan") if v is None else float(v == lv))
            columns[name].append(c)
    return out, columns


@contextmanager
def _single_threaded_blas():
    """Run with one BLAS thread: every matrix here is tiny (<= 25 x 25, stacks of 4 x 4), where BLAS threads only
    add contention -- on a loaded 2-core machine they made a run ~8x slower in wall time. Results are unchanged."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


def _analyze(responses, study, *, attributes, instrument, model, n_boot, seed, listwise, boot_method,
             loading_method="cfa", fits: SurveyFits | None = None) -> SurveyAnalysis:
    if loading_method not in LOADING_METHODS:
        raise ValueError(f"unknown loadings {loading_method!r} (one of {', '.join(LOADING_METHODS)})")
    if boot_method not in ("percentile", "bca"):
        raise ValueError(f"unknown bootstrap CI method {boot_method!r} (percentile or bca)")
    if int(n_boot) < 0:
        raise ValueError(f"n_boot must be >= 0, not {n_boot}")
    inst = resolve_instrument(study, instrument)
    plan = survey_plan(study, inst, _model(study, model))  # fail on a bad model before the slow steps
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
    constructs, retained = plan.constructs, plan.retained
    small = [c for c, v in constructs.items() if len(v) < 2]
    if small:
        warn.append(f"initial CFA: construct(s) {', '.join(small)} with a single scaled item left out of the "
                    f"initial stage")
        constructs = {c: v for c, v in constructs.items() if len(v) >= 2}
    all_items = [i for v in constructs.values() for i in v]
    check_not_constant(scored[all_items])
    covars, cov_cols = covariate_frame(attributes, study, plan.covariates, scored.index)
    specs = [ModelSpec(m.name, m.dv, tuple(tuple(c for p in b for c in cov_cols.get(p, [p])) for b in m.steps),
                       m.label) for m in plan.models]
    validate_models(specs, list(retained) + list(covars.columns))

    descriptives = _ordered(item_descriptives(scored, sample.raw, constructs, sample.reverse_items), "descriptives")

    if fits is None:
        fits = SurveyFits(scored=scored, listwise=listwise, initial=_cfa.fit_cfa(scored, constructs, label="initial"),
                          final=_cfa.fit_cfa(scored, retained, label="final"))
    else:
        fits.check(scored, listwise, retained, constructs)
    initial, final = fits.initial, fits.final
    warn += initial.warnings + final.warnings
    if loading_method != "cfa":
        initial, final = (_with_extraction(r, scored, loading_method, warn, stage)
                          for r, stage in ((initial, "initial"), (final, "final")))
    flagged = _cfa.flag_items(initial.loadings, scored, constructs, **plan.rules)
    flagged.insert(0, "stage", "initial")
    flagged["retained"] = ~flagged["item"].isin(plan.dropped)
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

    for m in plan.models:
        used = [p for b in m.steps for p in b if p in cov_cols]
        cols = [c for p in used for c in cov_cols[p]]
        lacking = covars.index[covars[cols].isna().any(axis=1)].tolist() if cols else []
        if lacking:
            warn.append(f"model {m.name}: {len(lacking)} participant(s) without {' or '.join(used)} left out of "
                        f"this model ({', '.join(lacking[:10])}{' ...' if len(lacking) > 10 else ''})")
    data = comp.join(covars) if len(covars.columns) else comp
    regressions = _ordered(run_models(data, specs, n_boot=n_boot, seed=seed, boot_method=boot_method), "regressions")
    hyp = _ordered(judge_hypotheses(regressions, plan.hypotheses, plan.alpha), "hypotheses")

    for _, r in reliability.iterrows():
        if r["ave"] < 0.5:
            warn.append(f"{r['construct']}: AVE = {r['ave']:.3f} < 0.5 (convergent validity not met)")
    for _, r in fl[~fl["pass"]].iterrows():
        warn.append(f"Fornell-Larcker fails for {r['a']}-{r['b']}: |r| = {abs(r['r']):.3f} >= "
                    f"min sqrt(AVE) = {min(r['sqrt_ave_a'], r['sqrt_ave_b']):.3f}")
    settings = {"instrument": inst.name, "listwise": listwise, "loadings": loading_method, "n_boot": n_boot,
                "seed": seed, "boot_method": boot_method, "dropped_items": list(plan.dropped), "rules": plan.rules,
                "models": [m.__dict__ for m in specs], "hypothesis_alpha": plan.alpha,
                "study": study.study_id, "study_hash": study.hash,
                "hypothesis_signs": {h.hypothesis: h.sign for h in plan.hypotheses},
                "covariates": cov_cols, "table_titles": table_titles(study),
                # the paper's row wording of Table 5 ("Step 1: Dependent Variable - BI") only where declared
                "paper_idioms": bool(study.settings.get("analysis", {}).get("paper_idioms", False)),
                "construct_labels": construct_labels(study, inst, list(constructs))}
    return SurveyAnalysis(descriptives=descriptives, loadings=loadings, fit=fit, reliability=reliability,
                          correlations=correlations, fornell_larcker=fl, htmt=ht, regressions=regressions,
                          hypotheses=hyp, composites=comp, latent_correlations=final.latent_corr, n=sample.n,
                          n_input=sample.n_input, settings=settings, warnings=warn, fits=fits)


LOADING_METHODS = ("cfa", "pca", "paf")


def _with_extraction(res, scored: pd.DataFrame, method: str, warn: list[str], stage: str):
    """A copy of the CFA result `res` whose std loadings ("loading") are SPSS-style extractions per construct."""
    import dataclasses

    from analysis.survey.extraction import construct_loadings

    ex, w = construct_loadings(scored, res.constructs, method, stage)
    warn += w
    lo = res.loadings.drop(columns="loading").merge(ex, on=["construct", "item"], how="left")
    return dataclasses.replace(res, loadings=lo[list(res.loadings.columns)])


def table_titles(study) -> dict[str, str]:
    """Titles of Tables 4 and 5 from ``[analysis]`` of study.toml: regression_title names the models ("TAM and
    TPB models" -> "Hierarchical regression analysis on TAM and TPB models"); Table 4 takes correlation_title, else
    the regression title with its last word "models" as "constructs"; without a regression_title both name the
    study's title.

    Examples
    --------
    >>> from analysis.survey.acceptance import table_titles
    >>> from pedas.paths import REPO_ROOT
    >>> from study.folder.definition import load
    >>> table_titles(load(REPO_ROOT / "studies" / "lane_keeping"))["table4"]
    'Inter-construct correlation matrix of the UTAUT constructs'
    """
    an = study.settings.get("analysis", {})
    rt = an.get("regression_title")
    if not rt:
        return {"table4": an.get("correlation_title") or f"Inter-construct correlation matrix: {study.title}",
                "table5": f"Hierarchical regression analysis: {study.title}"}
    what = rt[:-len(" models")] if rt.endswith(" models") else rt
    return {"table4": an.get("correlation_title") or f"Inter-construct correlation matrix of the {what} constructs",
            "table5": f"Hierarchical regression analysis on {rt}"}


def construct_labels(study, instrument, constructs: list[str]) -> dict[str, str]:
    """Construct -> its label in Table 3: ``[analysis.construct_labels]`` of study.toml, else
    "<codebook section> (<construct>)" when all its items share one section, else the construct's name."""
    given = study.settings.get("analysis", {}).get("construct_labels", {}) or {}
    out = {}
    for c in constructs:
        if c in given:
            out[c] = str(given[c])
            continue
        sections = set(instrument.items.loc[instrument.constructs.get(c, []), "section"])
        sec = next(iter(sections)) if len(sections) == 1 else ""
        out[c] = f"{sec} ({c})" if sec and sec != c else c
    return out


def responses_from_store(st, *, instrument=None) -> pd.DataFrame:
    """The wide survey frame of the included participants (exclusions scope 'subjective') from a store: the final
    answers as ``study.survey.answers.final_responses`` resolves double entry, for the store's study's instrument."""
    from study.people.exclusions import included_participants
    from study.store.studies import definition
    from study.survey.answers import final_responses

    inst = resolve_instrument(definition(st), instrument)
    wide = final_responses(st, inst.name)
    keep = {str(p) for p in included_participants(st, "subjective")}
    wide = wide[wide["participant_id"].astype(str).isin(keep)]
    cols = ["participant_id"] + [c for c in inst.scaled_items if c in wide.columns]
    return wide[cols].reset_index(drop=True)


def attributes_from_store(st) -> pd.DataFrame:
    """participant_id + one typed column per declared attribute (``study.people.participants.participant_attributes``)."""
    from study.people.participants import participant_attributes

    attrs = participant_attributes(st)
    return attrs.reset_index() if ID_COL not in attrs.columns and attrs.index.name == ID_COL else attrs


def analyze_store(st, *, instrument=None, model=None, **kw) -> tuple[SurveyAnalysis, pd.DataFrame]:
    """`analyze_survey` of a store's included answers with its study and, when the model uses covariates, its
    participants' attributes; returns (analysis, the responses analysed). Keyword arguments as analyze_survey."""
    from study.store.studies import definition

    study = definition(st)
    responses = responses_from_store(st, instrument=instrument)
    if responses.empty:
        raise ValueError("the store has no survey answers of included participants")
    attrs = attributes_from_store(st) if covariates_of(study, instrument, model) else None
    return analyze_survey(responses, study, attributes=attrs, instrument=instrument, model=model, **kw), responses


def covariates_of(study, instrument=None, model=None) -> list[str]:
    """The participant attributes the regressions of `study` (or of `model`) use as covariates."""
    return survey_plan(study, resolve_instrument(study, instrument), _model(study, model)).covariates
