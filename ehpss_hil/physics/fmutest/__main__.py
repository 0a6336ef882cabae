"""``python -m ehpss_hil.physics.fmutest DIR``: build the test FMU into DIR and print its path
and its ``fmu_map`` (docs/fmu.md's worked example)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ...errors import run_console
from . import TEST_FMU_MAP, build_test_fmu


def main(argv: list[str]) -> int:
    """Build into ``argv[0]`` (default: the current folder); 0 on success."""
    fmu = build_test_fmu(Path(argv[0] if argv else "."))
    print(fmu)
    print("fmu_map: " + json.dumps(TEST_FMU_MAP))
    return 0


if __name__ == "__main__":
    sys.exit(run_console("fmutest", lambda: main(sys.argv[1:])))
