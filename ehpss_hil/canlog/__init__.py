"""CAN logs: a non-blocking candump ``-L`` writer with size rotation and a JSON sidecar, and one
reader for every format python-can reads (:func:`read_frames`: candump ``-L``, ``.asc``,
``.blf``, …).

Log lines are exactly what ``candump -L`` writes (``(sec.usec) iface ID#DATA``), so python-can's
:class:`can.io.CanutilsLogReader`, ``canplayer`` and ``cantools decode`` read them; run metadata
(versions, DBC hash, config/scenario, counts, rotation files, lockstep or realtime) lives in
``<log>.json`` beside it.
"""

from .decode import decode_log
from .files import LogError
from .lineformat import format_line
from .reader import BadLines, log_files, read_frames, read_log, read_sidecar
from .sidecar import lockstep_of
from .writer import CandumpLogger

__all__ = [
    "BadLines",
    "CandumpLogger",
    "LogError",
    "decode_log",
    "format_line",
    "lockstep_of",
    "log_files",
    "read_frames",
    "read_log",
    "read_sidecar",
]
