"""The third example study (studies/takeover, a within-subjects design) end to end through the CLI on a temporary
store, as that lab would run it: check the folder, create the store, import the roster of 19 participants, assign the
Latin square's orders, walk each through the familiarisation drive and the three condition drives with a post-drive
questionnaire after each (TOR-A19 breaks off before the third drive), then, after the fact, import the 20 Hz logs
(ms, mph, ft) with the takeover flags from one folder at once and the questionnaires as one wide file with a condition column, then
`analyze within` and the report. The statistics are compared with R's (tests/data/takeover/within_reference.json: afex/aov with Error(),
friedman.test, paired tests, lme4::lmer), the takeover-time KPI with the log generator's truth. Every command and what
it printed is written to tests/output/takeover_e2e.txt."""
from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from tests.conftest import OUTPUT, REPO
from tests.takeover_logs import RATE_HZ, TOR_AT_S, takeover_time, write_log

STUDY = REPO / "studies" / "takeover"
DATA = REPO / "tests" / "data" / "takeover"
CONDITIONS = ("none", "visual", "audiovisual")
DROPOUT = "TOR-A19"        # motion sickness in the third drive: two drives and two questionnaires
#: our score name -> the R reference's
R_NAME = {"sus": "sus", "tlx_raw": "tlx", "trust": "trust"}

pytestmark = [pytest.mark.slow]


class Transcript:
    """Runs `pedas-study --db DB ...` in-process and records each command with its output."""

    def __init__(self, db, capsys):
        self.db, self.capsys, self.lines = db, capsys, []

    def __call__(self, *args, db: bool = True, quiet: bool = False, code: int = 0) -> str:
        from pedas_study.cli import main

        argv = ([f"--db={self.db}"] if db else []) + [str(a) for a in args]
        self.capsys.readouterr()
        try:
            got = main(argv)
        except SystemExit as exc:
            got = exc.code if isinstance(exc.code, int) else 2
        got = got or 0
        cap = self.capsys.readouterr()
        shown = [a.replace(str(self.db.parent) + "/", "").replace(str(REPO) + "/", "") for a in argv]
        if not quiet:
            self.lines.append("$ pedas-study " + " ".join(shown))
            text = (cap.out + cap.err).replace(str(self.db.parent) + "/", "")
            self.lines += [f"  {ln}" for ln in text.rstrip("\n").splitlines()]
            if got:
                self.lines.append(f"  (exit {got})")
        assert got == code, f"`pedas-study {' '.join(shown)}` exit {got}, wanted {code}: {cap.err.strip()}"
        return cap.out + cap.err

    def write(self) -> str:
        text = "\n".join(self.lines) + "\n"
        OUTPUT.mkdir(exist_ok=True)
        (OUTPUT / "takeover_e2e.txt").write_text(text, encoding="utf-8")
        return text


@pytest.fixture(scope="module")
def reference():
    """R's statistics (within_reference.json), the rank tests from R on the scores at their resolution
    (rank_reference.json) in "ranked"."""
    ref = json.loads((DATA / "within_reference.json").read_text())
    return {**ref, "ranked": json.loads((DATA / "rank_reference.json").read_text())}


def test_takeover_study_end_to_end(tmp_path, capsys, reference):
    db = tmp_path / "tor.duckdb"
    run = Transcript(db, capsys)
    items = pd.read_csv(DATA / "items.csv")
    people = items.drop_duplicates("participant")["participant"].tolist()
    logs = tmp_path / "logs"
    logs.mkdir()
    try:
        assert run("study", "check", STUDY, db=False).startswith("study takeover OK")
        run("init", "--study", STUDY)
        roster = tmp_path / "roster.csv"
        pd.DataFrame({"participant_id": people, "age": [21 + 2 * k for k in range(len(people))]}).to_csv(
            roster, index=False)
        assert "registered 19 participants" in run("participant", "import", roster)
        orders = {pid: run("session", "assign", pid, quiet=k > 2).strip().rsplit(" ", 1)[-1]
                  for k, pid in enumerate(people)}
        want = items.drop_duplicates("participant").set_index("participant")["order"]
        assert orders == want.to_dict()          # the Latin square's three orders in turn: 7/6/6 with TOR-A19

        protocol = json.loads((STUDY / "protocol.json").read_text())
        for k, pid in enumerate(people):
            for phase in protocol["orders"][orders[pid]]:
                if pid == DROPOUT and phase == "drive_audiovisual":
                    run("session", "abort", pid, "--reason", "motion sickness after the second drive")
                    break
                run("session", "advance", pid, phase, quiet=k > 0)
            else:
                run("session", "complete", pid, quiet=k > 0)

        # the end of the day: every log copied from the simulator into one folder, imported at once
        for pid in people:
            for condition in (None, *CONDITIONS):
                if not (pid == DROPOUT and condition == "audiovisual"):
                    write_log(logs, pid, condition)
        out = run("drive", "import", "--dir", logs, "--pattern", "{participant}_{condition}.csv")
        assert f"{4 * len(people) - 1} drive logs of {len(people)} participants" in out
        # the dropout never entered the third drive: a log for it is refused, naming the phases entered
        out = run("drive", "import", DROPOUT, "audiovisual", write_log(tmp_path, DROPOUT, "audiovisual"), code=2)
        assert f"{DROPOUT} has not entered the drive of audiovisual (drive_audiovisual); phases entered: " in out

        # the post-drive questionnaires of everyone, one wide file with a condition column
        answers = items.rename(columns={"participant": "participant_id"}).drop(columns=["order", "period"])
        wide = tmp_path / "post_drive.csv"
        answers.to_csv(wide, index=False)
        run("survey", "import", wide)

        out = run("analyze", "within", "--out", tmp_path / "within")
        assert "across none, visual, audiovisual" in out
        run("report", "--out", tmp_path / "reports", "--bootstrap", "0", "--cache-dir", tmp_path / "cache",
            "--bundle")
    finally:
        print(run.write())

    res = tmp_path / "within"
    diffs = r_differences(res, reference)
    (OUTPUT / "takeover_vs_r.md").write_text(diffs.to_markdown(index=False) + "\n", encoding="utf-8")
    print(diffs.to_string(index=False))
    # lmer's fixed effects: the REML optimum agrees to ~1e-8 (statsmodels' BFGS vs lme4's bobyqa); the rest is exact
    assert (diffs["max_abs_diff"] < np.where(diffs["group"] == "lmer fixed effects", 1e-6, 1e-9)).all(), diffs

    # the takeover time of every condition drive: the first 20 Hz sample with the hands on, after the request
    kpi = pd.read_csv(res / "descriptives.csv")
    truth = pd.DataFrame([{"participant": pid, "condition": c,
                           "value": np.ceil(takeover_time(pid, c) * RATE_HZ - 1e-9) / RATE_HZ}
                          for pid in people for c in CONDITIONS if not (pid == DROPOUT and c == "audiovisual")])
    means = truth.groupby("condition")["value"].mean()
    got = kpi[kpi["variable"] == "takeover_time"].set_index("condition")["mean"]
    assert np.allclose(got.loc[list(CONDITIONS)], means.loc[list(CONDITIONS)], atol=1e-9)
    assert TOR_AT_S > 0

    doc = (tmp_path / "reports" / "index.html").read_text(encoding="utf-8")
    assert "Within-subjects comparison" in doc and "Simulation core" not in doc
    # the paper's idioms only where declared: no principal-component table, each exhibit numbered once
    from analysis.report.exhibits import read_exhibits

    exhibits = read_exhibits(tmp_path / "reports")
    assert not [e for e in exhibits if "pca" in e.stem] and "principal component" not in doc
    assert len({(e.kind, e.stem) for e in exhibits}) == len(exhibits)
    # the takeover time in its declared unit in the result sentence, the scores without one
    sentence = next(ln for ln in (res / "methods.md").read_text().splitlines() if ln.startswith("- Takeover time:"))
    assert re.search(r"none: M = \d\.\d\d s, SD = \d\.\d\d s; visual: M = \d\.\d\d s", sentence), sentence
    assert re.search(r"none − visual = \d\.\d\d s, d_z = ", sentence), sentence
    assert re.search(r"- SUS \(0-100\): .* none: M = \d+\.\d\d, SD = \d+\.\d\d;", (res / "methods.md").read_text())
    assert re.search(r"pingouin \d", doc) and "DAQP" not in doc and "SUMO" not in doc
    # the variables by their labels and units in the main text's table and figure titles, not their identifiers
    assert "Takeover time (s) by Condition" in doc and "takeover_time by Condition" not in doc
    main_text = doc.split('id="appendix"')[0]
    assert "<td>Takeover time (s)</td>" in main_text and "<td>tlx_raw</td>" not in main_text
    # the bundle holds the within-subjects figures in three formats and every image the document shows
    import zipfile

    from analysis.report.bundle import document_images

    names = set(zipfile.ZipFile(tmp_path / "reports" / "bundle.zip").namelist())
    assert {f"figures/lines_{v}.{ext}" for v in ("sus", "tlx_raw", "trust", "takeover_time")
            for ext in ("png", "svg", "pdf")} <= names
    shown = document_images(tmp_path / "reports")
    assert len(shown) == 5 and set(shown) <= names


def r_differences(res, reference) -> pd.DataFrame:
    """group, variable, max |ours - R| over the quantities of that group (test_within's conventions)."""
    anova, friedman = pd.read_csv(res / "anova.csv"), pd.read_csv(res / "friedman.csv")
    posthoc, mixed = pd.read_csv(res / "posthoc.csv"), pd.read_csv(res / "mixed.csv")
    rows = []
    for ours, theirs in R_NAME.items():
        r = reference["variables"][theirs]
        a = anova[anova["variable"] == ours].iloc[0]
        f = friedman[friedman["variable"] == ours].iloc[0]
        ranked = reference["ranked"][theirs]
        afex = r["afex"]
        rows.append(("rm-ANOVA F, p, eta2, Mauchly, GG/HF", ours, max(
            abs(a["f"] - r["aov"]["f"]), abs(a["p"] - r["aov"]["p"]), abs(a["np2"] - afex["pes"]),
            abs(a["ng2"] - afex["ges"]), abs(a["mauchly_w"] - afex["mauchly_w"]),
            abs(a["mauchly_p"] - afex["mauchly_p"]), abs(a["eps_gg"] - afex["gg_eps"]),
            abs(a["p_gg"] - afex["gg_p"]), abs(a["p_hf"] - afex["hf_p"]))))
        rows.append(("Friedman chi2, p, W", ours, max(abs(f["chi2"] - ranked["friedman"]["chi2"]),
                                                     abs(f["p"] - ranked["friedman"]["p"]),
                                                     abs(f["kendall_w"] - ranked["friedman"]["kendall_w"]))))
        worst = 0.0
        for pair, rw in zip(r["pairs"], ranked["pairs"]):
            t = posthoc[(posthoc["variable"] == ours) & (posthoc["a"] == pair["a"]) & (posthoc["b"] == pair["b"])]
            tt, ww = t[t["test"] == "t"].iloc[0], t[t["test"] == "wilcoxon"].iloc[0]
            assert (rw["a"], rw["b"]) == (pair["a"], pair["b"])
            worst = max(worst, abs(tt["statistic"] - pair["t"]), abs(tt["p"] - pair["p_t"]),
                        abs(tt["p_holm"] - pair["p_t_holm"]), abs(tt["dz"] - pair["dz"]),
                        abs(ww["statistic"] - rw["v"]), abs(ww["p"] - rw["p"]), abs(ww["p_holm"] - rw["p_holm"]))
        rows.append(("paired t / Wilcoxon, Holm, d_z", ours, worst))
        m = mixed[mixed["variable"] == ours].reset_index(drop=True)
        coef = [t["coef"] for t in r["lmer_all"]["terms"]]
        rows.append(("lmer fixed effects", ours, float(np.max(np.abs(m["coef"].to_numpy() - np.array(coef))))))
    return pd.DataFrame(rows, columns=["group", "variable", "max_abs_diff"])
