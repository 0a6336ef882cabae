"""Whose files, and DBCs check-config must refuse (issue #29, items 3, 4 and 6), as rows of
``ehpss-hil bench faults``; every case runs the real command on real files:

- ``log -o F``, ``controller --log F``, ``firmware-sim --log F`` (``virtual`` bus) on a user's F,
  F.1, F.2024, F.json: exit 2, every file kept; ``log --overwrite``: exit 0, F.1 and F.2024 kept;
- ``campaign --out DIR`` on a user's summary.md, summary.json, results.parquet, two PNGs: exit
  2, all kept; a campaign ``name: ../../../../elsewhere``: exit 2, nothing written;
- a journal with a tampered record (fault class ``../../..``, a metric missing, a metric that is
  a string, another index): exit 2 and one line, then exit 0 once the line is deleted; a
  symlinked journal: exit 2, the user's file unchanged;
- vendor DBCs: factor 0, 1e-300, denormal, offset 1e308, min > max, ``[0|0.001] mA``, 20 MB:
  ``check-config`` exit 2, and the controller on a missing interface exit 2 (not 3: before the
  bus); a campaign of a million samples: ``check-config`` exit 0 within a 600 MB address space.
"""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import PROJECT_ROOT
from .procs import PY
from .table import Row

USER_LOG = ("F", "F.1", "F.2024", "F.json")
USER_CAMPAIGN = ("summary.md", "summary.json", "results.parquet", "coverage-onset.png", "distributions.png")
CAMPAIGN = """\
name: {name}
base: {base}
samples: {samples}
sampler: sobol
seed: 5
duration_s: 0.3
faults: {{count: [1, 1], onset_s: [0.05, 0.2], kinds: {{loe: {{}}, drift: {{}}}}}}
"""
_CUR = 'SG_ CurrentDemand : 23|22@0- (0.0005,0) [-1000|1000] "mA"'
_POS = 'SG_ PistonPos : 23|22@0- (0.0005,0) [-500|500] "mm"'
_SPOOL = 'SG_ SpoolPos : 40|20@1- (0.05,0) [-10000|10000] "um"'
_PRES = 'SG_ LoadPress m0 : 16|16@1+ (0.01,-300) [-300|355.35] "bar"'
#: (case, line of dbc/vendor-example.dbc, its replacement)
BAD_DBCS = (
    ("factor 0", _CUR, _CUR.replace("(0.0005,0)", "(0,0)")),
    ("factor 1e-300", _POS, _POS.replace("(0.0005,0)", "(1e-300,0)")),
    ("factor 1e-310 (denormal)", _SPOOL, _SPOOL.replace("(0.05,0)", "(1e-310,0)")),
    ("offset 1e308", _PRES, _PRES.replace("(0.01,-300)", "(0.01,1e308)")),
    ("current min > max", _CUR, _CUR.replace("[-1000|1000]", "[1000|-1000]")),
    ("current [0, 0.001] mA", _CUR, _CUR.replace("[-1000|1000]", "[0|0.001]")),
)
DBC_MB = 20


def _cli(argv: list[str], limit_kb: int = 0, timeout_s: float = 600.0) -> tuple[int | None, list[str], float]:
    """(exit code, non-empty lines on stderr, wall s) of ``python -m argv…``."""
    cmd = [PY, "-m", *argv]
    if limit_kb:
        cmd = ["bash", "-c", f"ulimit -v {limit_kb} && exec {shlex.join(cmd)}"]
    t0 = time.monotonic()
    try:
        r = subprocess.run(cmd, cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return None, [], time.monotonic() - t0
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    return r.returncode, lines, time.monotonic() - t0


def _plant(d: Path, names: tuple[str, ...]) -> Callable[[], int]:
    """Write the user's files ``names`` into ``d``; returns a counter of those still unchanged."""
    d.mkdir(parents=True, exist_ok=True)
    for n in names:
        (d / n).write_text(f"the user's {n}\n")
    return lambda: sum((d / n).is_file() and (d / n).read_text() == f"the user's {n}\n" for n in names)


def log_rows(out: Path) -> list[Row]:
    """A user's F, F.1, F.2024, F.json under each process's log, and ``log --overwrite``."""
    rows = []
    procs = {
        "log -o F": ["ehpss_hil.cli", "log", "-i", "virtual", "-c", "own", "-o"],
        "controller --log F": [
            *("ehpss_hil.cli", "controller", "-c", "configs/controller.yaml"),
            *("--interface", "virtual", "--duration", "0.2", "--log"),
        ],
        "firmware-sim --log F": [
            *("firmware_sim.cli", "-c", "configs/emulator.yaml"),
            *("--interface", "virtual", "--duration", "0.2", "--log"),
        ],
    }
    for case, argv in procs.items():
        d = out / case.split()[0]
        kept = _plant(d, USER_LOG)
        code, _lines, _ = _cli(
            [*argv, str(d / "F"), *(["--duration", "0.2"] if case.startswith("log") else [])]
        )
        measured = f"exit {code}, kept {kept()}/4"
        ok = code == 2 and kept() == 4
        if case.startswith("log"):
            code2, _, _ = _cli([*argv, str(d / "F"), "--duration", "0.2", "--overwrite"])
            ours = json.loads((d / "F.json").read_text()).get("log") == "F" if code2 == 0 else False
            measured += f"; --overwrite: exit {code2}, F.1 + F.2024 kept {kept()}/2"
            ok = ok and code2 == 0 and ours and kept() == 2
        rows.append(
            Row("a user's files", f"{case} (F, F.1, F.2024, F.json)", measured, "exit 2, all kept", ok)
        )
    return rows


def _campaign(d: Path, name: str = "own", samples: int = 4) -> Path:
    d.mkdir(parents=True, exist_ok=True)
    f = d / "c.yaml"
    base = PROJECT_ROOT / "scenarios" / "case1-loe.yaml"
    f.write_text(CAMPAIGN.format(name=json.dumps(name), base=base, samples=samples))
    return f


def _tampered(journal: Path, what: str) -> None:
    lines = journal.read_text().splitlines(keepends=True)
    rec = json.loads(lines[1])
    if what == "fault_class ../../..":
        rec["metrics"]["fault_class"] = "../../../../outside"
    elif what == "a metric missing":
        del rec["metrics"]["mmac.rms_error_m"]
    elif what == "a metric a string":
        rec["metrics"]["nrc.switches"] = "many"
    else:
        rec["index"] = 9999
    lines[1] = json.dumps(rec) + "\n"
    journal.write_text("".join(lines))


def campaign_rows(out: Path) -> list[Row]:
    """A user's files in ``--out``, a name that is a path, tampered and symlinked journals."""
    f = _campaign(out / "c")
    kept = _plant(out / "c" / "out", USER_CAMPAIGN)
    run = ["ehpss_hil.cli", "campaign", str(f), "--workers", "1", "--no-figures", "--out"]
    code, _, _ = _cli([*run, str(out / "c" / "out")])
    rows = [
        Row(
            "a user's files",
            "campaign --out DIR (summary.md/json, results.parquet, 2 PNGs)",
            f"exit {code}, kept {kept()}/5",
            "exit 2, all kept",
            code == 2 and kept() == 5,
        )
    ]
    evil = _campaign(out / "n" / "a" / "b", name="../../../../elsewhere")
    c1, _, _ = _cli(["ehpss_hil.cli", "check-config", str(evil)])
    c2, _, _ = _cli(["ehpss_hil.cli", "campaign", str(evil), "--workers", "1"])
    made = [p.name for p in (out / "n").rglob("*") if p.is_dir() and p.name not in ("a", "b")]
    rows.append(
        Row(
            "a path as campaign name",
            "name: ../../../../elsewhere",
            f"check-config exit {c1}, campaign exit {c2}, folders made {len(made)}",
            "exit 2, nothing written",
            c1 == c2 == 2 and not made,
        )
    )
    done = out / "c" / "done"
    _cli([*run, str(done)])
    for what in ("fault_class ../../..", "a metric missing", "a metric a string", "another index"):
        d = out / "t" / what.replace(" ", "_").replace("/", "").replace(".", "")
        shutil.copytree(done, d, symlinks=True)
        _tampered(d / "runs.jsonl", what)
        code, lines, _ = _cli([*run, str(d), "--resume"])
        journal = d / "runs.jsonl"
        rest = journal.read_text().splitlines(keepends=True)
        journal.write_text("".join(rest[:1] + rest[2:]))
        code2, _, _ = _cli([*run, str(d), "--resume"])
        rows.append(
            Row(
                "a tampered journal",
                what,
                f"exit {code} ({len(lines)} line(s)); line deleted, --resume: exit {code2}",
                "exit 2 + one line, then exit 0",
                code == 2 and len(lines) == 1 and code2 == 0,
            )
        )
    rows.append(_symlinked(done, out / "s", run))
    return rows


def _symlinked(done: Path, d: Path, run: list[str]) -> Row:
    shutil.copytree(done, d, symlinks=True)
    users = d.parent / "users.jsonl"
    users.write_bytes((d / "runs.jsonl").read_bytes())
    (d / "runs.jsonl").unlink()
    (d / "runs.jsonl").symlink_to(users)
    before = users.read_bytes()
    code, _, _ = _cli([*run, str(d), "--resume"])
    same = users.read_bytes() == before
    return Row(
        "a tampered journal",
        "runs.jsonl a symlink to a user's file",
        f"exit {code}, the user's file {'unchanged' if same else 'CHANGED'}",
        "exit 2, unchanged",
        code == 2 and same,
    )


def _vendor_config(d: Path, dbc_text: str) -> Path:
    d.mkdir(parents=True, exist_ok=True)
    (d / "vendor.dbc").write_text(dbc_text)
    cfg = (PROJECT_ROOT / "configs" / "controller-vendor.yaml").read_text()
    cfg = cfg.replace("dbc: ../dbc/vendor-example.dbc", f"dbc: {d / 'vendor.dbc'}")
    cfg = cfg.replace("params: params.yaml", f"params: {PROJECT_ROOT / 'configs' / 'params.yaml'}")
    cfg = cfg.replace("dbc: ../dbc/ehpss.dbc", f"dbc: {PROJECT_ROOT / 'dbc' / 'ehpss.dbc'}")
    (d / "controller.yaml").write_text(cfg)
    return d / "controller.yaml"


def dbc_rows(out: Path) -> list[Row]:
    """Each bad vendor DBC through check-config and the controller; a million-sample campaign."""
    text = (PROJECT_ROOT / "dbc" / "vendor-example.dbc").read_text()
    cases: list[tuple[str, str]] = [(case, text.replace(good, bad)) for case, good, bad in BAD_DBCS]
    cases.append((f"a {DBC_MB} MB DBC", text + "\n" * (DBC_MB * 2**20)))
    rows = []
    for i, (case, dbc) in enumerate(cases):
        cfg = _vendor_config(out / f"dbc{i}", dbc)
        code, lines, wall = _cli(["ehpss_hil.cli", "check-config", str(cfg)])
        ctrl = [
            "ehpss_hil.cli",
            "controller",
            "-c",
            str(cfg),
            "--interface",
            "socketcan",
            "--channel",
            "vcan99",
        ]
        code2, _, _ = _cli(ctrl)
        rows.append(
            Row(
                "a vendor DBC",
                case,
                f"check-config exit {code} ({len(lines)} line(s), {wall:.1f} s); controller exit {code2}",
                "exit 2 + one line; 2 before the bus (not 3)",
                code == 2 and len(lines) == 1 and code2 == 2,
            )
        )
    f = _campaign(out / "m", samples=1_000_000)
    code, _, wall = _cli(["ehpss_hil.cli", "check-config", str(f)], limit_kb=600_000)
    rows.append(
        Row(
            "check-config cost",
            "campaign samples: 1000000",
            f"exit {code} in {wall:.1f} s within 600 MB",
            "exit 0 within 600 MB",
            code == 0,
        )
    )
    return rows


def owned_rows(out: Path) -> tuple[list[Row], dict[str, Any]]:
    """Every row of this module (files under ``out``), and the raw rows for the JSON."""
    rows = [*log_rows(out / "logs"), *campaign_rows(out / "campaign"), *dbc_rows(out / "dbc")]
    return rows, {"owned": [r.__dict__ for r in rows]}
