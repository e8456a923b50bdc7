"""Exports of the store for SPSS and R: CSV, Parquet and .sav with labels, de-identified on request (`writer`,
the .sav header in `sav_header`).

Imports every family of study/ below it (common, folder, store, people, logs, survey).
"""
