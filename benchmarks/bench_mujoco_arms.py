"""The MuJoCo arms of a lockstep group in one model: what it saves, measured (issue 44).

    .venv/bin/python benchmarks/bench_mujoco_arms.py [--arms 24] [--ticks 600] [--tool board] [--json out.json]

The main job's MuJoCo UR5 trials cost some 160 µs a trial-tick (``bench_profile.py job mj-mg``), about ten times
a point-mass trial's on the array path. :class:`~coassist.robot.mujoco_world.MujocoArmGroup` (what ``drive_lockstep``
does) steps the worlds of a lockstep group in one MuJoCo model. This measures it against the worlds alone:

- ``separate``: B :class:`~coassist.robot.mujoco_world.MujocoArmWorld`, each its own model and data, each tick its
  own ``apply`` (the servo on Python floats, four 2 ms physics substeps of mj_step2/mj_step1, the sensor's samples);
- ``together``: B such worlds in a :class:`MujocoArmGroup` (one model holding their arms, each attached at the base's
  place), each tick every world's ``apply`` (its target, its hand) and the group's ``step`` (the servo on (B, 6)
  arrays, one ``mj_mulM`` and one mj_step2/mj_step1 per substep for all, each world's sensor samples).

Both get the same commands (each arm its own joint-velocity sines). The check: every arm's joint positions,
velocities, controls, sampled wrench and sample count in the group equal its twin's alone, bit for bit, at every
tick, outside the timed work (``--no-check``: at the end only); exit status 1 where they differ.

And the arm stage's numeric core, the damped-least-squares step (eq. 3.6, :func:`coassist.spatial.dls_joint_velocity`,
about 12 µs an arm), which the group does not batch: each arm's own Jacobian at every tick (its kinematics at its
joints), asked for the twist of its commanded joint velocity, once per arm as the tick does and once stacked ((B, 6,
6) products, ``eigvalsh`` and ``solve``: numpy runs the same LAPACK routine on each slice), the two compared bit for
bit; and on 200 random Jacobians, half of them within the damping's threshold of a singularity (the damped branch).

Printed per tick of all B arms: median and p99 [µs] of both (CPU time, the two alternated tick by tick), the ratio,
and the cost per trial-tick. No hand here: the simulated operator's own work stays per arm either way.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from coassist.robot.mujoco_world import MujocoArmGroup, MujocoArmWorld  # noqa: E402
from coassist.runtime.world import Command  # noqa: E402
from coassist.spatial import dls_joint_velocity  # noqa: E402


def dls_stacked(
    J: np.ndarray, twist: np.ndarray, sigma_threshold: float = 0.05, max_damping: float = 0.05
) -> np.ndarray:
    """:func:`~coassist.spatial.dls_joint_velocity` for a stack: J (B, n, n), twist (B, n) → q̇ (B, n), each row that
    function's operations on its slice (its default threshold and damping: the tick's)."""
    JJt = J @ np.transpose(J, (0, 2, 1))
    sigma_min = np.sqrt(np.maximum(np.linalg.eigvalsh(JJt)[:, 0], 0.0))
    out = np.empty_like(twist)
    plain = sigma_min >= sigma_threshold
    if plain.all():
        return np.linalg.solve(J, twist[:, :, None])[:, :, 0]
    if plain.any():
        out[plain] = np.linalg.solve(J[plain], twist[plain][:, :, None])[:, :, 0]
    damped = ~plain
    ratio = sigma_min[damped] / sigma_threshold
    lam = max_damping * np.sqrt(1.0 - ratio * ratio)
    A = JJt[damped]
    diag = np.arange(J.shape[1])
    A[:, diag, diag] += (lam * lam)[:, None]
    x = np.linalg.solve(A, twist[damped][:, :, None])
    out[damped] = (np.transpose(J[damped], (0, 2, 1)) @ x)[:, :, 0]
    return out


def dls_near_singular_same() -> bool:
    """The stacked step equals the per-arm one on 200 random Jacobians, half of them near a singularity."""
    rng = np.random.default_rng(44)
    J = rng.normal(0.0, 0.3, (200, 6, 6))
    for i in range(0, 200, 2):
        u, sv, vt = np.linalg.svd(J[i])
        sv[-1] = rng.uniform(0.0, 0.04)
        J[i] = (u * sv) @ vt
    twist = rng.normal(0.0, 0.1, (200, 6))
    one = np.array([dls_joint_velocity(J[i].copy(), twist[i])[0] for i in range(200)])
    return bool(np.array_equal(dls_stacked(J, twist), one))


def commands(B: int, n: int, ticks: int, dt: float) -> np.ndarray:
    """(ticks, B, n) joint velocities [rad/s]: each arm its own sines, within the UR5's limits."""
    rng = np.random.default_rng(20261205)
    freq = rng.uniform(0.2, 0.8, (B, n))
    phase = rng.uniform(0.0, 2.0 * math.pi, (B, n))
    amp = rng.uniform(0.05, 0.3, (B, n))
    t = np.arange(ticks)[:, None, None] * dt
    return amp * np.sin(2.0 * math.pi * freq * t + phase)


def same(worlds: list[MujocoArmWorld], grouped: list[MujocoArmWorld]) -> bool:
    for a, b in zip(worlds, grouped):
        sa, sb = a.read(), b.read()
        if not (
            np.array_equal(sa.q, sb.q)
            and np.array_equal(sa.qd, sb.qd)
            and np.array_equal(sa.wrench, sb.wrench)
            and sa.wrench_seq == sb.wrench_seq
            and np.array_equal(a._ctrl, b._ctrl)
        ):
            return False
    return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--arms", type=int, default=24, help="B, the lockstep group's trials (a cell: 24)")
    parser.add_argument("--ticks", type=int, default=600)
    parser.add_argument("--tool", default="board", choices=("handle", "board", "heavy"))
    parser.add_argument("--no-check", action="store_true", help="compare the two at the end only")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    if args.arms < 2 or args.ticks < 10:
        parser.error("--arms must be ≥ 2 (a group) and --ticks ≥ 10")
    worlds = [MujocoArmWorld(args.tool, seed=i) for i in range(args.arms)]
    grouped = [MujocoArmWorld(args.tool, seed=i) for i in range(args.arms)]
    group = MujocoArmGroup(grouped)
    if not same(worlds, grouped):
        raise SystemExit("the grouped worlds differ from their twins before the first tick")
    qd = commands(args.arms, worlds[0].n_joints, args.ticks, worlds[0].dt)
    t_sep, t_tog, d_one, d_stack = [], [], [], []
    kinematics = [w.kinematics() for w in worlds]
    dls_diff = None
    clock = time.process_time_ns
    first_diff = None
    for k in range(args.ticks):
        cmds = [Command(qd=qd[k, i]) for i in range(args.arms)]
        # alternate which goes first, so a slow moment of the machine falls on both alike
        order = (0, 1) if k % 2 == 0 else (1, 0)
        for which in order:
            t0 = clock()
            if which == 0:
                for w, c in zip(worlds, cmds):
                    w.apply(c)
                t_sep.append(clock() - t0)
            else:
                for w, c in zip(grouped, cmds):
                    w.apply(c)
                group.step()
                t_tog.append(clock() - t0)
        if not args.no_check and first_diff is None and not same(worlds, grouped):
            first_diff = k
        # the DLS step on each arm's Jacobian now, for the twist its command asks (Jacobians untimed)
        J = np.array([kin.forward_and_jacobian(w.data.qpos)[2] for kin, w in zip(kinematics, worlds)])
        twist = (J @ qd[k][:, :, None])[:, :, 0]
        t0 = clock()
        one = [dls_joint_velocity(J[i].copy(), twist[i])[0] for i in range(args.arms)]
        t1 = clock()
        stacked = dls_stacked(J, twist)
        t2 = clock()
        d_one.append(t1 - t0)
        d_stack.append(t2 - t1)
        if dls_diff is None and not np.array_equal(np.array(one), stacked):
            dls_diff = k
    if first_diff is None and not same(worlds, grouped):
        first_diff = args.ticks - 1
    sep, tog = np.array(t_sep) / 1e3, np.array(t_tog) / 1e3
    d1, ds = np.array(d_one) / 1e3, np.array(d_stack) / 1e3
    dls_same = dls_diff is None and dls_near_singular_same()
    out = {
        "arms": args.arms,
        "ticks": args.ticks,
        "tool": args.tool,
        "bit_for_bit": first_diff is None,
        "first_tick_differing": first_diff,
        "separate_us": {"median": float(np.median(sep)), "p99": float(np.percentile(sep, 99))},
        "together_us": {"median": float(np.median(tog)), "p99": float(np.percentile(tog, 99))},
        "dls_bit_for_bit": dls_same,
        "dls_per_arm_us": {"median": float(np.median(d1)), "p99": float(np.percentile(d1, 99))},
        "dls_stacked_us": {"median": float(np.median(ds)), "p99": float(np.percentile(ds, 99))},
    }
    B = args.arms
    print(
        f"{B} arms ({args.tool}), {args.ticks} ticks, CPU time per tick of all arms: separate worlds median "
        f"{out['separate_us']['median']:.0f} µs, p99 {out['separate_us']['p99']:.0f}; grouped median "
        f"{out['together_us']['median']:.0f} µs, p99 {out['together_us']['p99']:.0f}"
    )
    print(
        f"per trial-tick: {out['separate_us']['median'] / B:.1f} → {out['together_us']['median'] / B:.1f} µs "
        f"(ratio {out['separate_us']['median'] / out['together_us']['median']:.2f}x); "
        + (
            "every arm's state equal bit for bit at every tick"
            if first_diff is None
            else f"DIFFERS from tick {first_diff}"
        )
    )
    print(
        f"the DLS step, all arms: one call per arm median {out['dls_per_arm_us']['median']:.0f} µs "
        f"(p99 {out['dls_per_arm_us']['p99']:.0f}), stacked {out['dls_stacked_us']['median']:.0f} µs "
        f"(p99 {out['dls_stacked_us']['p99']:.0f}): {out['dls_per_arm_us']['median'] / B:.1f} → "
        f"{out['dls_stacked_us']['median'] / B:.1f} µs per trial-tick; "
        + ("equal bit for bit (and near singularities)" if dls_same else "DIFFERS")
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    if first_diff is not None or not dls_same:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
