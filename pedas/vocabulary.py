"""The words the paper's study uses for its factors, defined once: driving styles (Sec. 4.2), drive conditions
(Sec. 4.3) and route segments (Sec. 4.3, Sec. 5.1). Modules import these instead of spelling them out."""
from __future__ import annotations

STYLES = ("cautious", "normal", "sporty")  # self-reported driving style
CONDITIONS = ("baseline", "pedas")  # the drive without and with the assistance
SEGMENTS = ("urban", "highway")  # route segments a drive-log sample belongs to
