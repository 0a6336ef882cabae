"""ehpss-hil: fault-tolerant (MMAC) position control of an electro-hydraulic servo over CAN.

Subpackages: ``physics`` (plant model, exact ZOH), ``control`` (PI, estimators, model banks,
supervisor), ``frames`` (DBC codec + AUTOSAR E2E), ``bus`` (python-can factory), ``runtime``
(real-time loop), ``canlog`` (candump logs), ``report``/``bench`` (metrics, figures, benchmarks).
"""

from pathlib import Path

__version__ = "0.1.0"

#: Repository root (holds ``dbc/``, ``configs/``, ``scenarios/``) for a source/editable install.
PROJECT_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_DBC = PROJECT_ROOT / "dbc" / "ehpss.dbc"
