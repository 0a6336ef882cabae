"""The lockstep simulator: plant emulation, frame layer and controller stepped sample by sample.

Per sample k (Ts): ``emu.sample()`` (``measure()``'s values as a tuple) → sensor frames
(quantized, or real bytes with E2E; lost with the scenario's sensor-direction probability,
drawn by :meth:`PlantEmulation.frame_losses` as in the emulator process: then the controller
gets ``Measurement(fresh=False)`` with the last values) →
``controller.step`` → VALVE_CMD (quantized the same way; lost with the command-direction
probability, which makes the plant hold the last command it received) → transport delay d: the
command computed from y[k] is applied over [k+d, k+d+1) (the first d intervals get 0 A) →
``emu.advance``. Both sensor frames of a sample share one loss draw. The emulator's 10 ms command
timeout is not modelled here (it needs ≥ 10 consecutive lost command frames). Same scenario +
seed → bit-identical arrays.
"""

from __future__ import annotations

import gc
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from itertools import chain

import numpy as np

from ..blas import limit_blas_threads
from ..codec.frames import FrameCodec
from ..control.controllers import LoopBase
from ..control.registry import make_controller
from ..control.tuning import ControlTuning
from ..driver import ControllerDriver
from ..emulation import PlantEmulation
from ..errors import ConfigError
from ..physics.faults import FaultState
from ..physics.load import load_params
from ..physics.params import Params, PlantParams
from ..physics.reference import ReferenceModel
from ..protocol.cia408.codec import Cia408Codec
from ..report.result import N_SLOTS, SimResult
from ..scenario import Scenario
from .transport import FramesTransport, QuantizeTransport
from .transport_cia408 import Cia408Transport

TRANSPORTS = ("quantize", "frames")


_QUANTIZE: QuantizeTransport | None = None
_QUANTIZE_DBC: dict[str, QuantizeTransport] = {}
_Y_M: dict[tuple[Params, float, bytes], np.ndarray] = {}


def _transport(
    kind: str, protocol_config: str = "", dbc: str = ""
) -> QuantizeTransport | FramesTransport | Cia408Transport:
    global _QUANTIZE  # stateless, built once per process (the DBC parse is slow)
    if protocol_config and kind != "frames":
        raise ConfigError("", "transport", "a protocol profile runs with the frames transport only")
    if dbc:
        return _native_dbc_transport(kind, protocol_config, dbc)
    if kind == "quantize":
        if _QUANTIZE is None:
            _QUANTIZE = QuantizeTransport(FrameCodec())
        return _QUANTIZE
    if kind == "frames":
        if protocol_config:
            emu, ctrl = config_codec(protocol_config), config_codec(protocol_config)
            if isinstance(emu, Cia408Codec) and isinstance(ctrl, Cia408Codec):
                return Cia408Transport(emu, ctrl)
            return FramesTransport(emu, ctrl)
        return FramesTransport(FrameCodec(), FrameCodec())
    raise ConfigError("", "transport", f"unknown transport {kind!r}; choose {', '.join(TRANSPORTS)}")


def _native_dbc_transport(kind: str, protocol_config: str, dbc: str) -> QuantizeTransport | FramesTransport:
    """The transport of another native DBC (same frames, other scaling: ``bench resolution``)."""
    if protocol_config:
        raise ConfigError("", "dbc", "a protocol config brings its own DBC")
    if kind == "frames":
        return FramesTransport(FrameCodec(dbc), FrameCodec(dbc))
    tr = _QUANTIZE_DBC.get(dbc)
    if tr is None:
        tr = _QUANTIZE_DBC[dbc] = QuantizeTransport(FrameCodec(dbc))
    return tr


def config_codec(path: str) -> FrameCodec:
    """The codec of the protocol profile of controller config ``path`` (ConfigError naming it)."""
    from ..config import load_controller_config
    from ..protocol import make_codec

    cfg = load_controller_config(path)
    plant = load_params(cfg.params or None).plant
    return make_codec(
        cfg.protocol,
        cfg.dbc,
        cfg.ids,
        path,
        cfg.dbc_map,
        cfg.nodes,
        plant.spool_stroke_m,
        plant.stroke_current_a,
    )


def reference_output(params: Params, ts_s: float, x_d: np.ndarray) -> np.ndarray:
    """y_m for the reference sequence ``x_d`` (m), cached per process (campaigns run the same
    scenario for several controllers)."""
    key = (params, ts_s, x_d.tobytes())
    y = _Y_M.get(key)
    if y is None:
        if len(_Y_M) > 32:
            _Y_M.clear()
        y = _Y_M[key] = ReferenceModel(params, ts_s).simulate(x_d)
        y.setflags(write=False)
    return y


def run_scenario(
    scenario: Scenario,
    mode: str,
    params: Params | None = None,
    tuning: ControlTuning | None = None,
    transport: str = "quantize",
    protocol_config: str = "",
    plant_params: PlantParams | None = None,
    dbc: str = "",
) -> SimResult:
    """Simulate ``scenario`` with controller ``mode``; returns every per-sample array.
    ``params`` are the controller's (its models and y_m); the emulated plant is the scenario's
    ``plant:`` section over ``plant_params`` (default: ``params.plant``, plant = model unless
    the scenario says otherwise).
    ``protocol_config``: a controller config whose protocol profile the frames transport speaks
    on both sides (the emulator impersonating the mapped electronics); its tuning is the one
    used when ``tuning`` is None (cia408 needs mmac without its flow-gain test). ``dbc``: a
    native DBC other than the shipped one (the same frames, another scaling) on both sides."""
    limit_blas_threads(1)
    prm = params if params is not None else load_params()
    if protocol_config and tuning is None:
        from ..config import load_controller_config

        tuning = load_controller_config(protocol_config).tuning
    ts = scenario.sample_time_s
    ctrl = make_controller(mode, prm, ts, tuning, scenario.reference)
    emu = PlantEmulation(prm, scenario, plant_params)
    tr = _transport(transport, protocol_config, dbc)
    x_d = scenario.reference_samples()
    y_m = reference_output(prm, ts, x_d)
    rows: list[tuple] = []
    set_truth = getattr(ctrl, "set_truth", None)
    collecting = gc.isenabled()
    gc.disable()  # the loop makes no reference cycles: a collection would only rescan the rows
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        _loop(emu, ctrl, tr, x_d.tolist(), scenario.transport_delay_samples, set_truth, rows)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        if collecting:
            gc.enable()
    res = _result(scenario, mode, ts, x_d, y_m, rows, ctrl.index_slots, wall, tr.counts())
    res.cpu_s = cpu
    return res


def _loop(
    emu: PlantEmulation,
    ctrl: LoopBase,
    tr: QuantizeTransport | FramesTransport | Cia408Transport,
    x_d: list[float],
    delay: int,
    set_truth: Callable[[FaultState], None] | None,
    rows: list[tuple],
) -> None:
    """The per-sample loop (locals bound once: this is the simulator's hot path), the controller
    run by the same :class:`ControllerDriver` as the daemon and replay, the transport handing it
    the decoded sensor frames: sample k's frames carry the E2E counter k mod 16, a lost sample
    is a cycle without data.

    One row per sample: (x_true, y_s, spool, applied current, faults, fresh, nominal fallback,
    the controller's record: its probe then its J values).
    """
    drv = ControllerDriver(ctrl, x_d.__getitem__)
    queue: deque[float | None] = deque([0.0] * delay)
    held = 0.0
    sample, losses, advance = emu.sample, emu.frame_losses, emu.advance
    sensor, command = tr.sensor, tr.command
    step = drv.step
    record, push = ctrl.sample_record, rows.append
    for k in range(len(x_d)):
        # PlantEmulation.measure's values unpacked (no SensorSample built per sample)
        _, _, pos, spool, pressure, coil, x_true, _, faults, saturated = sample()
        sensor_lost, command_lost = losses()  # both directions' draws (own streams)
        fresh = sensor(drv, k, pos, spool, pressure, coil, saturated, sensor_lost)
        if set_truth is not None:
            set_truth(faults)
        current, enable = step()
        queue.append(command(current if enable else 0.0, k, command_lost))
        arrived = queue.popleft()
        if arrived is not None:
            held = arrived
        push((x_true, pos, spool, advance(held), faults, fresh, ctrl.nominal, record()))


def _result(
    sc: Scenario,
    mode: str,
    ts: float,
    x_d: np.ndarray,
    y_m: np.ndarray,
    rows: list[tuple],
    slots: tuple[int, ...],
    wall: float,
    counts: dict[str, int],
) -> SimResult:
    n = len(x_d)
    x, ys, sp, cur, faults, fresh, nominal, records = zip(*rows, strict=True)
    rec = _flat(records, n, 4 + len(slots))  # the probe's 4 columns, then J per slot
    index = np.full((n, N_SLOTS), np.nan)
    if slots:
        index[:, list(slots)] = rec[:, 4:]
    pr = rec[:, :4]
    tf = _flat(_true_faults(faults), n, 3)
    f = np.asarray
    return SimResult(
        scenario=sc.name,
        controller=mode,
        ts_s=ts,
        event_times_s=tuple(ev.t_s for ev in sc.events),
        t_s=np.arange(n, dtype=np.float64) * ts,
        x_d_m=x_d,
        y_m_m=y_m,
        x_true_m=f(x, dtype=float),
        y_s_m=f(ys, dtype=float),
        spool_m=f(sp, dtype=float),
        current_a=f(cur, dtype=float),
        active_spool=pr[:, 0].astype(np.int64),
        active_position=pr[:, 1].astype(np.int64),
        k_loe_hat=pr[:, 2].copy(),
        k_dft_hat=pr[:, 3].copy(),
        index=index,
        true_k_loe=tf[:, 0].copy(),
        true_k_q=tf[:, 1].copy(),
        true_k_dft=tf[:, 2].copy(),
        fresh=f(fresh, dtype=bool),
        wall_s=wall,
        frame_counts=counts,
        fallback=f(nominal, dtype=bool),
    )


def _flat(rows: Iterable[Iterable[float]], n: int, width: int) -> np.ndarray:
    """``n`` rows of ``width`` numbers as an (n, width) float array (one pass, no nested lists;
    a row of another width leaves a total the reshape refuses)."""
    return np.fromiter(chain.from_iterable(rows), dtype=float).reshape(n, width)


def _true_faults(faults: Iterable[FaultState]) -> Iterator[tuple[float, float, float]]:
    """(k_LOE, k_Q, k_DFT) per sample; the state object only changes at an event."""
    last: FaultState | None = None
    row = (1.0, 1.0, 1.0)
    for fs in faults:
        if fs is not last:
            last, row = fs, (fs.k_loe, fs.k_q, fs.k_dft)
        yield row
