"""The config's ``bus.bitrate`` against the bit rate the interface runs at, where it says.

A CAN controller set to another bit rate than the valve's sees only error frames, so the
controller checks before it opens the bus (and ``ehpss-hil bringup`` reports it):

* ``socketcan`` on a real CAN controller (``can0``): the kernel's bit timing, read from
  iproute2's ``ip -details -json link show dev CH`` (``linkinfo.info_data.bittiming.bitrate``,
  the netlink attribute IFLA_CAN_BITTIMING; sysfs has no bit-rate file). A different rate is a
  :class:`~ehpss_hil.errors.ConfigError` naming ``bus.bitrate`` (exit 2).
* ``socketcan`` on ``vcan`` (no bit timing), ``udp_multicast`` and ``virtual``: there is no
  bit rate to read; the check says so (``not exposed``) and the controller carries on — the
  config's ``bitrate`` then only feeds the bus budget (``bench bus``). So does an interface
  whose bit timing cannot be read (no ``ip`` program, an interface that does not exist yet:
  opening the bus then fails with its own error, exit 3).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from typing import Any

from ..config import BusConfig
from ..errors import ConfigError

#: how long ``ip`` may take to answer (s)
IP_TIMEOUT_S = 5.0


def parse_ip_link(text: str) -> int | None:
    """The bit rate (bit/s) in the output of ``ip -details -json link show dev CH`` (None: the
    link has no CAN bit timing, e.g. vcan, or the text is not iproute2's JSON)."""
    try:
        links: Any = json.loads(text)
    except ValueError:
        return None
    if not isinstance(links, list) or not links or not isinstance(links[0], dict):
        return None
    info = links[0].get("linkinfo") or {}
    timing = (info.get("info_data") or {}).get("bittiming") or {}
    rate = timing.get("bitrate")
    return int(rate) if isinstance(rate, int) and rate > 0 else None


def interface_bitrate(cfg: BusConfig) -> int | None:
    """The bit rate ``cfg``'s interface runs at (bit/s), None where it exposes none (module
    docstring)."""
    ip = shutil.which("ip")
    if cfg.interface != "socketcan" or ip is None:
        return None
    try:
        out = subprocess.run(
            [ip, "-details", "-json", "link", "show", "dev", cfg.channel],
            capture_output=True,
            text=True,
            timeout=IP_TIMEOUT_S,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return parse_ip_link(out.stdout) if out.returncode == 0 else None


#: how a note ends when the interface exposes no bit rate to check against
BITRATE_UNCHECKED = "not checked"


def check_bitrate(cfg: BusConfig, src: str, actual: int | None = None) -> str:
    """``cfg.bitrate`` against the interface's (``actual``, read when None): a one-line note
    when they agree or the interface exposes none, a ConfigError naming ``bus.bitrate`` when
    they differ."""
    rate = actual if actual is not None else interface_bitrate(cfg)
    where = f"{cfg.interface}:{cfg.channel}"
    if rate is None:
        return f"bit rate: {where} exposes none; bus.bitrate {cfg.bitrate} {BITRATE_UNCHECKED}"
    if rate != cfg.bitrate:
        raise ConfigError(
            src,
            "bus.bitrate",
            f"{cfg.bitrate} bit/s, but {cfg.channel} runs at {rate} bit/s (ip -details link show "
            f"{cfg.channel}); set the interface or the config to the valve's bit rate",
        )
    return f"bit rate: {where} runs at {rate} bit/s as configured"
