"""The simulator in its own process, driven over stdin: ``coassist ur-sim`` and :class:`URSimProcess`.

The ur_rtde client holds Python's GIL while it waits for the controller (its constructor
waits for the first package, a command for its answer), so a simulator in the same process
as the client would never answer: run it in its own, with :class:`URSimProcess` (tests, the
benchmark) or ``coassist ur-sim`` (by hand). Its clock then also never waits for the
client's Python.

:func:`serve` prints one line when every port listens::

    ur-sim: ready on 127.0.0.1 (e-series, 500 Hz, software 5.11.1.108318); dashboard 29999, scripts 30001-30003, RTDE 30004

then reads commands on stdin, one a line, and answers each with one line (``ok``, ``error: …``
or ``status {json}``):

=============================  =============================================================
``protective-stop``            the safety system's protective stop
``emergency-stop``             the pendant's emergency stop pressed; ``release-emergency-stop``
``pendant-stop``               the program stopped from the pendant
``stall`` / ``unstall``        the RTDE server hangs (nothing out, nothing in) / recovers
``delay LATE [JITTER]``        each output package LATE s late plus uniform [0, JITTER] s
``remote on|off``              remote control on the pendant
``drop [REFUSE_FOR]``          every connection closed; new ones refused for REFUSE_FOR s
``push FX FY FZ [TX TY TZ]``   a constant hand wrench on the handle [N, N·m], base frame; ``release``
``status``                     the controller's state and counters, as JSON
``periods``                    the output stream's periods [s] so far, as JSON
``clock``                      the clock's periods [s] so far (its wake-ups), as JSON
``quit``                       stop the simulator (as Ctrl-C and SIGTERM do; at the end of
                               its input it goes on serving)
=============================  =============================================================
"""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import threading
from collections.abc import Sequence
from dataclasses import asdict
from typing import IO, Any

import numpy as np

from coassist.robot.mujoco_world import FTSensorModel
from coassist.robot.ur_sim.server import PORTS, URSim, URSimConfig

__all__ = ["URSimProcess", "config_from_json", "config_to_json", "serve", "spawn"]

READY = "ur-sim: ready on"
#: ``python -m coassist.robot.ur_sim -``: the config is the first line of stdin (:func:`spawn`)
CONFIG_ON_STDIN = "-"


def config_to_json(config: URSimConfig) -> str:
    """The config as one JSON line (the sensor model as its fields)."""
    return json.dumps(asdict(config))


def config_from_json(text: str) -> URSimConfig:
    """The config of :func:`config_to_json`'s line."""
    data = json.loads(text)
    if data.get("sensor") is not None:
        data["sensor"] = FTSensorModel(**data["sensor"])
    for name in ("start", "tcp_offset", "version"):
        if data.get(name) is not None:
            data[name] = tuple(data[name])
    if data.get("payload") is not None:
        mass, cog = data["payload"]
        data["payload"] = (mass, tuple(cog))
    return URSimConfig(**data)


def ready_line(sim: URSim) -> str:
    c = sim.config
    version = ".".join(str(v) for v in c.controller_version)
    return (
        f"{READY} {c.host} ({c.series}, {c.rate:g} Hz, software {version}); dashboard {PORTS[0]}, "
        f"scripts {PORTS[1]}-{PORTS[3]}, RTDE {PORTS[4]}"
    )


def _command(sim: URSim, line: str) -> tuple[str, bool]:
    """One stdin command's reply line, and whether to quit."""
    parts = line.split()
    if not parts:
        return "", False
    name, args = parts[0].lower(), parts[1:]
    try:
        values = [float(a) for a in args] if name in ("delay", "drop", "push") else []
    except ValueError:
        return f"error: {name} takes numbers, got {' '.join(args)}", False
    if name == "quit":
        return "ok", True
    if name == "protective-stop":
        sim.protective_stop()
    elif name == "emergency-stop":
        sim.emergency_stop()
    elif name == "release-emergency-stop":
        sim.release_emergency_stop()
    elif name == "pendant-stop":
        sim.stop_program()
    elif name == "stall":
        sim.stall(True)
    elif name == "unstall":
        sim.stall(False)
    elif name == "delay" and len(values) in (1, 2):
        try:
            sim.set_stream_delay(*values)
        except ValueError as exc:
            return f"error: {exc}", False
    elif name == "remote" and args in (["on"], ["off"]):
        sim.set_remote_control(args[0] == "on")
    elif name == "drop" and len(values) <= 1:
        sim.drop_connections(*values)
    elif name == "push" and len(values) in (3, 6):
        sim.push(values + [0.0] * (6 - len(values)))
    elif name == "release":
        sim.push(None)
    elif name == "status":
        return "status " + json.dumps(sim.status()), False
    elif name == "periods":
        return "periods " + json.dumps(sim.stream_periods().tolist()), False
    elif name == "clock":
        return "clock " + json.dumps(sim.clock_periods().tolist()), False
    else:
        return f"error: unknown command {line.strip()!r} (see coassist ur-sim --help)", False
    return "ok", False


def serve(
    config: URSimConfig, stdin: IO[str] | None = None, stdout: IO[str] | None = None, *, quit_at_eof: bool = False
) -> None:
    """Run the simulator until ``quit`` or Ctrl-C (module docstring); at the end of ``stdin`` it goes
    on serving (a simulator started in the background), or with ``quit_at_eof`` it stops (its parent,
    :class:`URSimProcess`, has gone).

    Raises OSError (naming the port) when a port is taken.
    """
    stdin = stdin or sys.stdin
    stdout = stdout or sys.stdout
    # the clock and the network threads share the GIL: hand it over within 1 ms, not Python's 5 ms
    sys.setswitchinterval(0.001)
    with URSim(config) as sim:
        # what was built stays: the collector need not walk it, and runs rarely (its pauses are the clock's)
        gc.collect()
        gc.freeze()
        gc.set_threshold(50_000, 50, 100)
        print(ready_line(sim), file=stdout, flush=True)
        try:
            for line in stdin:
                reply, stop = _command(sim, line)
                if reply:
                    print(reply, file=stdout, flush=True)
                if stop:
                    return
            if not quit_at_eof:  # no more input (started in the background): serve until Ctrl-C or SIGTERM
                threading.Event().wait()
        except KeyboardInterrupt:
            pass


def spawn() -> subprocess.Popen[str]:
    """A simulator process that imports what it needs, then waits for its config: the first line of
    its stdin (``python -m coassist.robot.ur_sim -``); :meth:`URSimProcess.start` sends it.

    Started ahead (while a test's world closes), the ~0.5 s of imports are paid before the
    simulator is needed; until its config comes it builds nothing and listens on no port, and it
    ends when its stdin does (its parent gone) or on ``kill``.
    """
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    return subprocess.Popen(
        [sys.executable, "-m", "coassist.robot.ur_sim", CONFIG_ON_STDIN],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        bufsize=1,
        env=env,
    )


class URSimProcess:
    """The simulator in a child process (``python -m coassist.robot.ur_sim``), with :class:`URSim`'s fault methods.

    ``with URSimProcess(URSimConfig(host="127.0.0.2")) as sim:`` starts it and waits until it
    listens (RuntimeError with its output when it does not within ``timeout`` s); the methods
    send one stdin command each and wait for its answer.
    """

    def __init__(self, config: URSimConfig | None = None, *, timeout: float = 60.0) -> None:
        self.config = config or URSimConfig()
        self.timeout = float(timeout)
        self._proc: subprocess.Popen[str] | None = None
        self._lock = threading.Lock()

    @property
    def host(self) -> str:
        return self.config.host

    def start(self, process: subprocess.Popen[str] | None = None) -> URSimProcess:
        """Start the simulator with :attr:`config`: in ``process`` (one :func:`spawn` returned, not used
        before: its imports already done) or in a new one; return once it listens.

        Raises RuntimeError with its last lines of output when it does not (an address taken: the
        process has then ended).
        """
        if self._proc is not None:
            return self
        self._proc = process if process is not None else spawn()
        assert self._proc.stdin is not None
        try:
            self._proc.stdin.write(config_to_json(self.config) + "\n")
            self._proc.stdin.flush()
        except OSError as exc:  # it ended before its config (killed)
            self.kill()
            raise RuntimeError(f"ur-sim did not start: {exc}") from exc
        seen: list[str] = []
        done = threading.Event()

        def wait_ready() -> None:
            assert self._proc is not None and self._proc.stdout is not None
            for line in self._proc.stdout:
                seen.append(line.rstrip())
                if line.startswith(READY):
                    break
            done.set()

        t = threading.Thread(target=wait_ready, daemon=True)
        t.start()
        if not done.wait(self.timeout) or not seen or not seen[-1].startswith(READY):
            self.kill()
            raise RuntimeError("ur-sim did not start: " + " | ".join(seen[-5:]))
        return self

    def _ask(self, line: str) -> str:
        with self._lock:
            proc = self._proc
            if proc is None or proc.poll() is not None or proc.stdin is None or proc.stdout is None:
                raise RuntimeError("ur-sim is not running")
            proc.stdin.write(line + "\n")
            proc.stdin.flush()
            while True:
                reply = proc.stdout.readline()
                if not reply:
                    raise RuntimeError(f"ur-sim ended while answering {line!r}")
                reply = reply.rstrip("\n")
                if reply.startswith(("ok", "error", "status", "periods", "clock")):
                    break  # anything else is the simulator's log
        if reply.startswith("error"):
            raise ValueError(reply)
        return reply

    def protective_stop(self) -> None:
        self._ask("protective-stop")

    def emergency_stop(self) -> None:
        self._ask("emergency-stop")

    def release_emergency_stop(self) -> None:
        self._ask("release-emergency-stop")

    def stop_program(self) -> None:
        self._ask("pendant-stop")

    def stall(self, on: bool = True) -> None:
        self._ask("stall" if on else "unstall")

    def set_stream_delay(self, late: float = 0.0, jitter: float = 0.0) -> None:
        self._ask(f"delay {late!r} {jitter!r}")

    def set_remote_control(self, on: bool) -> None:
        self._ask(f"remote {'on' if on else 'off'}")

    def drop_connections(self, refuse_for: float = 0.0) -> None:
        self._ask(f"drop {refuse_for!r}")

    def push(self, wrench: Sequence[float] | None) -> None:
        if wrench is None:
            self._ask("release")
            return
        w = [float(v) for v in wrench]
        self._ask("push " + " ".join(repr(v) for v in w))

    def status(self) -> dict[str, Any]:
        return json.loads(self._ask("status")[len("status ") :])

    def stream_periods(self) -> np.ndarray:
        return np.asarray(json.loads(self._ask("periods")[len("periods ") :]), dtype=float)

    def clock_periods(self) -> np.ndarray:
        return np.asarray(json.loads(self._ask("clock")[len("clock ") :]), dtype=float)

    def stop(self) -> None:
        """Ask it to quit; kill it if it does not within 10 s (idempotent)."""
        proc = self._proc
        if proc is None:
            return
        if proc.poll() is None:
            try:
                assert proc.stdin is not None
                proc.stdin.write("quit\n")
                proc.stdin.flush()
                proc.wait(10)
            except (OSError, subprocess.TimeoutExpired):
                self.kill()
        self._proc = None

    def kill(self) -> None:
        if self._proc is not None:
            self._proc.kill()
            self._proc.wait(10)
            self._proc = None

    def __enter__(self) -> URSimProcess:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
