"""Drive logs, from a simulator's file to the store: reading a file as it is (`reading`: CSV, Parquet, SUMO FCD via
`fcd` and its network's route `fcd_route`), checking it (`validation`: columns, ranges, plausibility), importing it
for a participant's drive (`importing`: mapping, route join, energy, one transaction), the stored drives and their
extra channels (`stored`), the HUD channels (`hud_channels`), the live session's log (`live_log`) and simulated
drives (`simulated`). A new simulator log format belongs here (`reading`), with its column names and units in the
study's log mapping (`study.folder.logmap`).

Imports `study.common`, `study.folder`, `study.store` and `study.people`.
"""
