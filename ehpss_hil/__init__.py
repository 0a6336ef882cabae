"""ehpss-hil: fault-tolerant (MMAC) position control of an electro-hydraulic servo over CAN.

Subpackages: ``physics`` (plant model, exact ZOH), ``control`` (PI, estimators, model banks,
supervisor), ``frames`` (DBC codec + AUTOSAR E2E), ``bus`` (python-can factory), ``runtime``
(real-time loop), ``canlog`` (candump logs), ``report``/``bench`` (metrics, figures, benchmarks).
"""

from .interrupt import guard_startup

guard_startup()  # first: a Ctrl-C while a program starts exits 130 (ehpss_hil/interrupt.py)

from pathlib import Path  # noqa: E402

from . import _mf4import, native  # noqa: E402

native.guard()  # before any compiled module is imported: a stale native build is not used

__version__ = "0.1.0"

#: Repository root (holds ``configs/``, ``scenarios/``, ``campaigns/``) of a source/editable
#: install; a wheel does not ship these.
PROJECT_ROOT = Path(__file__).resolve().parent.parent
#: The files the package ships (package data, in the wheel too): ``dbc/`` (ehpss.dbc, the
#: vendor example), ``eds/`` (the emulated CANopen nodes) and ``params.yaml`` (the default plant
#: and controller parameters). The repository's ``dbc/``, ``eds/`` and ``configs/params.yaml``
#: are symbolic links to them.
DATA_DIR = Path(__file__).resolve().parent / "data"
DEFAULT_DBC = DATA_DIR / "dbc" / "ehpss.dbc"


_mf4import.install()
