"""pEDAS simulation core: vehicle and power model, reference speeds (DP, green wave), the reference-tracking and
car-following MPCs on DAQP (OSQP as cross-check), controller switching, speed correction, HUD advisory, the SUMO
route and traffic, virtual drivers and the drive loop. Imports neither `study` nor `analysis`."""

import os as _os
import sys as _sys

# numpy chooses SIMD code paths per CPU when it loads; on AVX-512 CPUs some float64 functions (exp, log, power,
# arctan2, ...) may take paths whose last bits differ from the AVX2 ones. Keeping numpy on its AVX2 (X86_V3)
# paths gives every x86-64 CPU with AVX2 the same arithmetic, hence the same drives (docs/vehicle_and_references.md,
# "Same numbers on every machine"). Only effective before numpy is imported; set the variable to "" to opt out.
if "numpy" not in _sys.modules:
    _os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", "X86_V4 AVX512_ICL AVX512_SPR")
