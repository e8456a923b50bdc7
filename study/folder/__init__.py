"""The study folder (docs/study_folder.md): `study.toml` and every file it declares, read and checked with file and
line: the definition (`definition`), participant attributes (`attributes`), the survey instrument and the shipped
instrument library (`instrument`, `instrument_library`), declared scores (`scores`), questionnaire occasions
(`occasions`), protocols (`protocol_file`), KPIs (`kpi_fields`, `kpi_query`, `kpi_spec`), the within-subjects
declaration (`within_spec`), the model file (`lavaan_parser`), the log mapping and the standard drive-log columns
(`logmap`, `drive_columns`) and the route (`route_file`). A new study-folder file belongs here: its reader, and its
check registered with `study.common.file_checks`.

Reads files and text only, never the store. Imports `study.common` and nothing else of study/.
"""
