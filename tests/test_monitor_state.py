"""The monitor's parts with real frames (the DBC through cantools, python-can virtual buses, the
aiohttp application on a real socket): what it shows for what the bus said, its row decimation,
the x_d alignment, bus load, the banner, and fault injection (only when allowed)."""

from __future__ import annotations

import asyncio
import math
import uuid
from typing import Any

import can
import numpy as np
import pytest

from ehpss_hil.codec import FrameCodec
from ehpss_hil.commands.monitor import run as monitor_run
from ehpss_hil.errors import InjectError
from ehpss_hil.monitor.listener import BusListener
from ehpss_hil.monitor.reference import CHUNK_SAMPLES, ReferenceTrack
from ehpss_hil.monitor.state import FRAME_OVERHEAD_BITS, MonitorState, choice_names
from ehpss_hil.monitor.tui import render
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.reference import ReferenceModel
from ehpss_hil.scenario import Reference

TS = 1e-3


@pytest.fixture(scope="module")
def codec() -> FrameCodec:
    return FrameCodec()


def _feed(state: MonitorState, rx: FrameCodec, msg: can.Message, t: float) -> None:
    state.feed(rx.classify(msg), msg.dlc, t)


def test_status_shows_what_the_frames_say(codec: FrameCodec) -> None:
    tx, rx = FrameCodec(), FrameCodec()
    st = MonitorState(choice_names(codec))
    frames = [
        tx.encode("CTRL_STATUS", {"State": 3, "FailsafeReason": 1, "Mode": 3, "NominalFallback": 0,
                                  "ActiveSpoolModel": 1, "ActivePosModel": 15, "KLoeHat": 0.5,
                                  "KDftHat": 0.8, "Switches": 4}),
        tx.encode("CTRL_STATS", {"FallbackReason": 2, "Overruns": 7, "RejectedFrames": 3,
                                 "CycleTimeMax": 250e-6}),
        tx.encode("CTRL_INDEX", {"ModelSlot": 1, "J_1": 0.25, "Theta_1": 0.5}),
        tx.encode("PLANT_FAULTS", {"KLoe": 0.5, "KQ": 0.9, "KDft": 0.8}),
        tx.encode("HEARTBEAT_CTRL", {"NmtState": 5}),
    ]  # fmt: skip
    for i, m in enumerate(frames):
        _feed(st, rx, m, 100.0 + i * 1e-3)
    s = st.status()
    assert (s["state"], s["failsafe_reason"], s["mode"]) == ("FAULT", "SENSOR_TIMEOUT", "mmac")
    assert (s["active_spool"], s["active_position"], s["switches"]) == (1, None, 4)
    assert s["values"]["k_loe_hat"] == 0.5 and s["values"]["k_dft_hat"] == 0.8
    assert s["values"]["k_loe_true"] == 0.5 and s["k_q_true"] == 0.9 and s["values"]["k_dft_true"] == 0.8
    assert s["fallback_reason"] == "ESTIMATE_AT_LIMIT" and s["overruns"] == 7 and s["ctrl_rejected"] == 3
    assert s["cycle_time_max_s"] == pytest.approx(250e-6)
    assert s["index"] == [{"slot": 1, "j": 0.25, "theta": 0.5}]
    assert s["nmt"] == {"controller": "OPERATIONAL"}
    assert s["banner"] == {"level": "fault", "text": "FAULT (fail-safe): SENSOR_TIMEOUT"}
    # a corrupted frame is counted by its verdict and changes nothing shown
    bad = tx.encode("CTRL_STATUS", {"State": 2, "Mode": 3})
    bad.data[2] ^= 0xFF
    _feed(st, rx, bad, 100.01)
    s = st.status()
    assert s["verdicts"]["CRC_ERROR"] == 1 and s["verdicts"]["OK"] == len(frames) and s["state"] == "FAULT"
    # J of a slot not heard for more than INDEX_STALE_S is dropped; a silent bus is a fault banner
    later = st.status(now_s=103.0)
    assert later["index"] == [] and later["banner"]["text"] == "bus silent"


def test_rows_are_decimated_and_x_d_follows_the_controller_cycle(codec: FrameCodec) -> None:
    """1 kHz frames for 1.5 s give a row every 10 ms; x_d and y_m are those of sample
    CycleCount − CycleCount₀ (counted from the first enabled command, across the 16-bit wrap)."""
    ref = Reference(kind="sine", amplitude_m=0.001, omega_rad_s=5.0)
    prm = load_params()
    st = MonitorState(choice_names(codec), ReferenceTrack(ref, prm, TS), bitrate=1_000_000)
    tx, rx = FrameCodec(), FrameCodec()
    c0 = 65_400  # wraps after 136 cycles
    n = 1500
    for k in range(n):
        t = 50.0 + k * TS
        _feed(st, rx, tx.encode("SENSOR_POS", {"Position": 1e-4 * k, "Spool": 0.0}), t)
        cmd = {"Enable": int(k >= 3), "CurrentSetpoint": 0.001, "CycleCount": (c0 + k) % 65536}
        _feed(st, rx, tx.encode("VALVE_CMD", cmd), t + 1e-4)
    rows = st.rows_since(0)
    assert len(rows["t_s"]) == pytest.approx(n * TS / 0.01, abs=1)
    assert np.all(np.diff(np.array(rows["t_s"], float)) >= 0.01 - 1e-9)
    last_k = n - 1 - 3
    x_d = ref.sample(np.arange(last_k + 1) * TS)
    y_m = ReferenceModel(prm, TS).simulate(x_d)
    s = st.status()
    assert s["values"]["x_d_m"] == pytest.approx(x_d[last_k], abs=1e-12)
    assert s["values"]["y_m_m"] == pytest.approx(y_m[last_k], abs=1e-12)
    # no PLANT_TRUTH: the error shown is the sensor's y_s − y_m
    assert s["values"]["e_m"] == pytest.approx(1e-4 * (n - 1) - y_m[last_k], abs=1e-9)
    # 2000 frames/s of 8 bytes: (47 + 64) bits each on a 1 Mbit/s bus
    assert s["frames_per_s"] == pytest.approx(2000, rel=0.01)
    assert s["bus_load"] == pytest.approx(2000 * (FRAME_OVERHEAD_BITS + 64) / 1e6, rel=0.01)
    assert st.rows_since(st.seq) == {f: [] for f in rows}
    assert s["reference"] == "aligned"


def test_attached_to_an_active_controller_no_x_d_is_shown(codec: FrameCodec) -> None:
    """The reference starts at the controller's first ACTIVE cycle; a monitor that only heard
    enabled commands does not know that cycle and shows no x_d rather than a shifted one."""
    prm = load_params()
    st = MonitorState(choice_names(codec), ReferenceTrack(Reference(), prm, TS))
    tx, rx = FrameCodec(), FrameCodec()
    for k in range(50):
        _feed(st, rx, tx.encode("VALVE_CMD", {"Enable": 1, "CycleCount": 4000 + k}), 10.0 + k * TS)
    s = st.status()
    assert s["reference"] == "attached late" and s["values"]["x_d_m"] is None
    text = render(s, "virtual:x")
    assert "x_d – mm (attached late)" in text and "[WARN] no CTRL_STATUS from the controller" in text


def test_reference_track_over_chunks_and_back() -> None:
    ref = Reference(kind="sine", amplitude_m=0.002, omega_rad_s=3.0)
    prm = load_params()
    track = ReferenceTrack(ref, prm, TS)
    ks = [5, CHUNK_SAMPLES + 7, 2 * CHUNK_SAMPLES + 1, 3]
    x_d = ref.sample(np.arange(2 * CHUNK_SAMPLES + 2) * TS)
    y_m = ReferenceModel(prm, TS).simulate(x_d)
    for k in ks:
        assert track.at(k) == pytest.approx((x_d[k], y_m[k]), abs=1e-13)


def _listener(allow: bool, channel: str) -> BusListener:
    codec = FrameCodec()
    return BusListener(
        lambda: can.Bus(interface="virtual", channel=channel, receive_own_messages=False),
        codec,
        MonitorState(choice_names(codec)),
        tx_codec=FrameCodec() if allow else None,
        allow_inject=allow,
    )


def test_inject_sends_one_fault_inject_frame_only_when_allowed() -> None:
    channel = f"mon-{uuid.uuid4().hex}"
    peer = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    lis = _listener(True, channel)
    off = _listener(False, channel)
    lis.start()
    off.start()
    try:
        assert lis.inject("k_dft", 0.8) == "FAULT_INJECT k_dft = 0.8"
        got = FrameCodec().classify(peer.recv(timeout=5.0))  # type: ignore[arg-type]
        assert got.name == "FAULT_INJECT" and got.verdict.usable and got.values is not None
        assert got.values["FaultKind"] == 2 and got.values["Value"] == pytest.approx(0.8)
        for bad in (("nonsense", 1.0), ("k_loe", math.nan)):
            with pytest.raises(InjectError):
                lis.inject(*bad)
        with pytest.raises(InjectError, match="--allow-inject"):
            off.inject("k_loe", 0.5)
        assert peer.recv(timeout=0.2) is None  # nothing else was sent
    finally:
        lis.stop()
        off.stop()
        peer.shutdown()


def test_page_endpoints_and_refused_injection() -> None:
    from aiohttp.test_utils import TestClient, TestServer

    from ehpss_hil.monitor.access import AccessPolicy, allowed_hosts
    from ehpss_hil.monitor.server import make_app

    lis = _listener(False, f"mon-{uuid.uuid4().hex}")
    policy = AccessPolicy(hosts=frozenset())

    async def go() -> tuple[int, dict[str, Any], int, str, dict[str, Any]]:
        async with TestClient(TestServer(make_app(lis, policy), host="127.0.0.1")) as client:
            policy.hosts = allowed_hosts("127.0.0.1", client.port or 0)
            r = await client.post("/api/inject", json={"kind": "k_loe", "value": 0.5})
            refused, body = r.status, await r.json()
            page = await client.get("/")
            js = await client.get("/static/uPlot.iife.min.js")
            ws = await client.ws_connect("/ws")
            first = await ws.receive_json(timeout=30)
            await ws.close()
            return refused, body, page.status, (await js.text())[:40], first

    refused, body, page, js, first = asyncio.run(go())
    assert refused == 403 and "--allow-inject" in body["error"]
    assert page == 200 and "uPlot" in js
    assert set(first) == {"rows", "status"} and first["status"]["banner"]["text"] == "no frames on the bus"


def test_bad_options_are_one_line_errors(capsys: pytest.CaptureFixture[str]) -> None:
    from ehpss_hil.cli import main

    assert main(["monitor", "-i", "virtual", "-c", "x", "--refresh-hz", "0"]) == 2
    assert main(["monitor", "-i", "udp_multicast", "-c", "10.0.0.1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("ehpss-hil monitor: error:") for e in err)
    assert monitor_run is not None
