"""The questionnaire's answers: entry, double entry, links and final answers per occasion (`answers`), import of
answer files (`survey_import`) and each participant's completeness of protocol and survey (`completeness`).

Imports `study.common`, `study.folder`, `study.store` and `study.people`.
"""
