"""The submission bundle: one zip archive with what a reviewer needs to check and rerun a report (docs/report.md,
"Submission bundle").

Contents (paths inside the archive):

* ``README.md`` -- what is inside and the commands that rerun the report;
* ``index.html`` -- the report document, with every image it shows at the path it shows it from;
* ``tables/`` -- every table of the report as CSV, APA-style Markdown and LaTeX (copied from the report's
  ``tables/``);
* ``figures/`` -- every figure of the report (the within-subjects figures too) as PNG, SVG and PDF;
* ``manuscript/`` -- the numbered tables and figures as ``results.docx`` (Word, APA style) and LaTeX
  (``latex/results.tex`` with its preamble), analysis.report.manuscript;
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
import html
import json
import platform
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.render import FIGURE_FORMATS
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


def table_hashes(st, skip: frozenset[str] = frozenset()) -> pd.DataFrame:
    """sha256 of each store table but those in `skip` (rows sorted, provenance columns left out: who wrote a row and
    when, and study_definitions.source); the last row ('*') hashes the others.

    Columns: table, rows, sha256."""
    rows = []
    for table in sorted(st.tables()):
        if table in _SKIP_TABLES or table in skip:
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


README = """# Submission bundle: {title}

Written by `pedas-study report --bundle` from the report in `{report}` (study `{study_id}`, version {version},
definition sha256 `{hash}`).

- `index.html`: the report document (open it in a browser; its images are beside it).
- `tables/`: every table of the report as CSV, Markdown and LaTeX.
- `figures/`: every figure of the report as PNG, SVG and PDF.
- `manuscript/`: the numbered tables and figures as `results.docx` (Word) and LaTeX (`latex/results.tex`).
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


def document_images(report_dir: Path) -> list[str]:
    """The images the report document shows that are files of the report folder (relative paths, sorted)."""
    doc = (Path(report_dir) / "index.html").read_text(encoding="utf-8")
    found = {html.unescape(m) for m in re.findall(r"<img[^>]*\ssrc=\"([^\"]+)\"", doc)}
    return sorted(src for src in found if "://" not in src and not src.startswith(("/", "data:")) and ".." not in src
                  and (Path(report_dir) / src).is_file())


def write_bundle(report_dir: Path, st, path: Path, settings: dict) -> Bundle:
    """Write the bundle of the report in `report_dir` (made from the open store `st`) to `path` (zip)."""
    from analysis.report.manuscript import MANUSCRIPT_DIR, manuscript_files
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
    # the report's figures/ and the figures a part keeps beside its tables (within/lines_<variable>)
    for f in [*sorted(report_dir.glob("figures/*")), *sorted(report_dir.glob("*/*"))]:
        if f.suffix.lstrip(".") in FIGURE_FORMATS and f.is_file():
            entries.setdefault(f"figures/{f.name}", f.read_bytes())
    if (report_dir / "index.html").exists():
        entries["index.html"] = (report_dir / "index.html").read_bytes()
        for src in document_images(report_dir):
            entries[src] = (report_dir / src).read_bytes()
    for rel, data in manuscript_files(report_dir).items():
        entries[f"{MANUSCRIPT_DIR}/{rel}"] = data
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
