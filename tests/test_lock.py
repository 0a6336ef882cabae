"""The lock files (requirements/*.lock, made by ``make lock`` with uv) pin what pyproject.toml asks
for, with hashes, and the environment the tests run in was installed from them: an install does
not drift when numpy, scipy or cantools release (a release enters only by ``make lock``)."""

from __future__ import annotations

import re
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parent.parent
DEV_LOCK = ROOT / "requirements" / "dev.lock"
BASE_LOCK = ROOT / "requirements" / "base.lock"
_PIN = re.compile(r"^([A-Za-z0-9_.\-]+)==([^\s;\\]+)")


def _lock(path: Path) -> dict[str, tuple[Version, int]]:
    """Package → (pinned version, number of hashes) of one lock file."""
    out: dict[str, tuple[Version, int]] = {}
    name = ""
    for line in path.read_text().splitlines():
        m = _PIN.match(line)
        if m:
            name = canonicalize_name(m.group(1))
            assert name not in out, f"{path.name}: {name} pinned twice"
            out[name] = (Version(m.group(2)), 0)
        elif line.strip().startswith("--hash=sha256:") and name:
            v, n = out[name]
            out[name] = (v, n + 1)
    return out


def _make_extras() -> list[str]:
    """The extras ``make`` installs (the Makefile's EXTRAS)."""
    m = re.search(r"^EXTRAS := (.+)$", (ROOT / "Makefile").read_text(), re.M)
    assert m, "Makefile has no EXTRAS line"
    return m.group(1).split()


def _project() -> dict[str, list[str]]:
    proj = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return {"": proj["dependencies"], **proj["optional-dependencies"]}


@pytest.mark.parametrize("path", [DEV_LOCK, BASE_LOCK], ids=lambda p: p.name)
def test_every_pin_is_exact_and_hashed(path: Path) -> None:
    pins = _lock(path)
    assert len(pins) > 10
    unhashed = [n for n, (_, h) in pins.items() if h == 0]
    assert not unhashed, f"{path.name}: no hash for {unhashed}"


def test_the_locks_satisfy_pyproject_and_agree() -> None:
    dev, base = _lock(DEV_LOCK), _lock(BASE_LOCK)
    deps = _project()
    wanted = [("", r) for r in deps[""]] + [(e, r) for e in _make_extras() for r in deps[e]]
    for extra, text in wanted:
        req = Requirement(text)
        locks = (dev,) if extra else (dev, base)
        for lock in locks:
            got = lock.get(canonicalize_name(req.name))
            assert got is not None, f"{req.name} ({extra or 'base'}) is not in the lock: run make lock"
            assert req.specifier.contains(got[0], prereleases=True), (
                f"{req.name} {got[0]} in the lock does not satisfy {req}: run make lock"
            )
    differ = {n: (str(v), str(dev[n][0])) for n, (v, _) in base.items() if dev.get(n, (None,))[0] != v}
    assert not differ, f"base.lock and dev.lock pin different versions: {differ}"


def test_this_environment_was_installed_from_the_lock() -> None:
    """What the tests run on is what the lock says (make builds .venv from it)."""
    wrong = {}
    for name, (version, _) in _lock(DEV_LOCK).items():
        try:
            have = Version(metadata.version(name))
        except metadata.PackageNotFoundError:
            wrong[name] = (str(version), "missing")
            continue
        if have != version:
            wrong[name] = (str(version), str(have))
    assert not wrong, f"installed versions differ from requirements/dev.lock (locked, installed): {wrong}"
