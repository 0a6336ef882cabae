"""Per-direction frame loss: the scenario keys, the one loss draw both the simulator and the
emulator use, case 1 on the lockstep simulator (5 % → mmac RMS ≤ 2× lossless), and a realtime
run of real processes whose watchdog trips only on real timeouts."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.errors import ConfigError
from ehpss_hil.physics.load import load_params
from ehpss_hil.reliability.loss import process_loss, sim_loss
from ehpss_hil.scenario import FrameLoss, load_scenario
from ehpss_hil.sim import run_scenario

CASE1 = PROJECT_ROOT / "scenarios" / "case1-loe.yaml"
NETNS_SKIP = netns_unavailable_reason()


def _scenario(tmp: Path, extra: str, events: str = "") -> Path:
    text = CASE1.read_text().replace("frame_loss: 0.0\n", f"frame_loss: 0.0\n{extra}")
    p = tmp / "sc.yaml"
    p.write_text(text + events)
    return p


def test_directional_keys_override_frame_loss_top_level_and_in_events(tmp_path: Path) -> None:
    sc = load_scenario(
        _scenario(
            tmp_path,
            "sensor_frame_loss: 0.2\n",
            "  - {t_s: 3.0, frame_loss: 0.1}\n  - {t_s: 3.5, command_frame_loss: 0.3}\n",
        )
    )
    assert [loss for _, _, loss in sc.fault_timeline()] == [
        FrameLoss(0.2, 0.0),
        FrameLoss(0.2, 0.0),
        FrameLoss(0.2, 0.0),
        FrameLoss(0.2, 0.0),
        FrameLoss(0.1, 0.1),
        FrameLoss(0.1, 0.3),
    ]


@pytest.mark.parametrize(
    "extra,events,key",
    [
        ("sensor_frame_loss: 1.5\n", "", "sensor_frame_loss"),
        ("command_frame_loss: -0.1\n", "", "command_frame_loss"),
        ("", "  - {t_s: 3.0, sensor_frame_loss: 2}\n", "events[3].sensor_frame_loss"),
        ("", "  - {t_s: 3.0, command_frame_loss: lots}\n", "events[3].command_frame_loss"),
    ],
)
def test_bad_loss_values_name_the_key_path(tmp_path: Path, extra: str, events: str, key: str) -> None:
    with pytest.raises(ConfigError) as exc:
        load_scenario(_scenario(tmp_path, extra, events))
    assert exc.value.key_path == key


def test_one_direction_only_and_the_same_draws_as_frame_loss() -> None:
    sc = replace(load_scenario(CASE1), duration_s=2.0, events=())
    prm = load_params()

    def draws(**loss: float) -> tuple[np.ndarray, np.ndarray]:
        emu = PlantEmulation(prm, replace(sc, **loss))  # type: ignore[arg-type]
        s, c = zip(*((emu.frame_lost(0), emu.frame_lost(1)) for _ in range(2000)), strict=True)
        return np.array(s), np.array(c)

    both_s, both_c = draws(frame_loss=0.2)
    only_s, none_c = draws(sensor_frame_loss=0.2)
    none_s, only_c = draws(command_frame_loss=0.2)
    assert not none_c.any() and not none_s.any()
    np.testing.assert_array_equal(only_s, both_s)  # the same seeded stream per direction
    np.testing.assert_array_equal(only_c, both_c)
    assert 0.15 < both_s.mean() < 0.25 and 0.15 < both_c.mean() < 0.25
    a = run_scenario(replace(sc, frame_loss=0.05), "mmac", prm)
    b = run_scenario(replace(sc, sensor_frame_loss=0.05, command_frame_loss=0.05), "mmac", prm)
    for k, v in a.arrays().items():
        np.testing.assert_array_equal(v, b.arrays()[k], err_msg=k)


def test_case1_five_percent_loss_each_direction_at_most_twice_lossless() -> None:
    rows = sim_loss(levels=(0.05,))
    base, sensor, command = rows
    assert base.direction == "none" and sensor.direction == "sensor"
    assert sensor.rms_m != base.rms_m and command.rms_m != base.rms_m  # loss did act
    assert sensor.ratio is not None and sensor.ratio <= 2.0
    assert command.ratio is not None and command.ratio <= 2.0
    assert sensor.target and command.target


@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
@pytest.mark.parametrize("direction", ["sensor", "command"])
def test_processes_lose_one_direction_and_trip_only_on_real_timeouts(tmp_path: Path, direction: str) -> None:
    """30 % loss in one direction, realtime processes, the shipped 3-cycle watchdog: with sensor
    loss it must trip (three samples in a row are lost every few hundred ms); either way every
    trip must follow a real timeout, or be the loop's own LOOP_OVERRUN on a starved host (its
    CTRL_STATUS says so, and its summary counts no fewer), and every real timeout must trip."""
    row = process_loss(tmp_path, direction, 0.3, duration_s=1.0, timeout_cycles=3)
    assert row.exit_ok and row.audit is not None
    a = row.audit
    assert a.spurious == 0 and a.missed == 0 and a.real_timeouts + a.starved >= a.trips, a
    ctl = json.loads((tmp_path / "run" / "controller-summary.json").read_text())
    assert a.starved <= ctl["watchdog_trips_by_reason"].get("LOOP_OVERRUN", 0), (a, ctl)
    emu = json.loads((tmp_path / "run" / "emulator-summary.json").read_text())
    lost_s, lost_c = emu["lost_sensor_frames"], emu["lost_command_frames"]
    # the loss is drawn for each sample the emulator sent or dropped, not for the periods it
    # slept through on a loaded host (those samples are skipped, never drawn)
    drawn = emu["periods"] - emu["skipped_periods"]
    if direction == "sensor":
        assert lost_c == 0
        assert drawn < 200 or 0.2 < lost_s / drawn < 0.4
        assert a.trips - a.at_end >= 1
    else:
        assert lost_s == 0 and 0.2 < lost_c / (lost_c + emu["commands_accepted"]) < 0.4
