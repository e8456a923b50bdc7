"""The submission bundle: one zip archive with what a reviewer needs to check and rerun a report (docs/report.md,
"Submission bundle").

Contents (paths inside the archive):

* ``README.md`` -- what is inside and the commands that rerun the report;
* ``tables/`` -- every table of the report as CSV, APA-style Markdown and LaTeX (copied from the report's
  ``tables/``), and ``tables/tables.docx`` with all of them (python-docx; APA style: numbered bold title, italic
  caption, horizontal rules only);
* ``figures/`` -- the report's figures (PNG) and ``index.html``, the report document;
* ``study/`` -- the study folder's files exactly as the store keeps them (study.toml, codebook, protocols, the
  model file in lavaan syntax), and ``model/`` -- any model syntax the analyses wrote (e.g. the SEM of
  ``analyze extended``);
* ``settings.json`` -- seeds, bootstrap resamples and the other report settings;
* ``versions.txt`` -- Python and the exact package versions of ``requirements.lock``;
* ``inputs.sha256`` -- a sha256 per store table and one over all of them. Provenance columns (who wrote a row and
  when) are left out, so the hash identifies the data, not the moment or the person that built the store.

The archive is deterministic: entries sorted, fixed dates, so the same report and store give the same bytes.
"""
from __future__ import annotations

import hashlib
import io
import json
import platform
import zipfile
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import pandas as pd

from pedas.paths import REPO_ROOT

LOCK_FILE = REPO_ROOT / "requirements.lock"
_EPOCH = (1980, 1, 1, 0, 0, 0)
# the log of writes, the schema's own bookkeeping and the link-token hashes are not study data
_SKIP_TABLES = {"audit_log", "schema_version", "survey_tokens"}
# when and by whom a row was written, and where a study folder was read from: provenance, not data (the visit
# times of phase_events and appointments are data and stay)
_PROVENANCE = {"created_at", "loaded_at", "entered_at", "submitted_at", "saved_at", "resolved_at", "issued_at",
               "revoked_at", "added_at", "assigned_at", "applied_at", "entered_by", "submitted_by", "resolved_by",
               "issued_by", "loaded_by"}


@dataclass(frozen=True)
class Bundle:
    """The archive written and the names of its entries, sorted."""

    path: Path
    files: tuple[str, ...]


def locked_versions(lock: Path = LOCK_FILE) -> list[str]:
    """``name==version`` of every package pinned in the lock file, in its order."""
    if not lock.exists():
        return []
    return [line.split()[0].rstrip("\\") for line in lock.read_text(encoding="utf-8").splitlines()
            if "==" in line and not line.startswith((" ", "#"))]


def table_hashes(st) -> pd.DataFrame:
    """sha256 of each store table (rows sorted, provenance columns left out: who wrote a row and when, and
    study_definitions.source); the last row ('*') hashes the others.

    Columns: table, rows, sha256."""
    rows = []
    for table in sorted(st.tables()):
        if table in _SKIP_TABLES:
            continue
        types = st.df("SELECT column_name, data_type FROM information_schema.columns WHERE table_name = ? "
                      "ORDER BY ordinal_position", [table])
        cols = [c for c in types["column_name"]
                if c not in _PROVENANCE and not (table == "study_definitions" and c == "source")]
        if not cols:
            continue
        quoted = ", ".join(f'"{c}"' for c in cols)
        df = st.df(f'SELECT {quoted} FROM "{table}" ORDER BY {quoted}')
        text = df.to_csv(index=False, lineterminator="\n", float_format="%.17g")
        rows.append({"table": table, "rows": len(df), "sha256": hashlib.sha256(text.encode()).hexdigest()})
    allh = hashlib.sha256("".join(f"{r['table']} {r['sha256']}\n" for r in rows).encode()).hexdigest()
    rows.append({"table": "*", "rows": sum(r["rows"] for r in rows), "sha256": allh})
    return pd.DataFrame(rows, columns=["table", "rows", "sha256"])


def tables_docx(tables_dir: Path) -> bytes:
    """Every ``*.csv`` table of `tables_dir` in one DOCX, APA style: "Table n" in bold, the caption in italics,
    the table with rules above and below the header and below the last row only."""
    import docx
    from docx.oxml import OxmlElement
    from docx.oxml.ns import qn
    from docx.shared import Pt

    doc = docx.Document()
    # fixed document dates: the same tables give the same bytes
    doc.core_properties.created = doc.core_properties.modified = datetime(2000, 1, 1)
    doc.core_properties.author = doc.core_properties.last_modified_by = ""
    style = doc.styles["Normal"]
    style.font.name, style.font.size = "Times New Roman", Pt(10)

    def rule(cell, edge: str) -> None:
        borders = cell._tc.get_or_add_tcPr().first_child_found_in("w:tcBorders")
        if borders is None:
            borders = OxmlElement("w:tcBorders")
            cell._tc.get_or_add_tcPr().append(borders)
        el = OxmlElement(f"w:{edge}")
        for k, v in (("val", "single"), ("sz", "6"), ("space", "0"), ("color", "000000")):
            el.set(qn(f"w:{k}"), v)
        borders.append(el)

    for n, csv in enumerate(sorted(tables_dir.glob("*.csv")), start=1):
        df = pd.read_csv(csv, dtype=str, keep_default_na=False)
        doc.add_paragraph().add_run(f"Table {n}").bold = True
        doc.add_paragraph().add_run(csv.stem.replace("_", " ")).italic = True
        t = doc.add_table(rows=len(df) + 1, cols=len(df.columns))
        rows = [r.cells for r in t.rows]  # once: cell look-ups by index walk the whole table
        for cell, c in zip(rows[0], df.columns):
            cell.text = str(c)
            rule(cell, "top")
            rule(cell, "bottom")
        for cells, row in zip(rows[1:], df.itertuples(index=False)):
            for cell, v in zip(cells, row):
                cell.text = str(v)
        for cell in rows[-1]:
            rule(cell, "bottom")
        doc.add_paragraph()
    buf = io.BytesIO()
    doc.save(buf)
    return _normalise_docx(buf.getvalue())


def _normalise_docx(data: bytes) -> bytes:
    """The DOCX (itself a zip) rewritten with sorted entries and fixed dates, so it is byte-identical per input."""
    src = zipfile.ZipFile(io.BytesIO(data))
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for name in sorted(src.namelist()):
            z.writestr(zipfile.ZipInfo(name, _EPOCH), src.read(name), zipfile.ZIP_DEFLATED)
    return out.getvalue()


README = """# Submission bundle: {title}

Written by `pedas-study report --bundle` from the report in `{report}` (study `{study_id}`, version {version},
definition sha256 `{hash}`).

- `tables/`: every table of the report as CSV, Markdown and LaTeX; `tables/tables.docx` has all of them.
- `figures/`: the report's figures; `figures/index.html` is the report document.
- `study/`: the study folder as the store keeps it (the model in lavaan syntax: `study/{model_file}`);
  `model/`: model syntax written by the analyses.
- `settings.json`: seeds and settings of the run; `versions.txt`: Python and package versions.
- `inputs.sha256`: sha256 of each store table (who wrote a row and when left out) and of all of them (`*`).

## Rerun

With pedas-study at the versions of `versions.txt` (`make` installs them from `requirements.lock`):

```sh
pedas-study --db study.duckdb init --study study/
# import the data: participants, phases, survey answers, drive logs (docs/contracts.md), then
pedas-study --db study.duckdb report --out reports --seed {seed} --bootstrap {n_boot}
```

{reference_note}The tables are then equal to those in `tables/`; `inputs.sha256` tells whether the data are the same.
"""


def write_bundle(report_dir: Path, st, path: Path, settings: dict) -> Bundle:
    """Write the bundle of the report in `report_dir` (made from the open store `st`) to `path` (zip)."""
    from study.store.studies import current

    report_dir = Path(report_dir)
    if not (report_dir / "tables").is_dir():
        raise FileNotFoundError(f"no report tables in {report_dir}/tables (run `pedas-study report` first)")
    study = current(st)
    if study is None:
        raise ValueError("the store has no study definition (run `pedas-study init --study DIR`)")
    entries: dict[str, bytes] = {}
    for f in sorted((report_dir / "tables").iterdir()):
        if f.suffix in (".csv", ".md", ".tex"):
            entries[f"tables/{f.name}"] = f.read_bytes()
    entries["tables/tables.docx"] = tables_docx(report_dir / "tables")
    for f in sorted((report_dir / "figures").glob("*.png")) if (report_dir / "figures").is_dir() else []:
        entries[f"figures/{f.name}"] = f.read_bytes()
    if (report_dir / "index.html").exists():
        entries["figures/index.html"] = (report_dir / "index.html").read_bytes()
    files = json.loads(study["files"])
    for rel, text in sorted(files.items()):
        entries[f"study/{rel}"] = text.encode("utf-8")
    for f in sorted(report_dir.rglob("*.lav")):
        entries[f"model/{f.relative_to(report_dir).as_posix().replace('/', '_')}"] = f.read_bytes()
    entries["settings.json"] = (json.dumps(settings, indent=2, sort_keys=True) + "\n").encode()
    versions = [f"python=={platform.python_version()}", *locked_versions()]
    entries["versions.txt"] = ("\n".join(versions) + "\n").encode()
    hashes = table_hashes(st)
    entries["inputs.sha256"] = "".join(f"{r.sha256}  {r.table} ({r.rows} rows)\n"
                                       for r in hashes.itertuples()).encode()
    model_file = next((rel for rel in files if rel.endswith(".lav")), "model.lav")
    ref = ("This bundle was made in reference mode: `pedas-study report --reference` rebuilds the same store from "
           "the repository's `data/reference/` and simulates the reference cohort.\n\n") if settings.get("reference") \
        else ""
    entries["README.md"] = README.format(title=study["title"], report=report_dir.name, study_id=study["study_id"],
                                         version=study["version"], hash=study["hash"], model_file=model_file,
                                         seed=settings.get("seed", 0), n_boot=settings.get("n_boot", 2000),
                                         reference_note=ref).encode()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for name in sorted(entries):
            z.writestr(zipfile.ZipInfo(name, _EPOCH), entries[name], zipfile.ZIP_DEFLATED)
    tmp.replace(path)
    return Bundle(path, tuple(sorted(entries)))
