"""The quantize transport's written-out DBC arithmetic against cantools' own conversions
(:meth:`FrameCodec.quantize`), bit for bit and type for type, on and off the DBC grid."""

from __future__ import annotations

import math

from ehpss_hil.codec import FrameCodec
from ehpss_hil.control.registry import make_controller
from ehpss_hil.driver import ControllerDriver
from ehpss_hil.physics.load import load_params
from ehpss_hil.sim.transport import QuantizeTransport

#: load pressures (Pa): exact multiples of the DBC's 10 Pa scale (cantools' integer conversion
#: takes its no-division branch there), half steps (round half to even), off the grid, the clip
PRESSURES = [0.0, -0.0, 10.0, -20.0, 1.2e7, 15.0, 25.0, -35.0, 123456.789, -9876543.21, 4e7, -4e7, 5e7]


def test_sensor_values_equal_the_dbc_conversions() -> None:
    codec = FrameCodec()
    tr = QuantizeTransport(codec)
    drv = ControllerDriver(make_controller("nrc", load_params(), 1e-3), lambda k: 0.0)
    for i, p in enumerate(PRESSURES):
        pos, spool, coil = 1.234567e-3 * math.sin(i), -3.33333e-4 * (i - 6), 0.0123456789 * (-1) ** i
        assert tr.sensor(drv, i, pos, spool, p, coil, False, False)
        want_pos = codec.quantize("SENSOR_POS", {"Position": pos, "Spool": spool})
        want_aux = codec.quantize("SENSOR_AUX", {"LoadPressure": max(-4e7, min(4e7, p)), "CoilCurrent": coil})
        m = drv.meas
        got = (m.position_m, m.spool_m, m.load_pressure_pa, m.coil_current_a)
        want = (want_pos["Position"], want_pos["Spool"], want_aux["LoadPressure"], want_aux["CoilCurrent"])
        assert got == want
        assert [math.copysign(1, g) for g in got] == [math.copysign(1, w) for w in want]  # ±0
    assert not tr.sensor(drv, 99, 0.1, 0.0, 0.0, 0.0, False, True)


def test_command_equals_the_dbc_conversion() -> None:
    codec = FrameCodec()
    tr = QuantizeTransport(codec)
    for c in (0.0, 1e-7, -3e-7, 0.123456789, -0.98765, 1.0, -1.5):
        want = codec.quantize("VALVE_CMD", {"CurrentSetpoint": max(-1.0, min(1.0, c))})["CurrentSetpoint"]
        assert tr.command(c, 0, False) == want
    assert tr.command(0.5, 0, True) is None
