"""``python -m ehpss_hil.physics.fmutest DIR [--fmi 3]``: build the test FMU (FMI 2.0 by default,
FMI 3.0 with ``--fmi 3``) into DIR and print its path and its ``fmu_map`` (docs/fmu.md's worked
example)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ...errors import run_console
from . import TEST_FMU_MAP, build_test_fmu


def main(argv: list[str]) -> int:
    """Build into the folder argument (default: the current folder); 0 on success."""
    parser = argparse.ArgumentParser(prog="python -m ehpss_hil.physics.fmutest")
    parser.add_argument("dest", nargs="?", default=".", help="folder to write the .fmu into")
    parser.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI major version (default 2)")
    args = parser.parse_args(argv)
    fmu = build_test_fmu(Path(args.dest), fmi_version=args.fmi)
    print(fmu)
    print("fmu_map: " + json.dumps(TEST_FMU_MAP))
    return 0


if __name__ == "__main__":
    sys.exit(run_console("fmutest", lambda: main(sys.argv[1:])))
