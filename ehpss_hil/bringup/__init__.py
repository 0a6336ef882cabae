"""``ehpss-hil bringup``: the checks before the first enable (docs/hardware.md §4.1).

:mod:`.sequence` is the bounded open-loop sequence the daemon's loop runs as its controller,
:mod:`.judge` what its record says, :mod:`.engine` the whole run (bit rate, the daemon's
start-up with the CiA 408 identity check, the sequence, the findings).
"""
