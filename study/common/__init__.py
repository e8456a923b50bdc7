"""Shared pieces every family of study/ uses: the one-line user error (`errors`), study-folder problems with file and
line (`problems`, `toml_lines`), numeric columns read from rows (`numbers`), units of the log mapping and the route
(`units`, pint on use), the registry of the study folder's file checks (`file_checks`), bulk files read row by row
(`bulk_rows`) and DuckDB's memory limit while a command streams (`duck_memory`).

Owns no file and no table. Imports nothing of study/ outside this package (and no other part of the project).
"""
