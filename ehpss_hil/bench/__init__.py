"""Benchmarks, one module per ``ehpss-hil bench KIND`` (NAME, HELP, add_arguments, run).

:data:`BENCHES` is the one list of them: ``ehpss-hil --help`` and ``bench --help`` are built
from it (this package imports nothing, so the top-level help stays cheap), and a test checks
that it names exactly the modules here that define a benchmark.
"""

#: every ``ehpss-hil bench`` sub-command, each the module ``ehpss_hil/bench/<name>.py``
BENCHES: tuple[str, ...] = (
    "bus",
    "campaign",
    "codec",
    "control",
    "faults",
    "fmu",
    "identify",
    "loop",
    "monitor",
    "plant",
    "resolution",
    "soak",
)
