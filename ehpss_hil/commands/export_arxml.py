"""``ehpss-hil export-arxml OUT.arxml [--dbc FILE]``: the DBC as an AUTOSAR 4 ARXML file that
cantools (and AUTOSAR tools) load: unique signal names, multiplexed PDUs, E2E DataIDs
(:mod:`ehpss_hil.protocol.arxml`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .. import DEFAULT_DBC
from ..protocol.arxml import export_arxml, export_names

NAME = "export-arxml"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", type=Path, help="the ARXML file to write")
    p.add_argument("--dbc", type=Path, default=DEFAULT_DBC, help="DBC file (default: the shipped ehpss.dbc)")


def run(args: argparse.Namespace) -> int:
    db = export_arxml(args.dbc, args.out)
    names = export_names(db)
    renamed = sorted(f"{m}.{s} → {n}" for (m, s), n in names.items() if n != s)
    print(f"wrote {args.out}: {len(db.messages)} messages, {len(names)} signals from {args.dbc}")
    if renamed:
        print(f"{len(renamed)} signals whose name occurs in several messages are named MESSAGE_signal there")
    return 0
