"""Hostile surroundings (issue #16): stray datagrams on the embedded bus, foreign files in a run
directory, a full disk under the logs. Real processes in a private network namespace; nothing
here is timed (waits have generous limits only so that a broken run fails)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ehpss_hil.reliability.procs import skip_reason
from ehpss_hil.reliability.stray import KINDS, stray_trial

SKIP = skip_reason()
needs_netns = pytest.mark.skipif(SKIP is not None, reason=str(SKIP))


@needs_netns
def test_stray_datagrams_are_counted_and_no_process_ends(tmp_path: Path) -> None:
    r = stray_trial(tmp_path, rounds=2, duration_s=1.5)
    assert not r.error, r.error
    assert r.sent == 2 * len(KINDS)
    assert r.alive == {"logger": True, "controller": True, "emulator": True}
    assert r.exits == {"emulator": 0, "controller": 0, "logger": 0}
    assert r.counted == dict.fromkeys(("controller", "emulator", "logger", "controller log"),
                                      r.sent)
    assert r.ok
