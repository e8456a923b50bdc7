"""Defaults that command-line help shows, in a module that imports nothing: building the `pedas-study` parser
reads them without loading the modules that use them (pandas and the rest are imported when a command runs)."""
from __future__ import annotations

#: the simulator a slot is booked on when none is named (:func:`study.people.scheduling.book`)
DEFAULT_SIMULATOR = "sim1"
#: minutes added to a protocol's planned duration for set-up, briefing and cleaning the simulator
DEFAULT_BUFFER_MINUTES = 15.0
