"""The DBC's ARXML export loads in cantools and says what the DBC says: every message and
signal (signals named in several messages as ``MESSAGE_signal``), frames encoded with the DBC
decode to the same values with the ARXML, and the E2E DataIDs give the same CRC."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import cantools
import pytest
from cantools.autosar.end_to_end import compute_profile2_crc
from cantools.database.can import Database, Message, Signal

from ehpss_hil import DEFAULT_DBC
from ehpss_hil.protocol.arxml import E2E_ATTRIBUTE, export_arxml, export_names

DBCS = [DEFAULT_DBC, DEFAULT_DBC.parent / "vendor-example.dbc"]


def _load(path: Path) -> Database:
    db = cantools.database.load_file(str(path))
    assert isinstance(db, Database)
    return db


@pytest.fixture(params=DBCS, ids=lambda p: p.name)
def pair(
    request: pytest.FixtureRequest, tmp_path: Path
) -> tuple[Database, Database, dict[tuple[str, str], str]]:
    """(the DBC, its ARXML export loaded by cantools, the export's signal names)."""
    dbc = _load(request.param)
    export_arxml(request.param, tmp_path / "out.arxml")
    return dbc, _load(tmp_path / "out.arxml"), export_names(dbc)


def _arxml_name(msg: Message, sig: Signal, names: dict[tuple[str, str], str]) -> str:
    """The name cantools gives ``sig`` of ``msg`` in the ARXML (a multiplexer is the PDU's
    selector field, which cantools names ``<MESSAGE>_selector1``)."""
    return f"{msg.name}_selector1" if sig.is_multiplexer else names[(msg.name, sig.name)]


def test_the_names_are_unique_and_only_the_shared_ones_change() -> None:
    names = export_names(_load(DEFAULT_DBC))
    assert names[("SENSOR_POS", "CRC")] == "SENSOR_POS_CRC"
    assert names[("VALVE_CMD", "CRC")] == "VALVE_CMD_CRC"
    assert names[("SENSOR_POS", "Spool")] == "Spool"  # in one message only
    assert len(set(names.values())) == len(names)


def test_every_message_and_signal_of_the_dbc_is_in_the_arxml(pair: Any) -> None:
    dbc, arxml, names = pair
    assert sorted(m.name for m in arxml.messages) == sorted(m.name for m in dbc.messages)
    for m in dbc.messages:
        a = arxml.get_message_by_name(m.name)
        assert (a.frame_id, a.length, a.is_extended_frame, a.is_fd) == (
            m.frame_id,
            m.length,
            m.is_extended_frame,
            m.is_fd,
        )
        assert a.comment == m.comment and a.is_multiplexed() == m.is_multiplexed(), m.name
        assert len(a.signals) == len(m.signals), m.name
        for s in m.signals:
            t = a.get_signal_by_name(_arxml_name(m, s, names))
            where = f"{m.name}.{s.name}"
            assert (t.start, t.length, t.byte_order, t.is_float) == (
                s.start,
                s.length,
                s.byte_order,
                s.is_float,
            )
            assert s.is_float or t.is_signed == s.is_signed, where  # a float has no signedness
            assert (t.scale, t.offset, t.unit, t.comment) == (s.scale, s.offset, s.unit, s.comment), where
            assert {k: str(v) for k, v in (t.choices or {}).items()} == {
                k: str(v) for k, v in (s.choices or {}).items()
            }, where
            assert t.is_multiplexer == s.is_multiplexer and t.multiplexer_ids == s.multiplexer_ids, where
            if s.multiplexer_signal is not None:
                assert t.multiplexer_signal == f"{m.name}_selector1", where
            if not s.is_multiplexer:  # cantools gives the selector field no range
                for got, want in ((t.minimum, s.minimum), (t.maximum, s.maximum)):
                    assert got == (None if want is None else pytest.approx(want, rel=1e-12)), where


def _values(msg: Message, mux_id: int | None) -> dict[str, float]:
    """A value inside each signal's range for one multiplexer alternative (raw steps, so
    encoding is exact)."""
    out: dict[str, float] = {}
    for i, s in enumerate(msg.signals):
        if s.is_multiplexer:
            out[s.name] = mux_id or 0
        elif s.multiplexer_ids is None or mux_id in s.multiplexer_ids:
            if s.is_float:
                out[s.name] = 1.5 + i
            else:
                lo = -(1 << (s.length - 1)) if s.is_signed else 0
                raw = lo + (i * 7919 + 3) % (1 << s.length)
                out[s.name] = raw * s.scale + s.offset
    return out


def test_frames_encoded_with_the_dbc_decode_the_same_with_the_arxml(pair: Any) -> None:
    dbc, arxml, names = pair
    for m in dbc.messages:
        a = arxml.get_message_by_name(m.name)
        ids = sorted({i for s in m.signals for i in (s.multiplexer_ids or ())}) or [None]
        for mux_id in ids:
            values = _values(m, mux_id)
            data = m.encode(values, strict=False)
            got = a.decode(data, decode_choices=False)
            want = m.decode(data, decode_choices=False)
            by_name = {s.name: _arxml_name(m, s, names) for s in m.signals}
            assert {by_name[k]: v for k, v in want.items()} == got, (m.name, mux_id)


def test_the_e2e_data_ids_give_the_dbc_s_crc(tmp_path: Path) -> None:
    export_arxml(DEFAULT_DBC, tmp_path / "out.arxml")
    dbc, arxml = _load(DEFAULT_DBC), _load(tmp_path / "out.arxml")
    protected = 0
    for m in dbc.messages:
        attr = m.dbc.attributes.get(E2E_ATTRIBUTE) if m.dbc is not None else None
        a = arxml.get_message_by_name(m.name)
        if attr is None or not attr.value or m.is_multiplexed():
            assert a.autosar is None or a.autosar.e2e is None, m.name
            continue
        ids = [int(v) for v in str(attr.value).split(",")]
        assert a.autosar is not None and a.autosar.e2e is not None, m.name
        assert a.autosar.e2e.data_ids == ids
        for counter in (0, 5, 15):
            payload = bytes([0, counter]) + bytes(range(m.length - 2))
            assert compute_profile2_crc(payload, a) == compute_profile2_crc(payload, ids[counter])
        protected += 1
    assert protected >= 10


def test_the_command_writes_the_file_and_refuses_a_bad_dbc_in_one_line(tmp_path: Path) -> None:
    cli = [sys.executable, "-m", "ehpss_hil.cli", "export-arxml"]
    ok = subprocess.run([*cli, "out.arxml"], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert ok.returncode == 0, ok.stderr
    assert len(_load(tmp_path / "out.arxml").messages) == len(_load(DEFAULT_DBC).messages)
    bad = subprocess.run(
        [*cli, "x.arxml", "--dbc", "missing.dbc"], capture_output=True, text=True, cwd=tmp_path, timeout=120
    )
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert "missing.dbc" in bad.stderr and not (tmp_path / "x.arxml").exists()
