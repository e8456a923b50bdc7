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

    def frame(self) -> pd.DataFrame:
        rows = [("enrolled", "", self.enrolled)]
        rows += [("excluded (all analyses)", r, int(n)) for r, n in self.excluded_all.items()]
        rows += [("excluded (survey)", r, int(n)) for r, n in self.excluded_subjective.items()]
        rows += [("excluded (drives)", r, int(n)) for r, n in self.excluded_objective.items()]
        rows += [("survey sample", "", self.subjective_sample), ("drive sample", "", self.objective_sample)]
        return pd.DataFrame(rows, columns=["stage", "reason", "n"])


def participant_flow(st) -> ParticipantFlow:
    """Participant flow of a store, through the one exclusion function the analyses use."""
    from study.exclusions import included_participants

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
    )


def _fmt(reasons: pd.Series) -> str:
    return "\n".join(f"{r.replace('_', ' ')}: {int(n)}" for r, n in reasons.items()) or "none"


def plot_participant_flow(flow: ParticipantFlow, out_dir: Path, stem: str = "participant_flow") -> list[Path]:
    """CONSORT-style flow: enrolled -> (excluded from all) -> took part -> survey and drive branches, each with its
    own exclusions beside the arrow."""
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
    for x, sx, label, reasons, n in ((0.3, 0.1, "Survey (subjective) sample", flow.excluded_subjective,
                                      flow.subjective_sample),
                                     (0.7, 0.9, "Drive (objective) sample", flow.excluded_objective,
                                      flow.objective_sample)):
        ax.annotate("", xy=(x, 0.45), xytext=(0.5, 0.52), arrowprops=line)
        ax.annotate("", xy=(x, 0.14), xytext=(x, 0.45), arrowprops=arrow)
        ax.annotate(f"Excluded\n{_fmt(reasons)}", xy=(x, 0.31), xytext=(sx, 0.31), ha="center", va="center",
                    bbox=side, fontsize=8.5, arrowprops=into_box)
        ax.text(x, 0.08, f"{label}\nN = {n}", ha="center", va="center", bbox=box, fontsize=10)
    ax.set_xlim(-0.05, 1.05)
    ax.set_ylim(0.0, 1.0)
    ax.set_title("Participant flow", fontsize=12)
    return save(fig, out_dir, stem)


def likert_distribution(responses: pd.DataFrame, items: list[str]) -> pd.DataFrame:
    """Share (%) of answers 1..5 per item (raw answers as ticked), missing answers left out; rows in `items` order."""
    cols = [i for i in items if i in responses]
    counts = pd.DataFrame({i: responses[i].dropna().astype(int).value_counts().reindex(range(1, 6), fill_value=0)
                           for i in cols}).T
    return counts.div(counts.sum(axis=1).replace(0, np.nan), axis=0) * 100.0


def plot_likert(responses: pd.DataFrame, instrument, out_dir: Path, stem: str = "likert_items") -> list[Path]:
    """Diverging stacked bars of the raw 1..5 answers per item (neutral centred), grouped by construct."""
    items = instrument.scaled_items
    share = likert_distribution(responses, items)
    colors = ["#b2182b", "#ef8a62", "#d9d9d9", "#67a9cf", "#2166ac"]
    fig, ax = plt.subplots(figsize=(8, 0.32 * len(share) + 1.4))
    y = np.arange(len(share))[::-1]
    left = -(share[1] + share[2] + share[3] / 2.0)
    for k in range(1, 6):
        ax.barh(y, share[k], left=left, color=colors[k - 1], edgecolor="white", linewidth=0.4,
                label=str(k) if k not in (1, 5) else ("1 strongly disagree / negative anchor" if k == 1 else
                                                       "5 strongly agree / positive anchor"))
        left = left + share[k]
    labels = [f"{i}{' (R)' if i in instrument.reverse_items else ''}" for i in share.index]
    ax.set_yticks(y, labels, fontsize=8)
    ax.axvline(0, color="#333", lw=0.8)
    ax.set_xlabel("share of answers (%) — left of 0: below neutral, right: above")
    ax.set_xlim(-100, 100)
    ax.legend(ncol=5, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12 - 2.0 / (len(share) + 4)),
              frameon=False)
    ax.set_title(f"Item-level answer distribution (n = {len(responses)}; R = reverse-scored item, raw answers)",
                 fontsize=10)
    return save(fig, out_dir, stem)
