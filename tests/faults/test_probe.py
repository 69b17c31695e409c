"""The fault probe's runtime cases without MuJoCo (issue 22 §3): each one failed before its fix.

The MuJoCo cases (state glitches, a jumping pose, a frozen sensor in the loop) are in
``test_runtime_faults.py``; the file and CLI cases in ``test_probe_files.py``.
"""

from __future__ import annotations

import socket

import numpy as np
import pytest

from coassist.control.controllers import saturate
from coassist.interfaces import Fault
from coassist.runtime.safety import SafetyLayer
from coassist.runtime.safety_limits import SafetyLimits
from coassist.runtime.wrench import MEASURED_FROZEN_TIME, WrenchConfig, WrenchPipeline

DT = 0.008


# ---------------------------------------------------------------------- SafetyLayer.limit_effort
CALM = np.zeros(6)


@pytest.mark.parametrize(
    "u_r, v, hand",
    [
        (np.array([np.nan, 1.0]), np.zeros(2), CALM),
        (np.array([np.inf, 1.0]), np.zeros(2), CALM),
        (np.array([3.0, 4.0]), None, CALM),
        (np.array([3.0, 4.0]), np.zeros(1), CALM),
        (np.array([3.0, 4.0]), np.zeros(2), None),
        (np.array([3.0, 4.0]), np.zeros(2), np.zeros(1)),
        (np.array([3.0, 4.0]), np.array([np.nan, 0.0]), CALM),
        (None, np.zeros(2), CALM),
        ("abc", np.zeros(2), CALM),
    ],
    ids=["nan u_r", "inf u_r", "v None", "v short", "hand None", "hand short", "v nan", "u_r None", "u_r str"],
)
def test_limit_effort_never_raises_and_never_returns_nan(u_r, v, hand):
    layer = SafetyLayer(SafetyLimits(), DT, 6)
    effort, flags, stop = layer.limit_effort(u_r, v, hand, Fault.NONE)
    assert effort.shape == (2,) and np.all(effort == 0.0) and not stop
    assert flags & (Fault.INVALID_INPUT | Fault.NONFINITE_EFFORT)
    # good input afterwards is served as before (the layer did not latch anything)
    effort, flags, stop = layer.limit_effort(np.array([3.0, 4.0]), np.zeros(2), CALM, Fault.NONE)
    assert effort.tolist() == [3.0, 4.0] and flags == Fault.NONE and not stop


def test_limit_effort_reads_a_short_force_only_hand():
    """An x-y hand force (2,) is enough for the contact check: 130 N > 120 N stops."""
    layer = SafetyLayer(SafetyLimits(), DT, 6)
    _, flags, stop = layer.limit_effort(np.array([1.0, 0.0]), np.zeros(2), np.array([130.0, 0.0]), Fault.NONE)
    assert stop and flags & Fault.CONTACT_FORCE_LIMIT


# ---------------------------------------------------------------------- saturate
def test_saturate_never_exceeds_its_limit_by_even_one_ulp():
    """20 000 random vectors (the probe found 7 522 of 200 000 one ulp over before the fix)."""
    rng = np.random.default_rng(0)
    u = rng.normal(scale=300.0, size=(20_000, 2)) * rng.uniform(0.5, 50.0, size=(20_000, 1))
    limit = np.array([100.0, 37.3])
    for row in u:
        out, scaled = saturate(row, limit)
        assert np.all(np.abs(out) <= limit)
        if scaled:  # the direction is kept to rounding
            assert abs(out[0] * row[1] - out[1] * row[0]) <= 1e-12 * np.abs(row).max() * np.abs(out).max()


# ---------------------------------------------------------------------- a frozen sensor with a live counter
def _feed(pipe, values, t0=0.0):
    return [pipe.update(v, np.eye(3), k + 1, t0 + k * DT) for k, v in enumerate(values)]


def test_bit_identical_samples_with_a_live_counter_go_stale_after_the_stated_time():
    cfg = WrenchConfig(cutoff_hz=None, deadband_force=0.0, deadband_torque=0.0, max_frozen_time=MEASURED_FROZEN_TIME)
    pipe = WrenchPipeline(cfg, DT)
    stuck = np.array([15.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    out = _feed(pipe, [stuck] * 40)
    stale = [bool(r.fault & Fault.SENSOR_STALE) for r in out]
    # the first sample at t = 0; stale once t > 0.1 s, i.e. from tick 13 (13 · 8 ms = 0.104 s)
    first = int(np.ceil(MEASURED_FROZEN_TIME / DT + 1e-9))
    assert stale == [False] * first + [True] * (40 - first)
    assert all(np.all(r.hand == 0.0) for r in out[first:])  # the hand "lets go"
    # the values move again (the sensor recovered): no longer stale
    assert not _feed(pipe, [stuck + 1e-3], t0=1.0)[0].fault & Fault.SENSOR_STALE


def test_noise_of_one_ulp_is_not_frozen_and_noise_free_inputs_are_exempt():
    cfg = WrenchConfig(max_frozen_time=MEASURED_FROZEN_TIME)
    pipe = WrenchPipeline(cfg, DT)
    base = np.array([15.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    values = [base + np.array([np.spacing(15.0) * (k % 2), 0, 0, 0, 0, 0]) for k in range(200)]
    assert not any(r.fault for r in _feed(pipe, values))
    plain = WrenchPipeline(WrenchConfig(), DT)  # the default: a noise-free (simulated) input
    assert WrenchConfig().max_frozen_time is None
    assert not any(r.fault for r in _feed(plain, [base] * 200))


# ---------------------------------------------------------------------- DNS rebinding on the play server
def _upgrade(port: int, host: str, origin: str | None) -> str:
    """The status line the server answers a websocket upgrade with (101: accepted)."""
    request = (
        f"GET /ws HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
    )
    if origin is not None:
        request += f"Origin: {origin}\r\n"
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall((request + "\r\n").encode())
        return s.recv(256).split(b"\r\n")[0].decode()


def _get(port: int, host: str) -> str:
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(f"GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
        return s.recv(256).split(b"\r\n")[0].decode()


def test_dns_rebinding_host_and_origin_of_another_site_are_refused(tmp_path):
    pytest.importorskip("uvicorn", reason="the play server needs the play extra: pip install 'coassist[play]'")
    from coassist.play.server import PlayServer
    from coassist.play.session import PlayConfig, PlaySession

    config = PlayConfig(user="alice", out=tmp_path, controllers=("manual",), motion_time=1.0, dwell=0.5, grace=0.5)
    with PlayServer(PlaySession(config), port=0) as server:
        p = server.port
        evil = f"evil.example:{p}"
        assert " 101 " not in _upgrade(p, evil, f"http://{evil}") + " "  # the probe's case
        assert " 421 " in _get(p, evil) + " "
        assert " 101 " not in _upgrade(p, f"127.0.0.1:{p + 1}", f"http://127.0.0.1:{p + 1}") + " "  # another port
        assert _upgrade(p, f"localhost:{p}", f"http://localhost:{p}").split()[1] == "101"
        assert _get(p, f"127.0.0.1:{p}").split()[1] == "200"


def test_host_allowed_by_bind():
    from coassist.play.server import host_allowed

    assert host_allowed("127.0.0.1:8765", "127.0.0.1", 8765)
    assert host_allowed("[::1]:8765", "127.0.0.1", 8765)
    assert not host_allowed("evil.example:8765", "127.0.0.1", 8765)
    assert not host_allowed("127.0.0.1:8766", "127.0.0.1", 8765)
    assert not host_allowed("127.0.0.1:x", "127.0.0.1", 8765) and not host_allowed(None, "127.0.0.1", 8765)
    assert host_allowed("192.168.1.5:8765", "0.0.0.0", 8765)
    assert not host_allowed("evil.example:8765", "0.0.0.0", 8765)
    assert host_allowed("10.0.0.2:80", "10.0.0.2", 80) and host_allowed("10.0.0.2", "10.0.0.2", 80)
    assert not host_allowed("10.0.0.3:80", "10.0.0.2", 80)
    # A server bound to a host name answers to that name only, and refuses an address (it raised before).
    assert host_allowed("myhost.lan:80", "myhost.lan", 80) and not host_allowed("10.0.0.2:80", "myhost.lan", 80)
