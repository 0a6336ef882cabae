"""``ehpss-hil bench faults``: the reliability suite of issue 8 as one table.

Fuzzing (crafted frames with a known verdict and random ones through the codec, the controller
loop and the emulator), frame loss per direction (lockstep simulator: case 1 mmac RMS against
lossless; processes: ``ehpss-hil run`` with a watchdog audit), duplicated/reordered/burst sensor
frames against a controller process, kill -9 of either process (``--trials``), SIGTERM during a
run, every config/scenario key made wrong, and hostile surroundings (issue #16: datagrams on the
bus that are no frame, foreign files in ``run --out``, a full disk under the logs, a second
VALVE_CMD transmitter), issue #29's rows (:mod:`ehpss_hil.reliability.owned`: a user's files
under the logs and the campaign, tampered journals, vendor DBCs check-config must refuse) and a
rogue CANopen node beside the CiA 408 master, one row per case of
:data:`~ehpss_hil.reliability.rogue_cia408.CASES`. Process
sections need a private network namespace (root + ``unshare``) and say so when they cannot run;
the full-disk row needs root for ``mount``. Exit 1 when any row fails. Implementation:
:mod:`ehpss_hil.reliability`.
"""

from __future__ import annotations

import argparse
import dataclasses
import random
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from ..reliability import badinput, duplicates, fuzz, hostile, kills, loss, owned, rogue, rogue_cia408, stray
from ..reliability.procs import skip_reason
from ..reliability.table import (
    Row,
    Summary,
    bad_rows,
    dup_rows,
    format_table,
    fuzz_rows,
    hostile_rows,
    kill_rows,
    loss_rows,
    rogue_rows,
    term_rows,
)
from .common import Scorecard, finite_json, write_json

NAME = "faults"
HELP = (
    "reliability suite: fuzzing, frame loss, duplicates, kill -9, SIGTERM, bad configs, "
    "stray datagrams, foreign files in --out, full disk, a second transmitter, a user's files "
    "under logs and campaigns, tampered journals, bad vendor DBCs, a rogue CANopen node"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--trials", type=int, default=10, help="kill -9 trials (default 10)")
    p.add_argument(
        "--quick", action="store_true", help="small counts, short runs, a quarter of the bad keys (< 1 min)"
    )
    p.add_argument("--seed", type=int, default=1, help="seed of fuzzing and fault timing")
    p.add_argument("--out", type=Path, help="keep the trial directories here")
    p.add_argument("--json", metavar="FILE", help="write every result as JSON")


def _say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _victims(n: int, rng: random.Random) -> list[str]:
    """Both processes equally often (one more controller kill when n is odd), shuffled."""
    v = ["controller", "emulator"] * (n // 2) + (["controller"] if n % 2 else [])
    rng.shuffle(v)
    return v


def _process_sections(
    a: argparse.Namespace, out: Path, rng: random.Random, rows: list[Row], s: Summary, raw: dict[str, Any]
) -> None:
    q = a.quick
    _say("frame loss across processes ...")
    if q:
        pl = loss.processes_loss(out / "loss", levels=(0.2,), lossless=False, duration_s=1.0)
    else:
        pl = loss.processes_loss(out / "loss")
        pl.append(
            loss.process_loss(
                out / "loss" / "deploy-sensor-0.2",
                "sensor",
                0.2,
                timeout_cycles=loss.configured_timeout_cycles(),
            )
        )
    rows += loss_rows(pl, s)
    _say("duplicated / reordered / burst sensor frames ...")
    n_dup = 1 if q else max(1, a.trials // 5)
    dups = [duplicates.dup_trial(out / f"dup-{i}", 500 if q else 2000, a.seed + i) for i in range(n_dup)]
    rows += dup_rows(dups, s)
    n_kill = min(a.trials, 2) if q else a.trials
    _say(f"kill -9: {n_kill} trials ...")
    ks = [kills.kill_trial(out / f"kill-{i}", i, v, rng) for i, v in enumerate(_victims(n_kill, rng))]
    rows += kill_rows(ks, s)
    _say("SIGTERM during a run ...")
    firsts = ["controller"] if q else ["controller", "emulator"]
    ts = [kills.term_trial(out / f"term-{i}", i, f, rng) for i, f in enumerate(firsts)]
    rows += term_rows(ts, s)
    _say("bad configs and scenarios ...")
    muts = badinput.mutations(out / "bad")
    if q:
        muts = muts[::4]
    bad, frames = badinput.run_bad_inputs(out / "bad", muts)
    rows += bad_rows(bad, frames, s)
    raw.update(
        process_loss=pl, duplicates=dups, kills=ks, sigterm=ts, bad_inputs=bad, bad_input_bus_frames=frames
    )
    _hostile_section(q, out, rows, s, raw)


def _hostile_section(q: bool, out: Path, rows: list[Row], s: Summary, raw: dict[str, Any]) -> None:
    _say("stray datagrams, foreign files in --out, full disk ...")
    st = stray.stray_trial(out / "stray", rounds=2 if q else 10)
    fo = hostile.foreign_files_trial(out / "hostile", hostile.short_scenario(out / "short.yaml"))
    disk = None
    if hostile.tmpfs_unavailable_reason() is None:
        disk = hostile.disk_full_trial(out / "disk", seconds=3.0 if q else 6.0)
    rows += hostile_rows(st, fo, disk, s)
    _say("a second VALVE_CMD transmitter ...")
    rg = rogue.rogue_trial(out / "rogue", rogue_s=0.5 if q else 1.0, duration_s=2.0 if q else 3.0)
    rows += rogue_rows(rg, s)
    _say("a rogue CANopen node beside the CiA 408 master ...")
    rc = [
        rogue_cia408.rogue_cia408_trial(
            out / f"rogue-cia408-{case}", case, rogue_s=0.5 if q else 1.0, duration_s=4.0 if q else 6.0
        )
        for case in rogue_cia408.CASES
    ]
    rows += rogue_cia408.cia408_rogue_rows(rc, s)
    raw.update(stray=st, foreign_files=fo, disk_full=disk, rogue=rg, rogue_cia408=rc)


def run(args: argparse.Namespace) -> Scorecard:
    t0 = time.monotonic()
    rng = random.Random(args.seed)
    rows: list[Row] = []
    s = Summary()
    raw: dict[str, Any] = {}
    n = 3000 if args.quick else 30000
    _say(f"fuzzing: {n} crafted + {n} random frames through 3 receivers ...")
    tallies = fuzz.fuzz_all(n, n, args.seed)
    rows += fuzz_rows(tallies, s)
    _say("frame loss on the lockstep simulator ...")
    sim = loss.sim_loss()
    rows += loss_rows(sim, s)
    raw.update(fuzz=tallies, sim_loss=sim)
    _say("a user's files, tampered journals, bad vendor DBCs ...")
    with tempfile.TemporaryDirectory(prefix="ehpss-bench-owned-") as tmp:
        own, raw_own = owned.owned_rows(args.out / "owned" if args.out else Path(tmp))
    rows += own
    raw.update(raw_own)
    why = skip_reason()
    if why is None:
        with tempfile.TemporaryDirectory(prefix="ehpss-bench-faults-") as tmp:
            out = args.out or Path(tmp)
            _process_sections(args, out, rng, rows, s, raw)
    else:
        rows.append(Row("processes", "skipped", why, trial=False))
        s.failed.append("process sections skipped")
    s.add(rows)
    wall = time.monotonic() - t0
    mode = "quick" if args.quick else "full"
    print(
        f"ehpss-hil bench faults ({mode}, {args.trials} kill trials requested, seed "
        f"{args.seed}, wall {wall:.0f} s)"
    )
    print(format_table(rows))
    print(s.line())
    write_json(
        args.json,
        finite_json(
            {
                "summary": dataclasses.asdict(s),
                "wall_s": wall,
                "rows": [dataclasses.asdict(r) for r in rows],
                "results": {k: _jsonable(v) for k, v in raw.items()},
            }
        ),
    )
    card = Scorecard()
    for r in rows:  # the table's PASS/FAIL, then the summary line's
        card.mark(r.ok, f"{r.fault}: {r.case}")
    card.mark(s.ok, "summary: " + ", ".join(s.failed or ["crashes or data lost"]))
    return card


def _jsonable(v: Any) -> Any:
    if isinstance(v, list):
        return [_jsonable(x) for x in v]
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return dataclasses.asdict(v)
    return v
