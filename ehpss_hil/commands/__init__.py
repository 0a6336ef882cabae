"""One module per ``ehpss-hil`` subcommand, each defining ``NAME``, ``add_arguments(parser)`` and
``run(args) -> int``. :data:`COMMANDS` names them with their one-line help, so that the CLI
imports only the module of the command asked for (``ehpss-hil --help`` imports none).
"""

from __future__ import annotations

from ..bench import BENCHES

#: subcommand → (module in this package, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "bench": (
        "bench",
        f"benchmarks: {', '.join(BENCHES)} (figures beside their targets; exit 1 when a target fails)",
    ),
    "bringup": (
        "bringup",
        "checks before the first enable: bit rate, node identity, sensor zero, spool/piston polarity",
    ),
    "campaign": (
        "campaign",
        "Monte-Carlo fault campaign (sampled faults × nrc/mmac/oracle) on local cores or a Dask cluster",
    ),
    "check-config": ("check_config", "validate controller/emulator/params configs and scenario files"),
    "controller": (
        "controller",
        "run the controller daemon (SIGTERM/SIGINT: zero current, flush log, exit 0)",
    ),
    "demo": (
        "demo",
        "the bench demo: case 3 (drift, then LOE), NRC vs MMAC on two real processes, metrics, figures",
    ),
    "export-arxml": (
        "export_arxml",
        "write the DBC as AUTOSAR 4 ARXML (unique signal names, multiplexed PDUs, E2E DataIDs)",
    ),
    "identify": (
        "identify",
        "identify the plant (bounded multisine around the PI, least-squares fit with intervals); "
        "write a params file",
    ),
    "log": ("log", "log every frame of a CAN bus to a candump -L file (+ JSON sidecar), rotated by size"),
    "monitor": (
        "monitor",
        "live bench monitor: decode the bus and show it in a local web page (or --tui); listen-only",
    ),
    "replay": (
        "replay",
        "feed a log's sensor frames through the controller offline; compare with its VALVE_CMDs",
    ),
    "report": (
        "report",
        "decode a CAN log (candump -L, .asc, .blf, …; + sidecar) into docs/design.md §10 metrics, "
        "PNG figures and report.md",
    ),
    "run": ("run", "run a scenario with firmware-sim and the controller as two processes on a real bus"),
    "sim": ("sim", "deterministic lockstep simulation of scenarios with one or more controllers"),
}
