"""The logger's BLF and MF4 formats: every frame kind written and read back (python-can's
readers, asammdf), the sidecar and the ownership rules as for candump, the format from the
suffix or asked for (a name that disagrees refused), ``log.format`` validated, and the three
programs' ``--log-format``."""

from __future__ import annotations

import json
import subprocess
import sys
import typing
from pathlib import Path

import can
import pytest

from ehpss_hil.canlog import CandumpLogger, read_frames, read_sidecar
from ehpss_hil.canlog.binary import MF4_CHUNK_FRAMES
from ehpss_hil.canlog.formats import LOG_FORMATS, log_format
from ehpss_hil.cli import main
from ehpss_hil.config import LogConfig, load_controller_config
from ehpss_hil.errors import ConfigError, OutputError

T0 = 1_700_000_000.25
#: a BLF stores its start time to the ms (SYSTEMTIME): read-back times may be that much early
BLF_START_RESOLUTION_S = 1e-3


def _frames(n: int) -> list[can.Message]:
    """``n`` data frames (standard, extended, CAN FD) 1 ms apart, then a remote and an error
    frame (timestamps in s)."""
    out = []
    for k in range(n):
        kind = k % 3
        out.append(
            can.Message(
                timestamp=T0 + k * 1e-3,
                arbitration_id=(0x100 + k % 7) if kind != 1 else 0x1ABC000 + k,
                is_extended_id=kind == 1,
                is_fd=kind == 2,
                bitrate_switch=kind == 2,
                data=bytes((k + i) % 256 for i in range(12 if kind == 2 else 8)),
            )
        )
    out.append(can.Message(timestamp=T0 + n * 1e-3, arbitration_id=0x123, is_remote_frame=True, dlc=4))
    out.append(can.Message(timestamp=T0 + (n + 1) * 1e-3, arbitration_id=0x80, is_error_frame=True))
    return out


def _key(m: can.Message) -> tuple[object, ...]:
    return (m.arbitration_id, m.is_extended_id, m.is_remote_frame, m.is_error_frame, m.is_fd)


@pytest.mark.parametrize("fmt", ["blf", "mf4"])
def test_every_frame_kind_is_written_and_read_back(fmt: str, tmp_path: Path) -> None:
    """More frames than an MF4 chunk: every one read back by python-can (in file order for the
    data frames), flags, data and time kept; the sidecar says the format and the count."""
    if fmt == "mf4":
        pytest.importorskip("asammdf")
    path = tmp_path / f"run.{fmt}"
    sent = _frames(2 * MF4_CHUNK_FRAMES + 17)
    with CandumpLogger(path, sidecar={"note": "x"}) as logger:
        for m in sent:
            logger.log(m)
    got = list(read_frames(path))
    assert len(got) == len(sent)
    tol = BLF_START_RESOLUTION_S if fmt == "blf" else 1e-6
    for a, b in zip(sorted(got, key=lambda m: m.timestamp), sent, strict=True):
        assert _key(a) == _key(b), (a, b)
        assert b.timestamp - tol <= a.timestamp <= b.timestamp + 1e-6, (a, b)
        if not b.is_remote_frame and not b.is_error_frame:
            assert bytes(a.data) == bytes(b.data), (a, b)
    side = read_sidecar(path)
    assert side is not None
    assert side["format"] == fmt.upper() and side["status"] == "closed" and side["note"] == "x"
    assert side["counts"]["written"] == len(sent) and side["counts"]["dropped"] == 0
    assert side["rotation"]["backups"] == 0
    assert side["files"] == [
        {
            "name": path.name,
            "lines": len(sent),
            "bytes": path.stat().st_size,
            "first_t_s": sent[0].timestamp,
            "last_t_s": sent[-1].timestamp,
        }
    ]


def test_asammdf_opens_the_mf4_and_python_can_s_blf_reader_the_blf(tmp_path: Path) -> None:
    asammdf = pytest.importorskip("asammdf")
    sent = _frames(40)
    for fmt in ("mf4", "blf"):
        with CandumpLogger(tmp_path / f"r.{fmt}") as logger:
            for m in sent:
                logger.log(m)
    mdf = asammdf.MDF(tmp_path / "r.mf4")
    try:
        ids = mdf.get("CAN_DataFrame.ID", raw=True).samples
        assert [int(i) & 0x1FFFFFFF for i in ids] == [m.arbitration_id for m in sent[:40]]
    finally:
        mdf.close()
    with can.BLFReader(tmp_path / "r.blf") as reader:
        assert [m.arbitration_id for m in reader] == [m.arbitration_id for m in sent]


@pytest.mark.parametrize(
    ("name", "fmt", "want"),
    [
        ("run.log", None, "candump"),
        ("run", None, "candump"),
        ("run.BLF", None, "blf"),
        ("run.mf4", "auto", "mf4"),
        ("run.blf", "blf", "blf"),
        ("run.txt", "candump", "candump"),
    ],
)
def test_the_format_comes_from_the_suffix_unless_asked(name: str, fmt: str | None, want: str) -> None:
    assert log_format(name, fmt) == want


@pytest.mark.parametrize(("name", "fmt"), [("run.log", "blf"), ("run.blf", "mf4"), ("run.mf4", "candump")])
def test_a_name_that_disagrees_with_the_format_is_refused(name: str, fmt: str, tmp_path: Path) -> None:
    with pytest.raises(OutputError, match="the name must"):
        CandumpLogger(tmp_path / name, fmt=fmt)
    assert not list(tmp_path.iterdir())


def test_a_log_of_ours_is_replaced_and_a_foreign_blf_refused(tmp_path: Path) -> None:
    path = tmp_path / "run.blf"
    for _ in range(2):  # the second open replaces the first log (its sidecar names it)
        with CandumpLogger(path) as logger:
            logger.log(_frames(1)[0])
    assert len(list(read_frames(path))) == 1
    foreign = tmp_path / "theirs.blf"
    foreign.write_bytes(b"user data")
    with pytest.raises(OutputError, match="did not write"):
        CandumpLogger(foreign)
    assert foreign.read_bytes() == b"user data"


def test_log_format_in_the_config_is_validated(tmp_path: Path) -> None:
    """``log.format`` is one of auto + the writer's formats; anything else names the key."""
    assert typing.get_args(typing.get_type_hints(LogConfig)["format"]) == ("auto", *LOG_FORMATS)
    cfg = tmp_path / "c.yaml"
    cfg.write_text("log: {path: x.blf, format: blf}\n")
    assert load_controller_config(cfg).log.format == "blf"
    cfg.write_text("log: {format: asc}\n")
    with pytest.raises(ConfigError, match=r"log\.format"):
        load_controller_config(cfg)


def test_log_command_writes_the_format_asked_for(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``ehpss-hil log --log-format blf``: a BLF (an empty one: nobody sends) with its sidecar;
    a .log name with ``--log-format blf`` is one line, exit 2, nothing written."""
    out = tmp_path / "bus.blf"
    assert (
        main(
            ["log", "-i", "virtual", "-c", "fmt", "-o", str(out), "--log-format", "blf", "--duration", "0.05"]
        )
        == 0
    )
    assert json.loads(out.with_name("bus.blf.json").read_text())["format"] == "BLF"
    assert list(read_frames(out)) == []
    rc = main(["log", "-i", "virtual", "-c", "fmt", "-o", str(tmp_path / "b.log"), "--log-format", "blf"])
    assert rc == 2
    assert "log format blf: the name must end in .blf" in capsys.readouterr().err
    assert not (tmp_path / "b.log").exists()


def test_python_can_loads_asammdf_only_when_an_mf4_is_asked_for(tmp_path: Path) -> None:
    """In a fresh interpreter: ``import ehpss_hil, can`` loads neither asammdf nor pandas; an MF4
    log is then written and read back all the same (and ``import asammdf`` works as usual)."""
    pytest.importorskip("asammdf")
    code = (
        "import sys, can, ehpss_hil.cli\n"
        "from ehpss_hil.canlog import CandumpLogger, read_frames\n"
        "loaded = sorted({'asammdf', 'pandas'} & set(sys.modules))\n"
        f"with CandumpLogger({str(tmp_path / 'x.mf4')!r}) as log:\n"
        "    log.log(can.Message(timestamp=1.7e9, arbitration_id=0x7, data=b'ab'))\n"
        f"got = [bytes(m.data) for m in read_frames({str(tmp_path / 'x.mf4')!r})]\n"
        "import asammdf\n"
        "print(loaded, got)\n"
    )
    code = "import ehpss_hil\n" + code  # ehpss_hil first, as the programs import it
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "[] [b'ab']"
