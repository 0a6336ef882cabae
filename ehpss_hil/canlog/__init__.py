"""candump ``-L`` logs: a non-blocking writer with size rotation and a JSON sidecar, and readers.

Log lines are exactly what ``candump -L`` writes (``(sec.usec) iface ID#DATA``), so python-can's
:class:`can.io.CanutilsLogReader`, ``canplayer`` and ``cantools decode`` read them; run metadata
(versions, DBC hash, config/scenario, counts, rotation files) lives in ``<log>.json`` beside it.
"""

from .lineformat import format_line
from .reader import BadLines, decode_log, log_files, read_log, read_sidecar
from .writer import CandumpLogger

__all__ = ["BadLines", "CandumpLogger", "decode_log", "format_line", "log_files", "read_log", "read_sidecar"]
