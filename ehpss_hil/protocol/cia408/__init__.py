"""CANopen (CiA 301) with the fluid-power valve profile CiA 408 and the encoder profile CiA 406:
the definitions the emulated nodes (``firmware_sim/canopen_node/``) and a master share.

:mod:`.cobid` the predefined connection set (which COB-ID carries what), :mod:`.objects` the
object indices, NMT codes, control/status word bits, EMCY and SDO abort codes and the ±16384
scaling, :mod:`.eds` the shipped EDS files (``eds/``) loaded through ``canopen``.
"""
