"""The identification report: each identified quantity with its 95 % interval (and, in
lockstep, the true value the scenario's ``plant:`` section set), and the measured vs fitted
frequency responses at the excitation's lines (``frf.csv``; ``frf.png`` with the ``plot``
extra), written to ``report.md`` in a directory."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..extras import missing
from ..physics.params import PlantParams
from .experiment import Record
from .fit import DERIVED, FitResult, simulate

Array = NDArray[np.complex128]

#: the frequency responses shown: name, numerator channel, denominator channel, unit
PATHS = (
    ("spool / current", 1, 3, "m/A"),
    ("position / spool", 0, 1, "m/m"),
    ("load pressure / current", 2, 3, "Pa/A"),
)


def truth_of(plant: PlantParams, name: str) -> float:
    """The value of key or derived quantity ``name`` (:data:`~.fit.DERIVED`) for a known plant."""
    if name in DERIVED:
        const, powers, _ = DERIVED[name]
        return const * math.prod(getattr(plant, k) ** a for k, a in powers.items())
    return float(getattr(plant, name))


def format_table(result: FitResult, truth: PlantParams | None = None) -> str:
    """The parameter table: value ± 95 % interval (relative), unit, and the true value and error
    when ``truth`` is known."""
    head = f"{'quantity':28s} {'identified':>12s} {'± 95 %':>8s}  {'unit':10s}"
    if truth is not None:
        head += f" {'true':>12s} {'error':>8s}"
    lines = [head, "-" * len(head)]
    for e in (*result.keys, *result.derived):
        row = f"{e.name:28s} {e.value:12.5g} {_pct(e.rel_ci95):>8s}  {e.unit:10s}"
        if truth is not None:
            t = truth_of(truth, e.name)
            row += f" {t:12.5g} {100 * (e.value / t - 1):+7.2f}%"
        lines.append(row)
    for e in (result.spool_null_offset_m, result.position_zero_m):
        lines.append(f"{e.name:28s} {e.value:12.3g} ±{e.rel_ci95:.2g} m (absolute)")
    rms = ", ".join(f"{k} {v:.3g}" for k, v in result.residual_rms.items())
    lines.append(f"residual RMS: {rms}; {result.evaluations} model evaluations")
    return "\n".join(lines)


def _pct(rel: float) -> str:
    return f"±{100 * rel:.2f}%" if np.isfinite(rel) and rel < 10 else "±large"


def frequency_responses(
    rec: Record, result: FitResult
) -> tuple[NDArray[np.float64], dict[str, tuple[Array, Array]]]:
    """Line frequencies (Hz) and, per :data:`PATHS`, the measured and fitted responses: ratios of
    the FFTs over the whole periods after the first (the loop settled), at the lines' bins."""
    n = rec.period_samples
    periods = len(rec.applied_a) // n
    meas = np.column_stack((rec.position_m, rec.spool_m, rec.load_pressure_pa, rec.applied_a))
    fitted = simulate(result.params.plant, rec.applied_a, rec.ts_s)
    fitted = np.column_stack((fitted, rec.applied_a))
    ref = np.abs(np.fft.rfft(rec.x_d_m[:n]))
    bins = np.nonzero(ref > 1e-3 * ref.max())[0]
    f = bins / (n * rec.ts_s)
    out: dict[str, tuple[Array, Array]] = {}
    for name, num, den, _ in PATHS:
        pair = []
        for sig in (meas, fitted):
            seg = np.nan_to_num(sig[n : periods * n]).reshape(periods - 1, n, 4)
            spec = np.fft.rfft(seg, axis=1).mean(axis=0)
            pair.append(spec[bins, num] / spec[bins, den])
        out[name] = (pair[0], pair[1])
    return f, out


def write_report(
    directory: Path, rec: Record, result: FitResult, truth: PlantParams | None, source: str
) -> list[Path]:
    """Write report.md, frf.csv and (with matplotlib) frf.png into ``directory``; returns them."""
    directory.mkdir(parents=True, exist_ok=True)
    f, frf = frequency_responses(rec, result)
    csv = directory / "frf.csv"
    cols = ["f_hz"] + [
        f"{n} {k} {part}" for n, _, _, _ in PATHS for k in ("measured", "fitted") for part in ("abs", "deg")
    ]
    rows = [f]
    for name, _, _, _ in PATHS:
        for h in frf[name]:
            rows += [np.abs(h), np.degrees(np.angle(h))]
    np.savetxt(csv, np.column_stack(rows), delimiter=",", header=",".join(cols), comments="", fmt="%.6g")
    written = [csv]
    md = directory / "report.md"
    err = {name: float(np.median(np.abs(h_f / h_m - 1))) for name, (h_m, h_f) in frf.items()}
    text = [
        f"# Plant identification: {source}",
        "",
        "```",
        format_table(result, truth),
        "```",
        "",
        "Fitted vs measured frequency response (median relative difference over the lines): "
        + ", ".join(f"{k} {100 * v:.1f} %" for k, v in err.items()),
        "",
    ]
    if not missing(("matplotlib",)):
        png = directory / "frf.png"
        _plot(png, f, frf)
        written.append(png)
        text.append("![measured vs fitted frequency response](frf.png)")
    md.write_text("\n".join(text) + "\n")
    return [md, *written]


def _plot(path: Path, f: NDArray[np.float64], frf: dict[str, tuple[Array, Array]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(PATHS), figsize=(13, 6), sharex=True)
    for j, (name, _, _, unit) in enumerate(PATHS):
        h_m, h_f = frf[name]
        axes[0, j].loglog(f, np.abs(h_m), "o", ms=3, label="measured")
        axes[0, j].loglog(f, np.abs(h_f), "-", label="fitted")
        axes[0, j].set_title(f"{name} ({unit})")
        axes[1, j].semilogx(f, np.degrees(np.unwrap(np.angle(h_m))), "o", ms=3)
        axes[1, j].semilogx(f, np.degrees(np.unwrap(np.angle(h_f))), "-")
        axes[1, j].set_xlabel("frequency (Hz)")
    axes[0, 0].legend()
    axes[1, 0].set_ylabel("phase (deg)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
