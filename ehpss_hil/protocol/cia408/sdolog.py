"""``canopen``'s SDO client logs ``ERROR: Transfer aborted by client with code 0x05040000``
whenever a request times out (it then sends that abort to the node and raises
``SdoCommunicationError``). In the master's start-up the time-out is handled where it happens:
while a node is awaited (it may boot after the controller) it is expected and the start-up
carries on, logging once that it waits; anywhere else it refuses the start with a
:class:`~ehpss_hil.errors.NodeError` naming the node and the object (exit 3). Either way the
library's ERROR line would say something the start-up's own line says better, so it is
dropped for the start-up's duration (:func:`quiet_sdo_timeouts`); every other record passes.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

#: the logger of canopen's SDO client
SDO_CLIENT_LOGGER = "canopen.sdo.client"
#: CiA 301 abort code "SDO protocol timed out"
ABORT_TIMED_OUT = 0x05040000
#: the message canopen logs when it aborts a transfer itself
CLIENT_ABORT_MSG = "Transfer aborted by client with code 0x%08X"


class _DropTimeoutAborts(logging.Filter):
    """Drops canopen's record of its own time-out abort, nothing else."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not (record.msg == CLIENT_ABORT_MSG and record.args == (ABORT_TIMED_OUT,))


@contextmanager
def quiet_sdo_timeouts() -> Iterator[None]:
    """Within the block, canopen's time-out abort is not logged (module docstring)."""
    lg = logging.getLogger(SDO_CLIENT_LOGGER)
    f = _DropTimeoutAborts()
    lg.addFilter(f)
    try:
        yield
    finally:
        lg.removeFilter(f)
