"""Nothing overwrites or deletes a user's file (issue #29, item 3): ``log -o``, ``controller
--log`` and ``firmware-sim --log`` refuse an existing target that is no log of ours (exit 2, one
line, every file as it was) unless ``--overwrite``; rotation removes only files of its log."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from _proc import EHPSS_HIL, EMU_CFG_PATH, ENV, FIRMWARE_SIM, ROOT

from ehpss_hil.canlog import CandumpLogger, read_log
from ehpss_hil.codec import FrameCodec
from ehpss_hil.errors import OutputError

CTRL_CFG = str(ROOT / "configs" / "controller.yaml")
#: the user's files around the target F: the tester's row (F truncated, F.1 and F.2024
#: deleted, F.json replaced)
USER_FILES = {"F": "my notes\n", "F.1": "old data\n", "F.2024": "the 2024 data\n", "F.json": '{"mine": 1}\n'}


def _user_files(d: Path) -> Path:
    d.mkdir(exist_ok=True)
    for name, text in USER_FILES.items():
        (d / name).write_text(text)
    return d / "F"


def _unchanged(d: Path, names: tuple[str, ...] = tuple(USER_FILES)) -> bool:
    return all((d / n).read_text() == USER_FILES[n] for n in names)


def _cli(argv: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(argv, cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=300)


def test_logger_refuses_a_users_file_and_keeps_every_file(tmp_path: Path) -> None:
    f = _user_files(tmp_path)
    with pytest.raises(OutputError, match="--overwrite") as e:
        CandumpLogger(f)
    assert e.value.exit_code == 2 and "\n" not in str(e.value)
    assert _unchanged(tmp_path) and sorted(p.name for p in tmp_path.iterdir()) == sorted(USER_FILES)


def test_a_foreign_numbered_file_alone_is_refused(tmp_path: Path) -> None:
    """F.3 would be replaced by the third rotation: refused while backups reach it."""
    (tmp_path / "F.3").write_text("x")
    with pytest.raises(OutputError, match=r"F\.3"):
        CandumpLogger(tmp_path / "F", backups=5)
    CandumpLogger(tmp_path / "F", backups=2).close()  # rotation never reaches F.3
    assert (tmp_path / "F.3").read_text() == "x"


def test_overwrite_replaces_the_log_and_sidecar_only(tmp_path: Path) -> None:
    f = _user_files(tmp_path)
    frames = [FrameCodec().encode("SENSOR_POS", {}, timestamp_s=1.0)]
    with CandumpLogger(f, overwrite=True) as lg:
        lg.log(frames[0])
    assert len(list(read_log(f, rotated=False))) == 1
    assert json.loads((tmp_path / "F.json").read_text())["log"] == "F"
    assert _unchanged(tmp_path, ("F.1", "F.2024"))


def test_rotation_moves_only_its_own_files(tmp_path: Path) -> None:
    """Rotation keeps its own F.1, F.2 and never touches the user's F.2024; reopening our own
    log removes only the rotated files its sidecar lists."""
    f = tmp_path / "F"
    (tmp_path / "F.2024").write_text("keep")
    codec = FrameCodec()
    with CandumpLogger(f, max_bytes=1000, backups=2) as lg:
        for i in range(60):
            lg.log(codec.encode("SENSOR_POS", {}, timestamp_s=1.0 + i))
    side = json.loads((tmp_path / "F.json").read_text())
    assert [x["name"] for x in side["files"]] == ["F.2", "F.1", "F"]
    assert (tmp_path / "F.2024").read_text() == "keep"
    # our own earlier log is replaced without --overwrite; its rotations go, F.2024 stays
    CandumpLogger(f, backups=2).close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["F", "F.2024", "F.json"]


def test_log_command_refuses_then_overwrites(tmp_path: Path) -> None:
    f = _user_files(tmp_path)
    base = [*EHPSS_HIL, "log", "-i", "virtual", "-c", "owned", "-o", str(f), "--duration", "0.2"]
    r = _cli(base)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().count("\n") == 0 and "--overwrite" in r.stderr and "Traceback" not in r.stderr
    assert _unchanged(tmp_path)
    r = _cli([*base, "--overwrite"])
    assert r.returncode == 0, r.stderr
    assert (
        list(read_log(f, rotated=False)) == [] and json.loads((tmp_path / "F.json").read_text())["log"] == "F"
    )
    assert _unchanged(tmp_path, ("F.1", "F.2024"))
    r = _cli(base)  # F and F.json are ours now; the user's F.1 still is not
    assert r.returncode == 2 and "F.1 exist" in r.stderr, r.stderr
    r = _cli([*base, "--backups", "0"])  # no rotation ever reaches F.1: ours is replaced
    assert r.returncode == 0, r.stderr
    assert _unchanged(tmp_path, ("F.1", "F.2024"))


@pytest.mark.parametrize(
    "argv",
    [
        [*EHPSS_HIL, "controller", "-c", CTRL_CFG, "--interface", "virtual", "--channel", "owned-c"],
        [*FIRMWARE_SIM, "-c", EMU_CFG_PATH, "--interface", "virtual", "--channel", "owned-e"],
    ],
    ids=["controller", "firmware-sim"],
)
def test_process_log_refuses_a_users_file(tmp_path: Path, argv: list[str]) -> None:
    f = _user_files(tmp_path)
    r = _cli([*argv, "--log", str(f), "--duration", "0.2"])
    assert r.returncode == 2, r.stderr
    err = [ln for ln in r.stderr.splitlines() if "--log" in ln]
    assert len(err) == 1 and "--overwrite" in err[0] and "Traceback" not in r.stderr
    assert _unchanged(tmp_path)


def test_bench_faults_rows_of_the_logs(tmp_path: Path) -> None:
    """``bench faults`` runs the same three cases and passes them."""
    from ehpss_hil.reliability.owned import log_rows

    rows = log_rows(tmp_path)
    assert len(rows) == 3 and all(r.ok for r in rows), rows
