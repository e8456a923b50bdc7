"""The study store: the DuckDB file and its lock (`store`), the forward-only schema migrations (`migrate`,
`migrations/NNNN_name.sql`), the audit trail every change writes (`audit_trail`), DuckDB constraint messages in
words (`constraint_text`) and the study a store serves, stored and read back by version (`studies`).

Imports `study.common` and `study.folder` (a stored study is a checked folder definition).
"""
