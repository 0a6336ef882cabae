"""Reading input files safely: regular files only, size and time caps, a strict YAML loader.

:func:`read_capped` opens without blocking (a FIFO or device is refused, not waited on), reads at
most a cap of bytes and refuses more. :func:`parse_yaml` is PyYAML's safe loader with YAML 1.2
floats that also refuses aliases (``*name``: no shipped file uses them, and an alias bomb of a few
hundred bytes expands to gigabytes), nesting deeper than :data:`~ehpss_hil.limits.MAX_YAML_DEPTH`,
more than :data:`~ehpss_hil.limits.MAX_YAML_NODES` nodes and parsing beyond
:data:`~ehpss_hil.limits.MAX_PARSE_S`. Every failure is a one-line
:class:`~ehpss_hil.errors.ConfigError` naming the file.
"""

from __future__ import annotations

import os
import re
import stat
import time
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError
from .limits import MAX_PARSE_S, MAX_YAML_BYTES, MAX_YAML_DEPTH, MAX_YAML_NODES

_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a device"),
    (stat.S_ISBLK, "a device"),
    (stat.S_ISSOCK, "a socket"),
)


def read_capped(path: str | Path, max_bytes: int, key: str = "") -> bytes:
    """The bytes of the regular file ``path`` (at most ``max_bytes``).

    Raises ConfigError (source ``path``, key path ``key``) for a missing/unreadable file, anything
    that is no regular file (FIFO, device, socket, directory: never blocks on one) or a file
    larger than ``max_bytes``.
    """
    src = str(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise ConfigError(src, key, f"cannot read file ({exc.strerror or exc})") from exc
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            what = next((name for test, name in _KINDS if test(mode)), "not a regular file")
            raise ConfigError(src, key, f"cannot read file ({what}; a regular file is needed)")
        chunks: list[bytes] = []
        size = 0
        while size <= max_bytes:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise ConfigError(src, key, f"cannot read file ({exc.strerror or exc})") from exc
    finally:
        os.close(fd)
    if size > max_bytes:
        raise ConfigError(src, key, f"file larger than {max_bytes} bytes")
    return b"".join(chunks)


def decode_text(data: bytes, src: str, key: str = "") -> str:
    """``data`` as UTF-8 text (a leading BOM dropped); else ConfigError naming line and column."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise ConfigError(
            src, key, f"not UTF-8 text: byte 0x{data[exc.start]:02X} at line {line}, column {col}"
        ) from exc
    return text.removeprefix("\ufeff")


class _Loader(yaml.SafeLoader):
    """SafeLoader that reads ``1e7`` / ``3.136e7`` as floats (YAML 1.2 style), refuses aliases
    and bounds nesting depth, node count and parse time."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0
        self._deadline = time.monotonic() + MAX_PARSE_S

    def compose_node(self, parent: Any, index: Any) -> Any:
        """Compose one node within the bounds (see the class docstring)."""
        mark = self.peek_event().start_mark
        if self.check_event(yaml.AliasEvent):
            raise yaml.composer.ComposerError(
                None, None, "aliases (*name) are not accepted in these files", mark
            )
        self._nodes += 1
        if self._nodes > MAX_YAML_NODES:
            raise yaml.composer.ComposerError(None, None, f"more than {MAX_YAML_NODES} values", mark)
        if self._nodes % 1024 == 0 and time.monotonic() > self._deadline:
            raise yaml.composer.ComposerError(None, None, f"parsing took longer than {MAX_PARSE_S:g} s", mark)
        if self._depth >= MAX_YAML_DEPTH:
            raise yaml.composer.ComposerError(None, None, f"nested deeper than {MAX_YAML_DEPTH} levels", mark)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""",
        re.VERBOSE,
    ),
    list("-+0123456789."),
)


def _where(exc: yaml.YAMLError, text: str) -> str:
    """`` at line L, column C`` of a YAML error, when it tells."""
    mark = getattr(exc, "problem_mark", None)
    if mark is not None:
        return f" at line {mark.line + 1}, column {mark.column + 1}"
    pos = getattr(exc, "position", None)  # ReaderError: a character index into the text
    if isinstance(pos, int):
        line = text.count("\n", 0, pos) + 1
        return f" at line {line}, column {pos - (text.rfind(chr(10), 0, pos) + 1) + 1}"
    return ""


def _problem(exc: yaml.YAMLError) -> str:
    if isinstance(exc, yaml.reader.ReaderError):
        return f"unacceptable character #x{exc.character:04X}"
    return str(getattr(exc, "problem", None) or type(exc).__name__)


def parse_yaml(text: str, source: str = "") -> Any:
    """Parse YAML text within the bounds above; any failure becomes ConfigError."""
    try:
        return yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as exc:
        raise ConfigError(source, "", f"invalid YAML{_where(exc, text)}: {_problem(exc)}") from exc
    except (ValueError, OverflowError, TypeError, RecursionError) as exc:
        # a scalar a constructor cannot take (an integer of 5000 digits, a date 2024-13-45)
        raise ConfigError(source, "", f"invalid YAML value: {exc}") from exc


def load_yaml(path: str | Path) -> Any:
    """Parse the YAML file ``path`` (read once, capped: see :func:`read_capped`)."""
    src = str(path)
    return parse_yaml(decode_text(read_capped(path, MAX_YAML_BYTES), src), src)
