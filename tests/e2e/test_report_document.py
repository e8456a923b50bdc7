"""The report document (`index.html`, analysis.report.document) of a small survey-only study: the lane-keeping example
with 24 registered participants, the committed survey answers and no drives. Read as HTML, and rendered in Debian's
headless Chromium (Playwright): headings in order, every image loaded, tables visible, no horizontal overflow at
1280 px; a full-page screenshot is kept in tests/output/report_document.png."""
from __future__ import annotations

import re
from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest

from analysis.report.document import SECTIONS, markdown_to_html
from analysis.report.exhibits import read_exhibits
from tests.conftest import needs_chromium

# the simulator does not drive its conditions and it declares no published values: those sections are absent
LK_SECTIONS = list(SECTIONS)

REPO = Path(__file__).resolve().parents[2]
LK_STUDY = REPO / "studies" / "lane_keeping"
LK_DATA = REPO / "tests" / "data" / "lane_keeping"
OUTPUT = REPO / "tests" / "output"


def run(db: Path, *args) -> None:
    from pedas_study.cli import main

    assert main([f"--db={db}", *map(str, args)]) == 0, args


@pytest.fixture(scope="module")
def lk_report(tmp_path_factory):
    """(output folder, store) of a report on a lane-keeping store with answers, phases and two exclusions."""
    tmp = tmp_path_factory.mktemp("lk_report")
    db = tmp / "lk.duckdb"
    run(db, "init", "--study", LK_STUDY)
    people = pd.read_csv(LK_DATA / "participants.csv", dtype={"participant_id": str})
    for r in people.itertuples():
        run(db, "participant", "add", r.participant_id, "--attr", f"age={r.age}")
    run(db, "session", "advance", "LK-01", "familiarisation")
    run(db, "session", "advance", "LK-02", "familiarisation")
    run(db, "session", "abort", "LK-02", "--reason", "motion sickness")
    run(db, "exclude", "LK-02", "--scope", "all", "--reason", "motion_sickness")
    run(db, "exclude", "LK-03", "--scope", "subjective", "--reason", "withdrawn")
    run(db, "survey", "import", LK_DATA / "survey.csv")
    out = tmp / "reports"
    run(db, "report", "--out", out, "--bootstrap", "50", "--cache-dir", tmp / "cache")
    return out, db


class _Outline(HTMLParser):
    def __init__(self):
        super().__init__()
        self.headings: list[tuple[str, str]] = []
        self.images: list[str] = []
        self.refs: list[str] = []
        self._in: str | None = None
        self.tags: set[str] = set()

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.add(tag)
        if tag in ("h1", "h2"):
            self._in = tag
            self.headings.append((tag, ""))
        if tag == "img":
            self.images.append(a["src"])
        for k in ("src", "href"):
            if a.get(k):
                self.refs.append(a[k])

    def handle_endtag(self, tag):
        if tag == self._in:
            self._in = None

    def handle_data(self, data):
        if self._in:
            tag, text = self.headings[-1]
            self.headings[-1] = (tag, text + data)


@pytest.mark.slow
def test_document_reads_top_to_bottom(lk_report):
    out, _ = lk_report
    doc = (out / "index.html").read_text(encoding="utf-8")
    outline = _Outline()
    outline.feed(doc)
    # no "Simulation core" section: the simulator does not drive this study's conditions
    assert outline.headings == [("h1", "Acceptance of a lane-keeping head-up display")] + \
        [("h2", s) for s in LK_SECTIONS]
    # the study summary: 24 registered, 22 in the survey analysis (LK-02 excluded from all, LK-03 from the survey)
    assert "24 registered; 22 in the survey analysis</dd>" in doc   # no drives stored: no drive sample
    assert "<code>hud</code> (Drive with the lane-keeping HUD)" in doc
    # LK-01 in familiarisation, LK-02 aborted in it: completed 0, aborted 1, in progress 1
    assert "<td>familiarisation</td><td class=\"r\">0</td><td class=\"r\">1</td><td class=\"r\">1</td>" in doc
    # methods from the declaration: software versions, estimators, age in step 1, signs
    assert re.search(r"semopy \d+\.\d+", doc) and re.search(r"statsmodels \d+\.\d+", doc)
    # the software list names what the run used: no simulation, so no QP solver and no SUMO
    software = re.search(r"<strong>Software\.</strong> ([^<]*)</p>", doc).group(1)
    assert not any(name in software for name in ("OSQP", "DAQP", "SUMO")), software
    assert "model 1, BI: step 1: age; step 2: PE + EE + SI" in doc
    assert "H1: PE -&gt; BI in model 1 step 2 (expected positive: β &gt; 0 and two-sided p &lt; α)" in doc
    assert "reverse-scored: EE3" in doc and "7-point" in doc
    # the survey results: the study's regression table and the three verdicts
    assert "UTAUT models" in doc
    hyp = pd.read_csv(out / "survey" / "hypotheses.csv")
    assert list(hyp["hypothesis"]) == ["H1", "H2", "H3"]
    n_ok = int(hyp["supported"].astype(str).str.lower().isin(["true", "1"]).sum())
    assert f"{n_ok} of 3 hypotheses supported at α = .05" in doc
    for h in ("H1", "H2", "H3"):
        assert re.search(rf"<tr><td>{h}</td><td>[A-Z]+ -&gt; BI</td><td>positive</td>", doc), h
    # what the study does not have is skipped with its reason, not failed
    assert "Skipped: the store has no drives, so there are no drive KPIs." in doc
    # a part the study's declaration rules out is absent: no published values, no reproduction section
    assert "id=\"reproduction\"" not in doc and "declares no published values" in doc  # (the steps table says why)
    # a part that belongs only to the simulator's studies is absent, not skipped
    assert "simulation core" not in doc.lower() and "core figures" not in doc
    # every figure written is shown with its caption, and has a reading from the numbers
    pngs = sorted(f"figures/{p.name}" for p in (out / "figures").glob("*.png"))
    assert pngs == ["figures/likert_items.png", "figures/participant_flow.png", "figures/path_diagram.png"]
    assert sorted(outline.images) == pngs
    assert "24 enrolled; 22 in the survey sample" in doc
    # no drives in this study: the flow has no drive branch (figure and table)
    stages = set(pd.read_csv(out / "tables" / "participant_flow.csv")["stage"])
    assert "survey sample" in stages and "drive sample" not in stages and "excluded (drives)" not in stages
    # self-contained: no scripts, no external resources, every relative link points at a written file
    assert "script" not in outline.tags and "link" not in outline.tags
    for ref in outline.refs:
        if ref.startswith("#"):   # a link within the document: to a section or a numbered exhibit
            assert f"id=\"{ref[1:]}\"" in doc, ref
            continue
        assert not re.match(r"^[a-z]+:", ref) and not ref.startswith("/"), ref
        assert (out / ref.split("#")[0]).is_file(), ref
    # every table written into tables/ is inline, numbered, and listed in exhibits.json in reading order
    for md in (out / "tables").glob("*.md"):
        assert f"id=\"x-{md.stem}\"" in doc, md.stem
    exhibits = read_exhibits(out)
    assert {e.stem for e in exhibits} >= {p.stem for p in (out / "tables").glob("*.md")} | {"participant_flow"}
    for kind, word in (("table", "Table"), ("figure", "Figure")):
        for part, prefix in (("main", ""), ("appendix", "A")):
            labels = [e.label for e in exhibits if e.kind == kind and e.part == part]
            assert labels == [f"{word} {prefix}{k}" for k in range(1, len(labels) + 1)], labels
    parts = [e.part for e in exhibits]
    assert parts == sorted(parts, key=lambda p: p != "main")      # the main text first, then the appendix
    labels_in_doc = re.findall(r"<p class=\"xlabel\">([^<]+)</p>", doc)
    assert labels_in_doc == [e.label for e in exhibits]           # the same numbers, in the document's order
    assert sum(e.part == "main" for e in exhibits) <= 10
    for e in exhibits:
        assert e.title and all((out / f).is_file() for f in e.files.values()), e
    # each table and figure once (the protocol phases were numbered twice)
    assert len({(e.kind, e.stem) for e in exhibits}) == len(exhibits)
    # the paper's idioms only where declared (studies/pedas_paper): no principal-component Table 3 here
    assert not (out / "survey" / "pca").exists() and not list((out / "tables").glob("survey_pca_*"))
    assert not [e for e in exhibits if "pca" in e.stem or "principal component" in (e.title + e.note).lower()]
    assert "principal component" not in doc and "Dependent Variable -" not in doc
    # APA numbers: no p with a leading zero, intervals as [LL, UL], the true minus sign
    assert not re.search(r"p [=<] 0\.", doc) and not re.search(r"\d – [−\d]", doc) and "−" in doc


@pytest.mark.slow
def test_document_bytes_are_deterministic(lk_report, tmp_path):
    """A second run with nothing changed renders the same bytes (no times, no absolute paths)."""
    out, db = lk_report
    before = (out / "index.html").read_bytes()
    run(db, "report", "--out", out, "--bootstrap", "50", "--cache-dir", out.parent / "cache")
    assert (out / "index.html").read_bytes() == before
    assert str(out.parent).encode() not in before


def test_markdown_cells_and_text_are_escaped():
    md = "**Title <b>**\n\n| a | b\\|c |\n|---|---:|\n| <script>x</script> | 1 |\n\n_note & more_\n"
    out = markdown_to_html(md)
    assert "<caption>Title &lt;b&gt;</caption>" in out
    assert "<th>a</th><th class=\"r\">b|c</th>" in out
    assert "<td>&lt;script&gt;x&lt;/script&gt;</td><td class=\"r\">1</td>" in out
    assert "<p class=\"note\"><em>note &amp; more</em></p>" in out
    assert "<script>" not in out


@pytest.mark.browser
@needs_chromium
def test_document_in_chromium(lk_report, browser):
    out, _ = lk_report
    OUTPUT.mkdir(exist_ok=True)
    shot = OUTPUT / "report_document.png"
    shot.unlink(missing_ok=True)
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    page.goto((out / "index.html").as_uri())
    page.wait_for_load_state("load")
    headings = page.eval_on_selector_all("h1, h2", "els => els.map(e => e.tagName + ' ' + e.textContent)")
    assert headings == ["H1 Acceptance of a lane-keeping head-up display"] + [f"H2 {s}" for s in LK_SECTIONS]
    images = page.eval_on_selector_all("img", "els => els.map(e => [e.getAttribute('src'), e.complete, "
                                              "e.naturalWidth])")
    assert len(images) == 3 and all(done and width > 0 for _, done, width in images), images
    tables = page.locator("table")
    assert tables.count() >= 10
    for k in range(tables.count()):
        assert tables.nth(k).is_visible(), k
    width = page.evaluate("[document.documentElement.scrollWidth, document.documentElement.clientWidth]")
    assert width[0] <= width[1] == 1280, width
    page.screenshot(path=str(shot), full_page=True)
    assert shot.stat().st_size > 10_000
