"""Private network namespaces for the embedded ``udp_multicast`` bus (docs/design.md §8).

Inside ``unshare --net`` only a loopback device exists; with ``ip link set lo up`` and
``ip route add 224.0.0.0/4 dev lo`` multicast works between the processes of that namespace and
cannot reach any other host or process. Two ways to use it:

- :func:`netns_prefix` — an argv prefix that runs *one* command in a fresh namespace (that
  command may start several processes, which then share the namespace);
- :class:`PrivateNetns` — a namespace kept alive by a holder process; :meth:`PrivateNetns.prefix`
  (``nsenter --net=/proc/PID/ns/net --``) runs any number of separately started processes in it.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
from types import TracebackType

#: shell commands that make multicast work on the namespace's loopback
SETUP_SH = "ip link set lo up && ip route add 224.0.0.0/4 dev lo"


@functools.cache
def netns_unavailable_reason() -> str | None:
    """None when a private network namespace can be made here, else why not (for skips)."""
    if os.geteuid() != 0:
        return "private network namespaces need root (unshare --net)"
    for tool in ("unshare", "ip", "nsenter"):
        if shutil.which(tool) is None:
            return f"'{tool}' not found"
    try:
        r = subprocess.run(
            ["unshare", "--net", "--", "sh", "-c", SETUP_SH], capture_output=True, text=True, timeout=10
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"unshare --net failed: {exc}"
    if r.returncode != 0:
        return f"unshare --net failed: {r.stderr.strip() or r.returncode}"
    return None


def can_make_netns() -> bool:
    """True when root and ``unshare --net`` with the multicast route work here."""
    return netns_unavailable_reason() is None


def netns_prefix() -> list[str]:
    """argv prefix: run the following command in a fresh namespace with lo up and the route."""
    return ["unshare", "--net", "--", "sh", "-c", f'{SETUP_SH} && exec "$@"', "ehpss-netns"]


class PrivateNetns:
    """A private network namespace held open by a sleeping holder process (context manager)."""

    def __init__(self) -> None:
        self._holder: subprocess.Popen[str] | None = None

    def start(self) -> PrivateNetns:
        """Create the namespace; raises OSError when it cannot be made."""
        reason = netns_unavailable_reason()
        if reason is not None:
            raise OSError(reason)
        self._holder = subprocess.Popen(
            ["unshare", "--net", "--", "sh", "-c", f"{SETUP_SH} && echo ready && exec cat"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self._holder.stdout is not None
        line = self._holder.stdout.readline().strip()
        if line != "ready":
            self.close()
            raise OSError("private network namespace setup failed")
        return self

    @property
    def pid(self) -> int:
        """PID of the holder process (its /proc/PID/ns/net is the namespace)."""
        if self._holder is None:
            raise RuntimeError("namespace not started")
        return self._holder.pid

    def prefix(self) -> list[str]:
        """argv prefix that runs a command inside this namespace (nsenter execs it: same PID)."""
        return ["nsenter", f"--net=/proc/{self.pid}/ns/net", "--"]

    def close(self) -> None:
        """End the holder (closing its stdin); the namespace goes when its last process exits."""
        if self._holder is None:
            return
        if self._holder.stdin is not None:
            self._holder.stdin.close()
        try:
            self._holder.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self._holder.kill()
            self._holder.wait()
        if self._holder.stdout is not None:
            self._holder.stdout.close()
        self._holder = None

    def __enter__(self) -> PrivateNetns:
        return self.start()

    def __exit__(
        self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()


#: Linux ``CLONE_NEWNET`` (``setns`` namespace type)
_CLONE_NEWNET = 0x40000000


def enter_netns(path: str) -> None:
    """Move the **calling thread** into the network namespace at ``path`` (``/proc/PID/ns/net``).

    Sockets opened by this thread afterwards belong to that namespace; sockets opened before, and
    the other threads, stay where they were (the monitor keeps its web server on the host's
    loopback and listens to a run's private bus). Needs CAP_SYS_ADMIN (root). Raises OSError.
    """
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        if libc.setns(fd, _CLONE_NEWNET) != 0:
            err = ctypes.get_errno()
            raise OSError(err, f"setns({path}): {os.strerror(err)}")
    finally:
        os.close(fd)
