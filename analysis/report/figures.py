"""Study-level figures: the participant flow from enrolment to the analysed samples, and the item-level Likert chart."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from analysis.render import save_figure as save  # noqa: E402


@dataclass(frozen=True)
class ParticipantFlow:
    """Counts from enrolment to the analysed samples, with the exclusion reasons."""

    enrolled: int
    excluded_all: pd.Series          # reason -> count (scope all)
    subjective_sample: int
    excluded_subjective: pd.Series   # reason -> count (scope subjective)
    excluded_objective: pd.Series    # reason -> count (scope objective)
    objective_sample: int
    # the branches the store has data for: a study without survey answers has no survey sample, one without drives
    # no drive sample (the flow shows only the analyses that can run)
    has_survey: bool = True
    has_drives: bool = True

    def frame(self) -> pd.DataFrame:
        rows = [("enrolled", "", self.enrolled)]
        rows += [("excluded (all analyses)", r, int(n)) for r, n in self.excluded_all.items()]
        if self.has_survey:
            rows += [("excluded (survey)", r, int(n)) for r, n in self.excluded_subjective.items()]
        if self.has_drives:
            rows += [("excluded (drives)", r, int(n)) for r, n in self.excluded_objective.items()]
        rows += [("survey sample", "", self.subjective_sample)] if self.has_survey else []
        rows += [("drive sample", "", self.objective_sample)] if self.has_drives else []
        return pd.DataFrame(rows, columns=["stage", "reason", "n"])

    def branches(self) -> list[tuple[str, pd.Series, int]]:
        """(label, exclusion reasons, sample size) of each analysed sample the store has data for."""
        return ([("Survey (subjective) sample", self.excluded_subjective, self.subjective_sample)]
                if self.has_survey else []) + \
            ([("Drive (objective) sample", self.excluded_objective, self.objective_sample)] if self.has_drives else [])


def participant_flow(st) -> ParticipantFlow:
    """Participant flow of a store, through the one exclusion function the analyses use."""
    from study.people.exclusions import included_participants

    exc = st.df("SELECT scope, reason FROM exclusions")

    def reasons(scope: str) -> pd.Series:
        return exc.loc[exc["scope"] == scope, "reason"].value_counts().sort_index()

    return ParticipantFlow(
        enrolled=int(st.one("SELECT count(*) FROM participants")),
        excluded_all=reasons("all"),
        subjective_sample=len(included_participants(st, "subjective")),
        excluded_subjective=reasons("subjective"),
        excluded_objective=reasons("objective"),
        objective_sample=len(included_participants(st, "objective")),
        has_survey=bool(st.one("SELECT count(*) FROM responses")),
        has_drives=bool(st.one("SELECT count(*) FROM drives")),
    )


def _fmt(reasons: pd.Series) -> str:
    return "\n".join(f"{r.replace('_', ' ')}: {int(n)}" for r, n in reasons.items()) or "none"


def plot_participant_flow(flow: ParticipantFlow, out_dir: Path, stem: str = "participant_flow") -> list[Path]:
    """CONSORT-style flow: enrolled -> (excluded from all) -> took part -> the survey and drive branches the store
    has data for (:meth:`ParticipantFlow.branches`), each with its own exclusions beside the arrow."""
    took_part = flow.enrolled - int(flow.excluded_all.sum())
    fig, ax = plt.subplots(figsize=(8.5, 5.2))
    ax.set_axis_off()
    box = dict(boxstyle="round,pad=0.5", fc="#eef3f8", ec="#2b5d8a")
    side = dict(boxstyle="round,pad=0.4", fc="#fbeeee", ec="#a33")
    arrow = dict(arrowstyle="->", color="#444")
    into_box = dict(arrowstyle="<-", color="#444")  # drawn from the box's text, so it ends at the box's edge
    line = dict(arrowstyle="-", color="#444")
    ax.text(0.5, 0.94, f"Enrolled\nN = {flow.enrolled}", ha="center", va="center", bbox=box, fontsize=11)
    ax.annotate("", xy=(0.5, 0.64), xytext=(0.5, 0.88), arrowprops=arrow)
    ax.annotate(f"Excluded from all analyses\n{_fmt(flow.excluded_all)}", xy=(0.5, 0.77), xytext=(0.84, 0.77),
                ha="center", va="center", bbox=side, fontsize=9, arrowprops=into_box)
    ax.text(0.5, 0.58, f"Took part\nN = {took_part}", ha="center", va="center", bbox=box, fontsize=11)
    branches = flow.branches()
    # two samples side by side, their exclusions outside; one sample straight below, its exclusions to the right
    places = [(0.3, 0.1), (0.7, 0.9)] if len(branches) == 2 else [(0.5, 0.84)]
    for (x, sx), (label, reasons, n) in zip(places, branches):
        if len(branches) > 1:   # the fork; a single sample's arrow starts at the box
            ax.annotate("", xy=(x, 0.45), xytext=(0.5, 0.52), arrowprops=line)
        ax.annotate("", xy=(x, 0.14), xytext=(x, 0.45 if len(branches) > 1 else 0.52), arrowprops=arrow)
        ax.annotate(f"Excluded\n{_fmt(reasons)}", xy=(x, 0.31), xytext=(sx, 0.31), ha="center", va="center",
                    bbox=side, fontsize=8.5, arrowprops=into_box)
        ax.text(x, 0.08, f"{label}\nN = {n}", ha="center", va="center", bbox=box, fontsize=10)
    ax.set_xlim(-0.05, 1.05)
    ax.set_ylim(0.0, 1.0)
    ax.set_title("Participant flow", fontsize=12)
    return save(fig, out_dir, stem)


def likert_distribution(responses: pd.DataFrame, items: list[str], points=range(1, 6)) -> pd.DataFrame:
    """Share (%) of answers per scale point (`points`, default 1..5) per item (raw answers as ticked), missing
    answers left out; rows in `items` order."""
    points = list(points)
    cols = [i for i in items if i in responses]
    counts = pd.DataFrame({i: responses[i].dropna().astype(int).value_counts().reindex(points, fill_value=0)
                           for i in cols}, index=points).T
    return counts.div(counts.sum(axis=1).replace(0, np.nan), axis=0) * 100.0


# the 5-point palette (ColorBrewer RdBu); other scales sample the same colour map
FIVE_COLORS = ["#b2182b", "#ef8a62", "#d9d9d9", "#67a9cf", "#2166ac"]


def _colors(k: int) -> list:
    if k == 5:
        return FIVE_COLORS
    cmap = plt.get_cmap("RdBu")
    return [cmap(x) for x in np.linspace(0.1, 0.9, k)]


def plot_likert(responses: pd.DataFrame, instrument, out_dir: Path, stem: str = "likert_items") -> list[Path]:
    """Diverging stacked bars of the raw answers per scaled item of the study's instrument (neutral centred),
    grouped by construct. Items on different scales share the axis of the widest one (lowest scale_min to highest
    scale_max)."""
    items = instrument.scaled_items
    scales = [instrument.scale(i) for i in items]
    lo, hi = min(s[0] for s in scales), max(s[1] for s in scales)
    points = list(range(lo, hi + 1))
    k = len(points)
    share = likert_distribution(responses, items, points)
    colors = _colors(k)
    fig, ax = plt.subplots(figsize=(8, 0.32 * len(share) + 1.4))
    y = np.arange(len(share))[::-1]
    # the bars start left of 0 by the share below the middle point (and half of the middle point on odd scales)
    left = -(sum(share[p] for p in points[:k // 2]) + (share[points[k // 2]] / 2.0 if k % 2 else 0.0))
    for j, p in enumerate(points):
        ax.barh(y, share[p], left=left, color=colors[j], edgecolor="white", linewidth=0.4,
                label=str(p) if p not in (lo, hi) else (f"{lo} strongly disagree / negative anchor" if p == lo else
                                                        f"{hi} strongly agree / positive anchor"))
        left = left + share[p]
    labels = [f"{i}{' (R)' if i in instrument.reverse_items else ''}" for i in share.index]
    ax.set_yticks(y, labels, fontsize=8)
    ax.axvline(0, color="#333", lw=0.8)
    ax.set_xlabel("share of answers (%) — left of 0: below neutral, right: above")
    ax.set_xlim(-100, 100)
    ax.legend(ncol=min(k, 7), fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12 - 2.0 / (len(share) + 4)),
              frameon=False)
    ax.set_title(f"Item-level answer distribution (n = {len(responses)}; R = reverse-scored item, raw answers)",
                 fontsize=10)
    return save(fig, out_dir, stem)
