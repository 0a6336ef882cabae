"""The frame layer between the emulated plant and the controller in a lockstep run.

``quantize``: each value goes through :meth:`FrameCodec.quantize` (the DBC scaling a receiver
decodes), without the bytes — fast. ``frames``: every frame
is built with :meth:`FrameCodec.encode` (bytes, E2E CRC and counter) and checked with
:meth:`FrameCodec.classify` on the receiving side — slow, but the real thing. Both give
bit-identical values (a test checks it). Frame loss is decided by the caller; a lost frame is
simply never delivered (the receiver's E2E counter then reports OK_SOME_LOST). Either way the
sensor pair reaches the controller's driver as the daemon's mapping
(:meth:`~ehpss_hil.driver.ControllerDriver.take`) puts decoded frames onto it.
"""

from __future__ import annotations

from collections.abc import Callable

from cantools.database.conversion import LinearConversion, LinearIntegerConversion

from ..codec.frames import FrameCodec
from ..codec.verdict import Decoded
from ..driver import ControllerDriver


def take_sensor_pair(drv: ControllerDriver, pos: Decoded, aux: Decoded) -> bool:
    """A classified SENSOR_POS + SENSOR_AUX pair onto ``drv`` (:meth:`ControllerDriver.take`)
    when both are usable; True if taken."""
    if not (pos.verdict.usable and aux.verdict.usable) or pos.values is None or aux.values is None:
        return False
    drv.take(pos)
    drv.take(aux)
    return True


def applied_current(cmd: Decoded) -> float | None:
    """The current (A) a classified VALVE_CMD asks the valve for, or None unless usable."""
    if not cmd.verdict.usable or cmd.values is None:
        return None
    return float(cmd.values["CurrentSetpoint"])


def _clip(v: float, lim: float) -> float:
    return -lim if v < -lim else lim if v > lim else v


def _quantizer(codec: FrameCodec, frame: str, signal: str) -> Callable[[float], float]:
    """``v → `` what :meth:`FrameCodec.quantize` returns for this signal, bit for bit.

    For cantools' ``LinearConversion`` (integer raw) this is its own arithmetic,
    ``round((v − offset)/scale)·scale + offset``, written out; any other conversion is called.
    """
    conv = codec.message(frame).get_signal_by_name(signal).conversion
    if isinstance(conv, LinearConversion) and not conv.is_float:
        sc, off = conv.scale, conv.offset
        return lambda v: round((v - off) / sc) * sc + off
    to_raw, to_scaled = conv.numeric_scaled_to_raw, conv.raw_to_scaled
    return lambda v: to_scaled(to_raw(v), False)  # type: ignore[return-value]


def _linear_scale(codec: FrameCodec, frame: str, signal: str) -> tuple[float, float] | None:
    """(scale, offset) when the signal uses cantools' integer-raw ``LinearConversion``."""
    conv = codec.message(frame).get_signal_by_name(signal).conversion
    if isinstance(conv, LinearConversion) and not conv.is_float:
        return conv.scale, conv.offset
    return None


def _integer_scale(codec: FrameCodec, frame: str, signal: str) -> tuple[int, int] | None:
    """(scale, offset) when the signal uses cantools' ``LinearIntegerConversion``."""
    conv = codec.message(frame).get_signal_by_name(signal).conversion
    if type(conv) is LinearIntegerConversion:
        return conv.scale, conv.offset
    return None


class QuantizeTransport:
    """DBC quantization only (the conversions of :meth:`FrameCodec.quantize`).

    Position, spool, coil current and the command current use cantools' ``LinearConversion``
    arithmetic written out inline, ``round((v − offset)/scale)·scale + offset`` (this is the
    simulator's hot path). So is the load pressure's ``LinearIntegerConversion`` (the shipped
    DBC's 10 Pa), expression for expression: ``r = v − offset``, ``r // scale`` when that
    divides exactly, else ``r / scale``, rounded; any other conversion is called through cantools.
    The quantized values go onto the driver in one :meth:`~ehpss_hil.driver.ControllerDriver.sensors`
    call (its :meth:`~ehpss_hil.driver.ControllerDriver.position` and
    :meth:`~ehpss_hil.driver.ControllerDriver.aux` together), where
    :meth:`~ehpss_hil.driver.ControllerDriver.take` puts a decoded SENSOR_POS and SENSOR_AUX (no
    frame object and no dict per sample; tests/test_driver_mapping.py pins the driver's input to
    the frames transport's).
    """

    __slots__ = (
        "_ko",
        "_ks",
        "_press",
        "_press_int",
        "_sensor_scales",
    )

    def __init__(self, codec: FrameCodec) -> None:
        lin = [
            _linear_scale(codec, "SENSOR_POS", "Position"),
            _linear_scale(codec, "SENSOR_POS", "Spool"),
            _linear_scale(codec, "SENSOR_AUX", "CoilCurrent"),
            _linear_scale(codec, "VALVE_CMD", "CurrentSetpoint"),
        ]
        if any(x is None for x in lin):
            raise TypeError("position/spool/current signals must use a linear integer scaling")
        (ps, po), (ss, so), (cs, co), (self._ks, self._ko) = lin  # type: ignore[misc]
        #: the sensor signals' (scale, offset): position, spool, coil current (one unpack a sample)
        self._sensor_scales = (ps, po, ss, so, cs, co)
        self._press = _quantizer(codec, "SENSOR_AUX", "LoadPressure")
        #: the load pressure's integer (scale, offset) when written out inline, else None
        self._press_int = _integer_scale(codec, "SENSOR_AUX", "LoadPressure")

    def sensor(
        self,
        drv: ControllerDriver,
        k: int,
        pos: float,
        spool: float,
        pressure: float,
        coil: float,
        saturated: bool,
        lost: bool,
    ) -> bool:
        """Sample ``k``'s SENSOR_POS + SENSOR_AUX onto ``drv`` as the controller decodes them
        (m, m, Pa, A; the E2E counter k mod 16 the emulator's frames carry); False if lost."""
        if lost:
            return False
        pos = -0.5 if pos < -0.5 else 0.5 if pos > 0.5 else pos
        spool = -0.01 if spool < -0.01 else 0.01 if spool > 0.01 else spool
        coil = -1.0 if coil < -1.0 else 1.0 if coil > 1.0 else coil
        ps, po, ss, so, cs, co = self._sensor_scales
        pressure = -4e7 if pressure < -4e7 else 4e7 if pressure > 4e7 else pressure
        if self._press_int is None:
            p_q = self._press(pressure)
        else:
            p_s, p_o = self._press_int
            r = pressure - p_o
            q, rem = divmod(r, p_s)
            p_q = round(q if rem == 0 else r / p_s) * p_s + p_o
        drv.sensors(
            round((pos - po) / ps) * ps + po,
            round((spool - so) / ss) * ss + so,
            k & 0x0F,
            round((coil - co) / cs) * cs + co,
            p_q,
        )
        return True

    def command(self, current_a: float, k: int, lost: bool) -> float | None:
        """VALVE_CMD current as the emulator decodes it (A); None if lost."""
        if lost:
            return None
        c = -1.0 if current_a < -1.0 else 1.0 if current_a > 1.0 else current_a
        return round((c - self._ko) / self._ks) * self._ks + self._ko

    def counts(self) -> dict[str, int]:
        """No frames are classified in this transport."""
        return {}


class FramesTransport:
    """Real encode → bytes → classify with E2E, one codec per side."""

    def __init__(self, emu_codec: FrameCodec, ctrl_codec: FrameCodec) -> None:
        self._emu = emu_codec
        self._ctrl = ctrl_codec

    def sensor(
        self,
        drv: ControllerDriver,
        k: int,
        pos: float,
        spool: float,
        pressure: float,
        coil: float,
        saturated: bool,
        lost: bool,
    ) -> bool:
        """Encode both sensor frames on the emulator side, classify them on the controller side
        unless ``lost`` (the TX counters advance either way) and hand them to ``drv``; True if
        both were usable (``k``: the sample, carried by the frames' own E2E counter)."""
        f1 = self._emu.encode("SENSOR_POS", {"Position": _clip(pos, 0.5), "Spool": _clip(spool, 0.01)})
        f2 = self._emu.encode(
            "SENSOR_AUX",
            {
                "LoadPressure": _clip(pressure, 4e7),
                "CoilCurrent": _clip(coil, 1.0),
                "ValveEnabled": 1,
                "CmdTimeout": 0,
                "CurrentSaturated": int(saturated),
            },
        )
        if lost:
            return False
        return take_sensor_pair(drv, self._ctrl.classify(f1), self._ctrl.classify(f2))

    def command(self, current_a: float, k: int, lost: bool) -> float | None:
        """Encode VALVE_CMD on the controller side, classify it on the emulator side unless
        ``lost``."""
        f = self._ctrl.encode(
            "VALVE_CMD",
            {
                "CurrentSetpoint": _clip(current_a, 1.0),
                "Enable": 1,
                "SensorCounterEcho": k & 0xF,
                "CycleCount": k & 0xFFFF,
            },
        )
        return None if lost else applied_current(self._emu.classify(f))

    def counts(self) -> dict[str, int]:
        """Verdict counts of both receivers (name → count)."""
        out: dict[str, int] = {}
        for c in (self._emu, self._ctrl):
            for v, n in c.counts.items():
                out[v.name] = out.get(v.name, 0) + n
        return out
