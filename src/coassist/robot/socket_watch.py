"""Whether a TCP connection another library owns has ended, asked of the kernel without touching it.

ur-rtde keeps its sockets to itself, and a call into it on a connection that has ended starts a
teardown that can race with its own receive thread's (:mod:`coassist.robot.ur_rtde_world`,
*Link loss*). The kernel knows sooner than either: a reset (RST) or an end of stream (FIN) from the
peer marks the socket at once. :class:`SocketWatch` asks ``poll(2)`` with a zero timeout for the
events that say so, and for no others: it reads nothing, writes nothing and never closes the
descriptor, which stays the library's.

- RST: ``POLLERR | POLLHUP``; FIN: ``POLLRDHUP`` (Linux); the descriptor closed: ``POLLNVAL``.
- The descriptor is found by its number: :func:`socket_fds` before and after the library connects
  (``/proc/self/fd``, Linux), :func:`sockets_to` keeps the new ones whose peer is on a given port.
  Where there is no ``/proc`` nothing is found and the caller goes without a watch.

Once the library closes the descriptor, its number may be handed to a later socket, and ``poll(2)``
then answers for that one: ur-rtde reconnects by itself after a reset, and its new connection took the
old one's number within 3–10 ms on ``coassist ur-sim`` (measured), so a loop asking once a period
(8 ms) missed the reset about half the time and sent its next command into a connection whose
control script had ended with the old one. A watch therefore also compares the descriptor's
(device, inode) with the socket's it was made for (``fstat(2)``, read-only): another socket under
the number is an ended connection. A watch says "ended" once and the caller stops there.
"""

from __future__ import annotations

import os
import select
import socket

__all__ = ["ENDED", "SocketWatch", "socket_fds", "sockets_to"]

#: poll(2) events that say a connection has ended (POLLRDHUP is Linux's; 0 elsewhere).
ENDED = select.POLLERR | select.POLLHUP | select.POLLNVAL | getattr(select, "POLLRDHUP", 0)
_FD_DIR = "/proc/self/fd"


def socket_fds() -> set[int]:
    """This process's open socket descriptors (from ``/proc/self/fd``; empty where it does not exist)."""
    try:
        names = os.listdir(_FD_DIR)
    except OSError:
        return set()
    out = set()
    for name in names:
        try:
            if os.readlink(f"{_FD_DIR}/{name}").startswith("socket:"):
                out.add(int(name))
        except (OSError, ValueError):  # closed meanwhile, or not a number
            continue
    return out


def _peer_port(fd: int) -> int | None:
    """The remote port of the connected IP socket ``fd`` (borrowed: never closed), else None."""
    try:
        sock = socket.socket(fileno=fd)
    except OSError:
        return None
    try:
        peer = sock.getpeername()
    except OSError:  # not connected
        return None
    finally:
        sock.detach()  # the descriptor is the library's: give it back unclosed
    return peer[1] if isinstance(peer, tuple) and len(peer) >= 2 else None


def sockets_to(port: int, before: set[int]) -> list[int]:
    """Socket descriptors opened since ``before`` (a :func:`socket_fds`) whose peer is on ``port``."""
    return sorted(fd for fd in socket_fds() - before if _peer_port(fd) == port)


class SocketWatch:
    """Whether the connection on descriptor ``fd`` has ended (module docstring); one ``poll(2)``, no wait.

    Parameters
    ----------
    fd : a connected TCP socket's descriptor, owned by someone else (never read, written or closed here).
    """

    def __init__(self, fd: int) -> None:
        if not isinstance(fd, int) or isinstance(fd, bool) or fd < 0:
            raise ValueError(f"fd must be a descriptor number >= 0, got {fd!r}")
        self.fd = fd
        self._identity = self._file_identity()
        if self._identity is None:
            raise ValueError(f"fd {fd} is not an open descriptor")
        self._poll = select.poll()
        self._poll.register(fd, ENDED)  # no POLLIN: pending data is no news

    def _file_identity(self) -> tuple[int, int] | None:
        """(device, inode) of what the descriptor names now, None where it is closed."""
        try:
            st = os.fstat(self.fd)
        except OSError:
            return None
        return st.st_dev, st.st_ino

    def ended(self) -> bool:
        """True when the peer reset or closed the connection, or the descriptor was closed or now
        names another socket (the library reconnected under the same number: module docstring)."""
        if any(events & ENDED for _, events in self._poll.poll(0)):
            return True
        return self._file_identity() != self._identity
