"""The identification reference: a periodic multisine x_d(t) (m) with bounded amplitude.

Around the PI loop (the nrc controller) the loop follows the low lines (the flow gain, spool →
position) while above the loop's bandwidth the current is ≈ K_a·K_p·K_f·x_d, so the high lines
drive the valve (current → spool) and the hydraulic resonance (the load pressure). Lines lie on
the period's frequency grid (an integer number of cycles per period: the measured frequency
response is an FFT over whole periods, no leakage) and get Schroeder phases (a low crest factor:
the peak stays near the RMS). The sum is scaled so that its peak is ``amplitude_m`` exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..schema import rng


@dataclass(frozen=True)
class Excitation:
    """The experiment's reference and limits (SI). Every limit is checked each sample; any one
    crossed ends the experiment in fail-safe (0 A) with a one-line reason."""

    #: peak of the multisine reference (m): the high lines must keep the spool off its stop
    #: (current ≈ 4.4 A/m·x_d above the loop bandwidth, spool ≈ 16.5 m/A·current)
    amplitude_m: float = field(default=50e-6, metadata=rng(1e-6, 1e-3))
    #: lowest and highest line (Hz); the highest stays below Nyquist
    f_min_hz: float = field(default=1.0, metadata=rng(0.1, 100.0))
    f_max_hz: float = field(default=450.0, metadata=rng(1.0, 5000.0))
    #: number of lines, log-spaced on the period's grid (duplicates on the grid merged)
    lines: int = field(default=60, metadata=rng(1, 1000))
    #: period of the multisine (s): its frequency grid is 1/period_s
    period_s: float = field(default=1.0, metadata=rng(0.01, 100.0))
    #: whole periods run; the first settles the loop, the others are measured
    periods: int = field(default=3, metadata=rng(2, 100))
    #: measured piston travel limit |y_s| (m)
    travel_limit_m: float = field(default=1e-3, metadata=rng(0.0, 0.5, lo_open=True))
    #: commanded coil current limit |I| (A)
    current_limit_a: float = field(default=5e-3, metadata=rng(0.0, 1.0, lo_open=True))
    #: measured spool limit |x_v| (m): at the stop the valve is no longer linear
    spool_limit_m: float = field(default=9e-3, metadata=rng(0.0, 0.01, lo_open=True))

    def frequencies_hz(self, ts_s: float) -> NDArray[np.float64]:
        """The lines (Hz): log-spaced from f_min to min(f_max, 0.9·Nyquist), on the 1/period grid."""
        df = 1.0 / self.period_s
        top = min(self.f_max_hz, 0.45 / ts_s)
        k = np.unique(np.round(np.geomspace(self.f_min_hz, top, self.lines) / df).astype(int))
        return k[k > 0] * df

    def reference(self, ts_s: float) -> NDArray[np.float64]:
        """x_d at every sample of the experiment (m): ``periods`` whole periods of the multisine."""
        f = self.frequencies_hz(ts_s)
        n_period = round(self.period_s / ts_s)
        t = np.arange(n_period) * ts_s
        m = len(f)
        phase = -np.pi * np.arange(m) * (np.arange(m) + 1) / m  # Schroeder
        one = np.sin(2.0 * np.pi * f[:, None] * t[None, :] + phase[:, None]).sum(axis=0)
        one *= self.amplitude_m / np.abs(one).max()
        return np.tile(one, self.periods)
