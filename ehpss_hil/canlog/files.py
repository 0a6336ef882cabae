"""Opening a log's files safely: regular files only, a log read up to its size when the read
began, sidecars capped in size and depth.

A FIFO or a device given as a log (or found beside it as its sidecar) would block a reader for
ever or stream without end; it is refused with one line (:class:`LogError`, exit 2) before it is
opened for reading. A log still being written grows while it is read: each file of it is read up
to the size it had when it was opened, so a read always ends. A sidecar is JSON from another
program: larger than :data:`~ehpss_hil.limits.MAX_SIDECAR_BYTES` or nested deeper than
:data:`~ehpss_hil.limits.MAX_SIDECAR_DEPTH` it is refused with one line too.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path
from typing import Any, BinaryIO

from ..errors import ConfigError, EhpssError
from ..inputfile import read_capped
from ..limits import MAX_SIDECAR_BYTES, MAX_SIDECAR_DEPTH


class LogError(EhpssError, OSError):
    """A log file or directory cannot be found or read."""

    exit_code = 2


_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _refuse_unless_regular(path: Path, mode: int) -> None:
    if not stat.S_ISREG(mode):
        what = next((name for test, name in _KINDS if test(mode)), "not a regular file")
        raise LogError(f"{path}: {what}, not a log file (a log must be a regular file)")


def check_regular(path: str | os.PathLike[str]) -> Path:
    """``path`` when it is a regular file (``stat`` only: a FIFO is never opened); else a
    :class:`LogError` naming what it is."""
    p = Path(path)
    try:
        mode = os.stat(p).st_mode
    except OSError as exc:
        raise LogError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    _refuse_unless_regular(p, mode)
    return p


def open_log(path: str | os.PathLike[str]) -> tuple[BinaryIO, int]:
    """``(binary file, its size in bytes now)`` of the regular file ``path``, opened without
    blocking (a FIFO that appeared since :func:`check_regular` is refused too)."""
    p = Path(path)
    flags = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(p, flags)
    except OSError as exc:
        raise LogError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    try:
        st = os.fstat(fd)
        _refuse_unless_regular(p, st.st_mode)
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return os.fdopen(fd, "rb"), st.st_size


def json_depth(obj: Any) -> int:
    """Nesting depth of a JSON value (a scalar is 0), without recursion."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(obj, 0)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict):
            stack.extend((v, depth + 1) for v in value.values())
        elif isinstance(value, list):
            stack.extend((v, depth + 1) for v in value)
        else:
            continue
        deepest = max(deepest, depth + 1)
    return deepest


def read_json_capped(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The JSON object in ``path`` (a sidecar, ``run.json``), or None when there is none or it
    is no JSON object; a :class:`LogError` when it is no regular file, larger than
    :data:`~ehpss_hil.limits.MAX_SIDECAR_BYTES` or nested deeper than
    :data:`~ehpss_hil.limits.MAX_SIDECAR_DEPTH`."""
    p = Path(path)
    if not os.path.lexists(p):
        return None
    try:
        st = os.stat(p)
    except OSError:
        return None  # a dangling link: no sidecar
    if stat.S_ISREG(st.st_mode) and st.st_size > MAX_SIDECAR_BYTES:
        raise LogError(f"{p}: sidecar refused: {st.st_size} bytes, more than {MAX_SIDECAR_BYTES}")
    try:
        raw = read_capped(p, MAX_SIDECAR_BYTES)
    except ConfigError as exc:
        raise LogError(f"{p}: sidecar refused: {exc.reason}") from exc
    try:
        data = json.loads(raw)
    except RecursionError as exc:
        raise LogError(f"{p}: sidecar nested deeper than {MAX_SIDECAR_DEPTH} levels") from exc
    except ValueError:
        return None
    if json_depth(data) > MAX_SIDECAR_DEPTH:
        raise LogError(f"{p}: sidecar nested deeper than {MAX_SIDECAR_DEPTH} levels")
    return data if isinstance(data, dict) else None
