"""CANopen (CiA 301) with the fluid-power valve profile CiA 408 and the encoder profile CiA 406:
the definitions the emulated nodes (``firmware_sim/canopen_node/``) and a master share.

:mod:`.cobid` the predefined connection set (which COB-ID carries what), :mod:`.objects` the
object indices, NMT codes, control/status word bits, EMCY and SDO abort codes and the ±16384
scaling, :mod:`.eds` the shipped EDS files (``eds/``) loaded through ``canopen``, :mod:`.check`
the checks of a ``cia408:`` section. The master's side: :mod:`.cyclic` the cyclic frames and
scalings, :mod:`.codec` the PDOs as the controller's logical frames, :mod:`.drive` the device
state machine driven through the control word, :mod:`.startup` and :mod:`.configure` the
start-up by SDO and NMT (run by ``ehpss_hil.protocol.cia408.master``).
"""
