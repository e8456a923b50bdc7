"""The ``[within]`` table of ``study.toml``: which declared scores and drive KPIs a within-subjects study compares
across which of its conditions (docs/study_folder.md, "Within-subjects comparisons").

.. code-block:: toml

    [within]
    conditions = ["none", "visual", "audiovisual"]   # default: every declared condition, in declaration order
    scores = ["sus", "tlx_raw", "trust"]             # scores declared by the study's instruments
    kpis = ["takeover_time"]                         # KPIs declared in the KPI file (or built-in KPI columns)
    period = true                                    # the drive's period as a fixed effect of the mixed model

Every protocol order must drive each compared condition once (otherwise a participant cannot be measured under
all of them); the check below runs with every parse of a study (:mod:`study.common.file_checks`).
"""
from __future__ import annotations

from dataclasses import dataclass

from study.common.file_checks import register_file_check
from study.common.toml_lines import line_of

STUDY_FILE = "study.toml"
KEYS = ("conditions", "scores", "kpis", "period")


@dataclass(frozen=True)
class WithinSpec:
    """A study's declared within-subjects comparison."""
    conditions: tuple[str, ...]
    scores: tuple[str, ...] = ()
    kpis: tuple[str, ...] = ()
    period: bool = True


def within_spec(study) -> WithinSpec | None:
    """The ``[within]`` declaration of a :class:`study.folder.definition.StudyDefinition`, None when it has none (a checked
    study: the values are those :func:`_check_study` accepted)."""
    raw = study.settings.get("within")
    if not isinstance(raw, dict):
        return None
    return WithinSpec(conditions=tuple(raw.get("conditions") or study.condition_names),
                      scores=tuple(raw.get("scores", ())), kpis=tuple(raw.get("kpis", ())),
                      period=bool(raw.get("period", True)))


def _names(raw: dict, key: str, text: str, problems) -> list[str]:
    value = raw.get(key, [])
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        problems.add(STUDY_FILE, line_of(text, key, "within"), f"within.{key}", "must be a list of names")
        return []
    if dup := sorted({v for v in value if value.count(v) > 1}):
        problems.add(STUDY_FILE, line_of(text, key, "within"), f"within.{key}", f"{', '.join(dup)} listed twice")
    return value


def declared_kpis(study) -> set[str]:
    """Every KPI column the study's KPI file yields (built-in columns and the study's own KPIs)."""
    from study.common.problems import StudyError
    from study.folder.kpi_spec import study_spec

    try:
        return set(study_spec(study).columns)
    except StudyError:      # the KPI file's own check reports its problems
        return set()


def declared_scores(study) -> set[str] | None:
    """Every score the study's instruments declare; None when the instruments cannot be read (their own check
    reports why)."""
    from study.folder.scores import study_scores

    try:
        return {s.name for s in study_scores(study)}
    except Exception:  # noqa: BLE001 - the instrument's own check names the problem
        return None


def _check_study(study, problems) -> None:
    raw = study.settings.get("within")
    if raw is None:
        return
    text = study.files.get(STUDY_FILE, "")
    if not isinstance(raw, dict):
        problems.add(STUDY_FILE, line_of(text, "", "within"), "within", "must be a table")
        return
    for key in raw:
        if key not in KEYS:
            problems.add(STUDY_FILE, line_of(text, key, "within"), f"within.{key}",
                         f"unknown key (known: {', '.join(KEYS)})")
    if "period" in raw and not isinstance(raw["period"], bool):
        problems.add(STUDY_FILE, line_of(text, "period", "within"), "within.period", "must be true or false")
    conditions = _names(raw, "conditions", text, problems) if "conditions" in raw else list(study.condition_names)
    if unknown := [c for c in conditions if c not in study.condition_names]:
        problems.add(STUDY_FILE, line_of(text, "conditions", "within"), "within.conditions",
                     f"{', '.join(unknown)} not declared in [[conditions]] ({'|'.join(study.condition_names)})")
    if len(set(conditions)) < 2:
        problems.add(STUDY_FILE, line_of(text, "conditions", "within") or line_of(text, "", "within"),
                     "within.conditions", "a within-subjects comparison needs two or more conditions")
    scores, kpis = _names(raw, "scores", text, problems), _names(raw, "kpis", text, problems)
    if not scores and not kpis:
        problems.add(STUDY_FILE, line_of(text, "", "within"), "within",
                     "declares nothing to compare: list scores and/or kpis")
    if scores:
        known = declared_scores(study)
        if known is not None and (unknown := [s for s in scores if s not in known]):
            problems.add(STUDY_FILE, line_of(text, "scores", "within"), "within.scores",
                         f"{', '.join(unknown)}: no instrument of the study declares such a score"
                         + (f" (declared: {', '.join(sorted(known))})" if known else " (it declares none)"))
    if kpis:
        known = declared_kpis(study)
        if unknown := [k for k in kpis if k not in known]:
            problems.add(STUDY_FILE, line_of(text, "kpis", "within"), "within.kpis",
                         f"{', '.join(unknown)}: not a KPI of the study's KPI file"
                         + (f" (declared: {', '.join(sorted(known))})" if known else ""))
    _check_orders(study, conditions, problems)


def _check_orders(study, conditions: list[str], problems) -> None:
    """Every order of every protocol drives each compared condition exactly once."""
    from study.common.errors import UserError
    from study.folder.protocol_file import parse_protocol, protocol_orders

    for rel in study.paths.get("protocols", []):
        if rel not in study.files:
            continue
        try:
            proto = parse_protocol(study.files[rel], rel)
        except UserError:   # the protocol's own check reports it
            continue
        cond = {p.name: p.condition for p in proto.steps if p.drive}
        for order, seq in protocol_orders(proto).items():
            driven = [cond[p] for p in seq if p in cond]
            bad = [c for c in conditions if driven.count(c) != 1]
            if bad:
                problems.add(rel, None, f"orders.{order}",
                             f"drives {', '.join(f'{c} {driven.count(c)}x' for c in bad)}: a within-subjects "
                             f"comparison needs each compared condition driven once in every order")


register_file_check(_check_study)

