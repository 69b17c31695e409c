"""SocketWatch against real loopback TCP connections: what the kernel says when the peer resets or closes."""

from __future__ import annotations

import contextlib
import os
import select
import socket
import struct
from collections.abc import Iterator
from pathlib import Path

import pytest

from coassist.robot.socket_watch import ENDED, SocketWatch, socket_fds, sockets_to

HAS_PROC = Path("/proc/self/fd").is_dir()


@contextlib.contextmanager
def connection() -> Iterator[tuple[socket.socket, socket.socket, int]]:
    """(client, the server's end of it, the server's port) on 127.0.0.1."""
    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        client = socket.create_connection(("127.0.0.1", port), timeout=2.0)
        peer, _ = server.accept()
        try:
            yield client, peer, port
        finally:
            client.close()
            peer.close()


def test_a_live_connection_has_not_ended_even_with_data_waiting():
    with connection() as (client, peer, _):
        watch = SocketWatch(client.fileno())
        assert not watch.ended()
        peer.sendall(b"x" * 100)  # unread data is no news (the library reads it, not the watch)
        client.settimeout(2.0)
        assert client.recv(1, socket.MSG_PEEK) == b"x"
        assert not watch.ended()
        assert client.recv(100) == b"x" * 100  # the watch read nothing


def test_a_reset_from_the_peer_is_seen_at_once():
    with connection() as (client, peer, _):
        watch = SocketWatch(client.fileno())
        peer.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        peer.close()  # RST (loopback: delivered before close returns)
        assert watch.ended()
        with pytest.raises(ConnectionResetError):  # what the library's next call would meet
            client.send(b"x")


def test_an_orderly_close_from_the_peer_is_seen():
    with connection() as (client, peer, _):
        watch = SocketWatch(client.fileno())
        peer.close()  # FIN
        assert watch.ended()
        assert client.recv(1) == b""  # the end of the stream, as the library would read it


def test_a_descriptor_closed_by_its_owner_has_ended():
    with connection() as (client, _, _):
        watch = SocketWatch(client.fileno())
        client.close()
        assert watch.ended()


def test_another_socket_under_the_watched_number_has_ended():
    # ur-rtde reconnects by itself after a reset, and its new socket took the old one's number within
    # 3-10 ms on coassist ur-sim: poll(2) on the number then answers for the live new connection
    with connection() as (client, peer, port):
        watch = SocketWatch(client.fileno())
        with socket.create_connection(("127.0.0.1", port), timeout=2.0) as new:
            os.dup2(new.fileno(), client.fileno())  # the old connection closed, its number now the new one's
            alone = select.poll()
            alone.register(client.fileno(), ENDED)
            assert not alone.poll(0)  # poll(2) alone: a live connection, the reset missed
            assert watch.ended()
            assert watch.ended()  # asked again: still ended, the number is still another socket's


def test_a_closed_descriptor_cannot_be_watched():
    with connection() as (client, _, _):
        fd = client.fileno()
    with pytest.raises(ValueError, match="not an open descriptor"):
        SocketWatch(fd)


@pytest.mark.skipif(not HAS_PROC, reason="the descriptors are listed from /proc/self/fd")
def test_sockets_to_finds_the_new_connection_to_the_port_and_leaves_it_open():
    with connection() as (old, _, port):
        before = socket_fds()
        assert old.fileno() in before
        with socket.create_connection(("127.0.0.1", port), timeout=2.0) as new:
            found = sockets_to(port, before)
            assert found == [new.fileno()]  # not the older connection to the same port
            assert sockets_to(port + 1 if port < 65535 else port - 1, before) == []
            new.sendall(b"still open")  # borrowed to ask its peer, never closed


@pytest.mark.parametrize("fd", [-1, 1.5, "3", True])
def test_the_descriptor_is_checked(fd):
    with pytest.raises(ValueError, match="fd must be a descriptor number"):
        SocketWatch(fd)
