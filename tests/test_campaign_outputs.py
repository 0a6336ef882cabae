"""A campaign never overwrites a user's file or writes outside ``--out`` (issue #29, item 3): a
user's files at its names are refused unless ``--overwrite``, a campaign name is a folder name,
journal contents never become paths, a tampered journal is one line and exit 2 and resumes once
the bad line is gone, a symlinked journal is refused; check-config is O(1) in ``samples``."""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import pytest
from _proc import EHPSS_HIL, ENV, ROOT

from ehpss_hil.campaign.journal import JOURNAL_NAME, MAX_RECORD_BYTES
from ehpss_hil.campaign.session import run_campaign
from ehpss_hil.campaign.spec import load_campaign
from ehpss_hil.errors import ConfigError, OutputError
from ehpss_hil.outputs import MANIFEST
from ehpss_hil.rundir import prepare_run_dir

SAMPLES = 4
TINY = """\
name: {name}
base: {base}
samples: {samples}
sampler: sobol
seed: 5
duration_s: 0.3
faults:
  count: [1, 1]
  onset_s: [0.05, 0.2]
  kinds: {{loe: {{}}, drift: {{}}}}
"""
#: the user's files at the campaign's names (the tester's row) and one elsewhere in the folder
USER_FILES = {
    "summary.md": "# my summary\n",
    "summary.json": '{"mine": true}\n',
    "results.parquet": "not parquet\n",
    "coverage-onset.png": "my png\n",
    "distributions.png": "my other png\n",
    "notes.txt": "keep me\n",
}


def _tiny(path: Path, name: str = "tiny", samples: int = SAMPLES) -> Path:
    path.write_text(TINY.format(name=name, base=ROOT / "scenarios" / "case1-loe.yaml", samples=samples))
    return path


def _cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*EHPSS_HIL, *args], cwd=cwd, env=ENV, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The tiny campaign file and a folder it finished in (copy it before changing it)."""
    d = tmp_path_factory.mktemp("camp")
    f = _tiny(d / "tiny.yaml")
    run_campaign(load_campaign(f), d / "done", workers=1, figures=False)
    return f, d / "done"


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst, symlinks=True)
    return dst / JOURNAL_NAME


def test_a_users_files_are_refused_then_only_our_names_replaced(tmp_path: Path) -> None:
    f = _tiny(tmp_path / "tiny.yaml")
    out = tmp_path / "out"
    out.mkdir()
    for name, text in USER_FILES.items():
        (out / name).write_text(text)
    r = _cli("campaign", str(f), "--workers", "1", "--out", str(out))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--overwrite" in r.stderr, r.stderr
    assert {p.name: p.read_text() for p in out.iterdir()} == USER_FILES
    r = _cli("campaign", str(f), "--workers", "1", "--out", str(out), "--overwrite", "--no-figures")
    assert r.returncode == 0, r.stderr
    assert (out / "notes.txt").read_text() == USER_FILES["notes.txt"]
    assert (out / "summary.md").read_text().startswith("# Campaign tiny")
    assert json.loads((out / "summary.json").read_text())["classes"]
    # the user's PNGs were not written over (no figures this time) and stay
    assert (out / "coverage-onset.png").read_text() == USER_FILES["coverage-onset.png"]
    # a run of ours in the folder now: --resume needs no --overwrite
    r = _cli("campaign", str(f), "--workers", "1", "--out", str(out), "--resume", "--no-figures")
    assert r.returncode == 0 and f"0 run(s) done, {SAMPLES} skipped" in r.stdout, r.stderr


def test_a_user_file_in_the_worst_folder_is_refused(finished: tuple[Path, Path], tmp_path: Path) -> None:
    f, _done = finished
    out = tmp_path / "out"
    out.mkdir()
    (out / "worst" / "all").mkdir(parents=True)
    (out / "worst" / "all" / "1-run00000.yaml").write_text("mine\n")
    with pytest.raises(OutputError, match=r"1-run00000\.yaml"):
        run_campaign(load_campaign(f), out, workers=1, figures=False)
    assert (out / "worst" / "all" / "1-run00000.yaml").read_text() == "mine\n"
    assert sorted(p.name for p in out.iterdir()) == ["worst"]


def test_a_run_directory_is_not_taken_over(finished: tuple[Path, Path], tmp_path: Path) -> None:
    """``run --out``'s manifest is another tool's: the campaign refuses to replace it."""
    f, _done = finished
    out = tmp_path / "run"
    prepare_run_dir(out)
    before = (out / MANIFEST).read_bytes()
    with pytest.raises(OutputError, match=re.escape(MANIFEST)):
        run_campaign(load_campaign(f), out, workers=1, figures=False)
    assert (out / MANIFEST).read_bytes() == before and sorted(p.name for p in out.iterdir()) == [MANIFEST]


@pytest.mark.parametrize("name", ["../../../../elsewhere", "a/b", ".hidden", "x" * 65])
def test_a_campaign_name_is_a_folder_name(tmp_path: Path, name: str) -> None:
    (tmp_path / "c").mkdir()
    f = _tiny(tmp_path / "c" / "tiny.yaml", name=json.dumps(name))
    with pytest.raises(ConfigError) as exc:
        load_campaign(f)
    assert exc.value.key_path == "name"
    r = _cli("check-config", str(f), cwd=tmp_path / "c")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and ": name: " in r.stderr, r.stderr
    r = _cli("campaign", str(f), "--workers", "1", cwd=tmp_path / "c")
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["c", "tiny.yaml"]


def _tamper(journal: Path, change: object) -> int:
    """Apply ``change`` to the record on the journal's second line; returns its line number."""
    lines = journal.read_text().splitlines(keepends=True)
    rec = json.loads(lines[1])
    if callable(change):
        change(rec)
    lines[1] = json.dumps(rec) + "\n"
    journal.write_text("".join(lines))
    return 2


def _fault_class(rec: dict[str, object]) -> None:
    rec["metrics"]["fault_class"] = "../../../../outside"  # type: ignore[index]


def _missing(rec: dict[str, object]) -> None:
    del rec["metrics"]["mmac.rms_error_m"]  # type: ignore[attr-defined]


def _string(rec: dict[str, object]) -> None:
    rec["metrics"]["nrc.switches"] = "many"  # type: ignore[index]


def _index(rec: dict[str, object]) -> None:
    rec["index"] = 9999


@pytest.mark.parametrize("change", [_fault_class, _missing, _string, _index], ids=lambda c: c.__name__)
def test_a_tampered_journal_is_one_line_and_resumes_without_the_line(
    finished: tuple[Path, Path], tmp_path: Path, change: object
) -> None:
    f, done = finished
    out = tmp_path / "deep" / "er" / "out"
    journal = _copy(done, out)
    line = _tamper(journal, change)
    r = _cli("campaign", str(f), "--workers", "1", "--out", str(out), "--resume", "--no-figures")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    assert f"line {line}:" in r.stderr and "delete the line" in r.stderr
    assert not any(p.suffix == ".yaml" for p in tmp_path.rglob("*") if out not in p.parents)
    lines = journal.read_text().splitlines(keepends=True)
    journal.write_text("".join(lines[:1] + lines[2:]))  # the user drops the bad line
    r = _cli("campaign", str(f), "--workers", "1", "--out", str(out), "--resume", "--no-figures")
    assert r.returncode == 0 and "1 run(s) done" in r.stdout, r.stderr
    assert f"{SAMPLES - 1} skipped" in r.stdout


def test_a_line_longer_than_any_record_is_refused_unbuffered(
    finished: tuple[Path, Path], tmp_path: Path
) -> None:
    f, done = finished
    journal = _copy(done, tmp_path / "out")
    with open(journal, "ab") as fh:
        fh.write(b'{"run_hash": "' + b"a" * (4 * MAX_RECORD_BYTES) + b'"}\n')
    with pytest.raises(OutputError, match=f"line {SAMPLES + 1}: longer than"):
        run_campaign(load_campaign(f), tmp_path / "out", resume=True, figures=False)


def test_a_symlinked_journal_is_refused(finished: tuple[Path, Path], tmp_path: Path) -> None:
    f, done = finished
    journal = _copy(done, tmp_path / "out")
    users = tmp_path / "users.jsonl"
    users.write_bytes(journal.read_bytes())
    journal.unlink()
    journal.symlink_to(users)
    before = users.read_bytes()
    r = _cli("campaign", str(f), "--workers", "1", "--out", str(tmp_path / "out"), "--resume", "--no-figures")
    assert r.returncode == 2 and "symlink" in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert users.read_bytes() == before


def test_check_config_does_not_plan_every_run(tmp_path: Path) -> None:
    """A million samples, check-config under a 600 MB address space: it builds a few runs only
    (planning all of them took 2.9 GB)."""
    f = _tiny(tmp_path / "big.yaml", samples=1_000_000)
    cmd = f"ulimit -v 600000 && exec {shlex.join([*EHPSS_HIL, 'check-config', str(f)])}"
    r = subprocess.run(["bash", "-c", cmd], cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and "campaign tiny: 1000000 runs" in r.stdout, r.stderr
