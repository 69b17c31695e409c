"""The whole control tick on the MuJoCo UR5, without the physics step, against a naive tick.

    .venv/bin/python benchmarks/bench_tick.py [--ticks 3000] [--model MODEL [--backends process,onnx,torch]]
                                              [--realtime-seconds 60]

Measures the tick's own work as the loop times it for its deadline (``LoopRun.compute``:
the world's read, the wrench pipeline, predictor dispatch, game, impedance, J⁺, safety, up to
the command; not the world's apply) for the assistive controller with the simulated operator, and a naive tick that
does the same work but recomputes the game's gains (prediction matrices and the
equilibrium solve) and an SVD pseudo-inverse (np.linalg.pinv) every tick. With
``--model`` the intent stage is the RealtimePredictor on that model (the deployed
path), once per backend: the network in a worker process, ONNX Runtime in a worker
thread, eager torch in a worker thread (it holds the GIL the tick needs); without, the
nominal plan. Prints median and p99 [ms] and the ratio.

``--realtime-seconds S`` also runs the MuJoCo world at 500 Hz paced to the wall clock for S
seconds and counts deadline misses (the tick's own work over 2 ms) and periods the
world could not keep (physics + tick over 2 ms). One BLAS thread: one core.

Each row but the naive one is measured twice: **back to back** (the world is stepped as
fast as it goes: the tick's own work on one core, the issue's measure) and **paced** (the
world sleeps to the wall clock between periods, as on a robot). On a VM the first instructions after
a sleep run slowly (cold caches and TLB): the **platform reference** row times a fixed
workload of small numpy and Python operations the same two ways, so the paced/back-to-back
ratio of the tick can be read against the machine's own. Two single calls the tick
path makes (``np.isfinite`` on 8 numbers every tick; a worker process's ``is_alive``, which
the process backend asks at most every 50 ms) are timed the same two ways.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from coassist.control.game import CooperativeGame  # noqa: E402
from coassist.robot import drive as drive_mod  # noqa: E402
from coassist.robot.drive import DriveConfig  # noqa: E402
from coassist.runtime import loop as loop_mod  # noqa: E402
from coassist.runtime import tick as tick_mod  # noqa: E402


def _stats(x: np.ndarray) -> tuple[float, float]:
    return float(np.median(x) * 1e3), float(np.percentile(x, 99) * 1e3)


class NaiveController:
    """The assistive controller that rebuilds the game every tick (no precomputed gains)."""

    def __init__(self, controller, params) -> None:
        self.inner, self.params = controller, params
        self.name, self.model, self.horizon = controller.name, controller.model, controller.horizon

    def step(self, z, ref_h, ref_r, wrench):
        # the game built anew, not cooperative_game's per-process copy of one built once
        p = self.params
        game = CooperativeGame(
            self.model,
            p.weights,
            alpha=p.alpha,
            horizon=p.horizon,
            control_horizon=p.control_horizon,
            input_weighting=p.input_weighting,
        )
        self.inner.game = game
        return self.inner.step(z, ref_h, ref_r, wrench)


def naive_dls(J, twist, thr, damp):
    return np.linalg.pinv(J) @ twist, 0.0


def reference_work(a: np.ndarray, M: np.ndarray) -> float:
    """A fixed workload of small numpy operations and Python arithmetic, in the tick's style."""
    s = 0.0
    for i in range(40):
        b = M @ a
        s += float(b[i % 6]) if np.isfinite(b).all() else 0.0
        a = np.clip(b, -1.0, 1.0)
    return s


def measure_reference(n: int, period: float) -> dict:
    """The platform reference: ``reference_work`` back to back and with a sleep of one period before each call."""
    rng = np.random.default_rng(0)
    a, M = rng.normal(size=6), rng.normal(size=(6, 6)) / 3
    out = {}
    for name, pause in (("back_to_back", 0.0), ("paced", period)):
        t = []
        for _ in range(n):
            if pause:
                time.sleep(pause)
            t0 = time.perf_counter()
            reference_work(a, M)
            t.append(time.perf_counter() - t0)
        out[name] = np.array(t[50:])
    return out


def measure_cold_calls(n: int, period: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Single calls the tick makes, timed back to back and right after a sleep of one period:
    ``np.isfinite(a).all()`` on 8 numbers and ``multiprocessing.Process.is_alive()`` (a waitpid)."""
    import multiprocessing

    proc = multiprocessing.get_context("spawn").Process(target=time.sleep, args=(3600.0,), daemon=True)
    proc.start()
    a = np.zeros(8)
    out = {}
    try:
        for name, call in (
            ("np.isfinite(a).all()", lambda: np.isfinite(a).all()),
            ("Process.is_alive()", proc.is_alive),
        ):
            runs = []
            for pause in (0.0, period):
                t = []
                for _ in range(n):
                    if pause:
                        time.sleep(pause)
                    t0 = time.perf_counter()
                    call()
                    t.append(time.perf_counter() - t0)
                runs.append(np.array(t[20:]))
            out[name] = (runs[0], runs[1])
    finally:
        proc.kill()
        proc.join(timeout=5.0)
    return out


def measure(
    ticks: int,
    model: str | None,
    naive: bool,
    rate: int = 125,
    realtime: bool = False,
    backend: str = "process",
    task_kind: str = "z",
    paced: bool = True,
) -> dict:
    times: list[float] = []
    dt = 1.0 / rate
    config = DriveConfig(
        controller="cooperative",
        task=task_kind,
        intent=model or "nominal",
        rate_hz=rate,
        time_limit=ticks * dt,
        realtime_intent=True if model else None,
        predictor_backend=backend,
    )
    # the tick's own work as the loop times it (LoopRun.compute, read → command): the loop runs the tick in
    # parts (sense, decide/finish), so wrapping ControlTick.step times nothing
    orig_log = loop_mod.LoopRun.log
    orig_dls = tick_mod._spatial.dls_joint_velocity
    orig_ctrl = drive_mod._controller

    def logged(self):
        log = orig_log(self)
        times[:] = log.compute.tolist()
        return log

    loop_mod.LoopRun.log = logged
    if naive:
        from coassist.control.presets import get_preset

        def naive_controller(cfg):
            c = orig_ctrl(cfg)
            from dataclasses import replace

            p = get_preset(cfg.preset).game
            params = replace(p, horizon=c.horizon)
            return NaiveController(c, params)

        drive_mod._controller = naive_controller
        tick_mod._spatial.dls_joint_velocity = naive_dls
    try:
        from coassist.robot.mujoco_world import MujocoUR5World
        from coassist.scenario.tasks import make_task

        world = None
        if realtime or model or paced:  # paced to the wall clock as on a robot, or (a model's run) back to back
            task = make_task(task_kind, np.random.default_rng(np.random.SeedSequence([0, 0])))
            world = MujocoUR5World(
                "handle",
                control_dt=dt,
                start=(float(task.start[0]), float(task.start[1]), 0.2),
                realtime=bool(realtime or paced),
            )
        t_wall = time.perf_counter()
        trial = drive_mod.drive(config, world=world)
        wall = time.perf_counter() - t_wall
        if world is not None:
            world.close()
    finally:
        loop_mod.LoopRun.log = orig_log
        tick_mod._spatial.dls_joint_velocity = orig_dls
        drive_mod._controller = orig_ctrl
    arr = np.array(times)
    misses = int((arr > dt).sum())
    dl = int((trial.fault & int(tick_mod.Fault.DEADLINE_MISS) != 0).sum())
    return {"times": arr, "misses": misses, "flagged": dl, "wall": wall, "n": trial.n_samples}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=3000)
    ap.add_argument("--naive-ticks", type=int, default=300)
    ap.add_argument("--model", default=None, help="an intent model folder (the deployed RealtimePredictor path)")
    ap.add_argument("--backends", default="process,onnx,torch", help="predictor backends to measure with --model")
    ap.add_argument("--realtime-seconds", type=float, default=0.0)
    a = ap.parse_args()
    backends = a.backends.split(",") if a.model else ["process"]
    slow = measure(a.naive_ticks, a.model, naive=True, backend=backends[0], paced=False)
    sm, sp = _stats(slow["times"][20:])
    ref = measure_reference(a.ticks, 1.0 / 125)
    rbm, rbp = _stats(ref["back_to_back"])
    rpm, rpp = _stats(ref["paced"])
    print(f"intent: {'RealtimePredictor on ' + a.model if a.model else 'nominal plan'}; 125 Hz; assistive; z task")
    print(
        "| the tick's own work (no physics) | back to back: median ms | p99 ms | paced: median ms | p99 ms | "
        "paced/back-to-back p99 | ticks > 8 ms | ratio naive/this (median, p99) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for backend in backends:
        hot = measure(a.ticks, a.model, naive=False, backend=backend, paced=False)
        fm, fp = _stats(hot["times"][50:])
        paced = measure(a.ticks, a.model, naive=False, backend=backend, paced=True)
        pm, pp = _stats(paced["times"][50:])
        name = f"coassist, predictor backend {backend}" if a.model else "coassist"
        misses = hot["misses"] + paced["misses"]
        print(
            f"| {name} | {fm:.3f} | {fp:.3f} | {pm:.3f} | {pp:.3f} | {pp / fp:.1f} | "
            f"{misses}/{len(hot['times']) + len(paced['times'])} | {sm / fm:.0f}x, {sp / fp:.0f}x |"
        )
    print(
        f"| naive (gains + pinv every tick; backend {backends[0]}) | {sm:.3f} | {sp:.3f} | | | | "
        f"{slow['misses']}/{len(slow['times'])} | 1x |"
    )
    print(
        f"| platform reference (fixed workload, not coassist) | {rbm:.3f} | {rbp:.3f} | {rpm:.3f} | {rpp:.3f} | "
        f"{rpp / rbp:.1f} | | |"
    )
    for name, (hot, cold) in measure_cold_calls(400, 1.0 / 125).items():
        print(
            f"one call of {name}: back to back median {np.median(hot) * 1e6:.1f} µs, p99 {np.percentile(hot, 99) * 1e6:.1f} µs; "
            f"after an 8 ms sleep median {np.median(cold) * 1e6:.1f} µs, p99 {np.percentile(cold, 99) * 1e6:.1f} µs"
        )
    if a.realtime_seconds > 0:
        # Trials end at their target: run one task after another until the time is filled.
        n = int(math.ceil(a.realtime_seconds * 500))
        times, flagged, wall, ticks, tasks = [], 0, 0.0, 0, []
        for task_kind in ("z", "curved", "sinusoidal", "linear") * 10:
            rt = measure(n - ticks, None, naive=False, rate=500, realtime=True, task_kind=task_kind)
            times.append(rt["times"])
            flagged, wall, ticks = flagged + rt["flagged"], wall + rt["wall"], ticks + rt["n"]
            tasks.append(task_kind)
            if ticks >= n:
                break
        arr = np.concatenate(times)
        m, p = _stats(arr)
        print(
            f"500 Hz real time, {ticks} ticks ({ticks / 500:.1f} s; tasks {', '.join(tasks)}) in {wall:.1f} s wall: "
            f"tick median {m:.3f} ms, p99 {p:.3f} ms, max {arr.max() * 1e3:.3f} ms; ticks over 2 ms: "
            f"{int((arr > 0.002).sum())}; deadline misses flagged by the loop: {flagged}"
        )


if __name__ == "__main__":
    main()
