"""The host figures of ``bench loop``: /proc/stat's aggregate cpu line and the steal fraction."""

from __future__ import annotations

import pytest

from ehpss_hil.runtime.hoststeal import cpu_times, steal_fraction

STAT_A = "cpu  1000 0 200 5000 10 0 30 40 0 0\ncpu0 500 0 100 2500 5 0 15 20 0 0\nintr 1\n"
STAT_B = "cpu  1300 5 260 5600 10 0 35 140 77 0\ncpu0 650 0 130 2800 5 0 17 70 0 0\nintr 2\n"


def test_cpu_times_reads_the_aggregate_line() -> None:
    assert cpu_times(STAT_A) == (1000, 0, 200, 5000, 10, 0, 30, 40, 0, 0)
    assert cpu_times("cpu0 1 2 3 4 5 6 7 8\n") is None  # no aggregate line
    assert cpu_times("cpu  1 2 3 4 5 6 7\n") is None  # no steal column
    assert cpu_times("cpu  1 2 x 4 5 6 7 8\n") is None


def test_steal_fraction_is_steal_over_the_time_the_vm_wanted_a_cpu() -> None:
    a, b = cpu_times(STAT_A), cpu_times(STAT_B)
    # deltas: user 300, nice 5, system 60, idle 600, iowait 0, irq 0, softirq 5, steal 100
    # (idle is not wanted time; guest 77 is inside user already and does not count twice)
    assert steal_fraction(a, b) == pytest.approx(100 / 470)
    assert steal_fraction(a, a) is None
    assert steal_fraction(None, b) is None


def test_this_host_has_a_cpu_line_or_none() -> None:
    t = cpu_times()
    assert t is None or (len(t) >= 8 and all(x >= 0 for x in t))
