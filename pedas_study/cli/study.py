"""`pedas-study study new | check`: write a template study folder, check a study folder (docs/study_folder.md)."""
from __future__ import annotations

import re
import sys
from pathlib import Path

from study.common.errors import UserError

STUDY_TOML = '''\
# A study of pedas-study as plain files (docs/study_folder.md). Edit every value, then run
#   pedas-study study check {folder}
# and, when it prints OK, create a store for it:
#   pedas-study --db {id}.duckdb init --study {folder}

[study]
id = "{id}"                      # lower-case letters, digits, _ or -; one store serves one study
title = "Acceptance of a driving assistance system"
description = """You drove a simulated car twice, once with an assistance system and once without it. \\
Please tell us what you think of the system."""   # shown to participants above the survey
summary = """Acceptance of a driving assistance system: each participant drives with and without it; a \
questionnaire after the drives."""   # researcher-facing, opens the report

[participants]
id_pattern = "^P[0-9]{{3,}}$"      # regular expression every (pseudonymous) participant id must match,
id_example = "P001"               # e.g. "^VP[0-9]{{2}}$" for VP07 or "^S-[0-9]{{3}}$" for S-012

# Participant attributes: recorded at registration (`participant add P001 --attr age=30`), usable as covariates
# in the model file and as groups of KPIs. type = integer | number | choice | text.
[[attributes]]
name = "age"
type = "integer"
min = 18
max = 99
label = "Age (years)"
required = false                 # true: a registration without it is refused

[[attributes]]
name = "gender"
type = "choice"
choices = ["female", "male", "diverse", "undisclosed"]
label = "Gender"

[[attributes]]
name = "license_years"
type = "integer"
min = 0
max = 80
label = "Years holding a driving licence"

# Rules over several attributes as DuckDB SQL expressions; a registration for which one is false is refused
# with its message (a missing value makes the expression NULL, which passes).
[[checks]]
sql = "age IS NULL OR license_years IS NULL OR license_years <= age - 16"
message = "license years impossible at this age (licence from 16)"

# The experimental conditions; every drive is recorded under one of them.
[[conditions]]
name = "control"
label = "Drive without the system"

[[conditions]]
name = "system"
label = "Drive with the system"

# The files of this study (paths inside this folder). protocols: the first is the default protocol.
# Optional: published (values a paper printed), log_mapping, route, kpis (docs/drive_logs.md, docs/kpis.md).
[files]
instrument = "codebook.csv"
protocols = ["protocol.json"]
model = "model.lav"

# The survey instrument is stored as <name>_v<version>; change the version whenever its items change.
[instrument]
name = "acceptance"
version = 1

[analysis]
alpha = 0.05                     # significance level of the hypothesis tests
min_loading = 0.7                # items loading below this are flagged in the initial measurement model
cross_margin = 0.0
regression_title = "Acceptance model"
'''

CODEBOOK = '''\
item_id,construct,section,text,response_type,scale_min,scale_max,anchor_low,anchor_high,choices,reverse_scored,required,attribute
AGE,DEMO,About you,Your age (years),number,18,99,,,,0,0,age
GENDER,DEMO,About you,Your gender,choice,1,4,,,1=Female|2=Male|3=Diverse|4=Prefer not to say,0,0,gender
PU1,PU,Usefulness,The system helps me drive better.,likert5,1,5,Strongly disagree,Strongly agree,,0,1,
PU2,PU,Usefulness,The system is useful when I drive.,likert5,1,5,Strongly disagree,Strongly agree,,0,1,
PU3,PU,Usefulness,I would miss the system if it were removed.,likert5,1,5,Strongly disagree,Strongly agree,,0,1,
EOU1,EOU,Ease of use,The system is easy to understand.,likert5,1,5,Strongly disagree,Strongly agree,,0,1,
EOU2,EOU,Ease of use,Following the system takes little effort.,likert5,1,5,Strongly disagree,Strongly agree,,0,1,
EOU3,EOU,Ease of use,The system distracts me from driving.,likert5,1,5,Strongly disagree,Strongly agree,,1,1,
BI1,BI,Intention,I would use the system in my own car.,likert5,1,5,Strongly disagree,Strongly agree,,0,1,
BI2,BI,Intention,I would recommend the system to others.,likert5,1,5,Strongly disagree,Strongly agree,,0,1,
BI3,BI,Intention,I intend to use such a system in the future.,likert5,1,5,Strongly disagree,Strongly agree,,0,1,
COMMENT,FEEDBACK,Comments,Anything else you would like to tell us?,text,,,,,,0,0,
'''

PROTOCOL = '''\
{
  "name": "protocol_v1",
  "version": 1,
  "title": "Familiarisation, two drives in counterbalanced order, survey",
  "note": "planned_minutes size the simulator slots; a drive phase names a condition of study.toml",
  "note_orders": "orders are optional; without them every participant runs the phases in the order listed",
  "phases": [
    {"name": "familiarisation", "planned_minutes": 10, "drive": false, "condition": null},
    {"name": "drive_control", "planned_minutes": 15, "drive": true, "condition": "control"},
    {"name": "drive_system", "planned_minutes": 15, "drive": true, "condition": "system"},
    {"name": "survey", "planned_minutes": 10, "drive": false, "condition": null}
  ],
  "orders": {
    "control_first": ["familiarisation", "drive_control", "drive_system", "survey"],
    "system_first": ["familiarisation", "drive_system", "drive_control", "survey"]
  }
}
'''

MODEL = '''\
# Analysis model in lavaan syntax (docs/study_folder.md).

# Measurement model: each construct with its items (scaled items of codebook.csv; EOU3 is reverse-scored there).
PU =~ PU1 + PU2 + PU3
EOU =~ EOU1 + EOU2 + EOU3
BI =~ BI1 + BI2 + BI3

# One hierarchical regression: one line per step listing all its predictors. age (a participant attribute) is a
# control in step 1; the labels H1, H2 mark the paths the hypotheses are read from (step 2).
BI ~ age
BI ~ age + H1*PU + H2*EOU

# Expected signs: one-sided tests (a label without a sign line is tested two-sided).
H1 > 0
H2 > 0
'''


def template_files(study_id: str, folder: str) -> dict[str, str]:
    """{file name: text} of the template study `study_id` (a folder that `study check` accepts)."""
    return {"study.toml": STUDY_TOML.format(id=study_id, folder=folder), "codebook.csv": CODEBOOK,
            "protocol.json": PROTOCOL, "model.lav": MODEL}


def study_id_for(folder: Path) -> str:
    """A valid study id made from the folder's name (lower case, other characters as _)."""
    name = re.sub(r"[^a-z0-9_-]+", "_", folder.resolve().name.lower()).strip("_-")
    if not name or not name[0].isalpha():
        name = f"study_{name}".rstrip("_")
    return name[:40]


def summary(study) -> str:
    """One line: what a checked study declares."""
    parts = [f"{len(study.attributes)} attributes", f"conditions {'|'.join(study.condition_names)}"]
    for ins in study.instruments.values():
        parts.append(f"instrument {ins.name} ({len(ins.items)} items)")
    parts.append(f"protocols {', '.join(study.protocols)}")
    model = study.model
    parts.append("model: none" if model is None else
                 f"model: {len(model.measurement)} constructs, {len(model.regressions)} regressions, "
                 f"{len(model.hypotheses)} hypotheses")
    from study.folder.scores import study_scores
    from study.folder.within_spec import within_spec

    scores = [s.name for s in study_scores(study)]
    if scores:
        parts.append(f"scores {', '.join(scores)}")
    within = within_spec(study)
    if within is not None:
        parts.append(f"within-subjects: {len(within.scores) + len(within.kpis)} variables across "
                     f"{'|'.join(within.conditions)}")
    labels = study.settings.get("analysis", {}).get("construct_labels") or {}
    unlabelled = [c for c in (model.measurement if model is not None else ()) if c not in labels]
    if unlabelled:
        parts.append(f"constructs without a researcher-facing label ([analysis.construct_labels]): "
                     f"{', '.join(unlabelled)}")
    if not study.summary:
        parts.append("no [study] summary (the report opens without a researcher-facing description)")
    return f"study {study.study_id} OK: " + ", ".join(parts)


def _new(args) -> None:
    from study.folder.definition import check

    folder = Path(args.dir)
    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise UserError(f"{folder} exists and is not an empty folder; `study new` writes only into a new one")
    files = template_files(study_id_for(folder), str(folder))
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (folder / name).write_text(text, encoding="utf-8")
    problems = check(folder)
    if problems:  # the template must always pass its own check
        raise RuntimeError(f"the template does not pass the check: {problems[0]}")
    print(f"template study written to {folder} ({', '.join(files)}); edit it, then run "
          f"`pedas-study study check {folder}`")


def _check(args) -> int:
    from study.folder.definition import check, load

    folder = Path(args.dir)
    problems = check(folder)
    for p in problems:
        # names relative to the study folder become paths a terminal or an editor can open
        shown = p.file if Path(p.file) == folder else str(folder / p.file)
        where = f"{shown}:{p.line}" if p.line else shown
        print(f"{where}: {p.field}: {p.message}" if p.field else f"{where}: {p.message}")
    if problems:
        print(f"pedas-study: error: {len(problems)} problem(s) in study folder {folder}", file=sys.stderr)
        return 2
    print(summary(load(folder)))
    return 0


def register(cli) -> None:
    """Declare the `study` group."""
    g = cli.group("study", "write or check a study folder (study.toml, codebook, protocols, model)")
    p = g.command("new", "write a commented template study into a new folder", _new)
    p.add_argument("dir", metavar="DIR")
    p = g.command("check", "check a study folder: every problem as file:line: field: message (exit 2 when any)",
                  _check)
    p.add_argument("dir", metavar="DIR")
