"""Where the repository's data lives. `PEDAS_DATA_DIR` overrides the checkout's `data/` folder."""
from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
DATA_DIR = Path(os.environ.get("PEDAS_DATA_DIR", REPO_ROOT / "data"))
PAPER_DIR = DATA_DIR / "paper"
REFERENCE_DIR = DATA_DIR / "reference"
NETWORK_DIR = DATA_DIR / "network"
# generated SUMO artefacts (net.xml, routes); never committed
NETWORK_BUILD_DIR = NETWORK_DIR / "build"
