"""The MuJoCo arms of a lockstep group in one model: what its world stage would save, measured (issue 44).

    .venv/bin/python benchmarks/bench_mujoco_arms.py [--arms 24] [--ticks 600] [--tool board] [--json out.json]

The main job's MuJoCo UR5 trials cost some 160 µs a trial-tick (``bench_profile.py job mj-mg``), about ten times
a point-mass trial's on the array path; docs/performance.md names the lever: a lockstep group's arms stepped
together. This measures that lever's first stage, the world, before anything is built on it:

- ``separate``: B :class:`~coassist.robot.mujoco_world.MujocoArmWorld` (the main job's), each its own model and
  data, each tick its own ``apply`` (the servo on Python floats, four 2 ms physics substeps of mj_step2/mj_step1,
  the sensor's samples);
- ``together``: one MuJoCo model holding the B arms (the same arm spec attached B times, :meth:`mujoco.MjSpec.attach`,
  all at the base's own place: the UR5 model has no contacts, so they never touch), each substep the servo as
  (B, 6) arrays (the world's formula, elementwise, in its order), one ``mj_mulM`` and one mj_step2/mj_step1 for
  all; each arm's sensor noise from its own generator, as in its world.

And the arm stage's numeric core, the damped-least-squares step (eq. 3.6, :func:`coassist.spatial.dls_joint_velocity`,
about 12 µs an arm): each arm's own Jacobian at every tick (its kinematics at its joints), asked for the twist of its
commanded joint velocity, once per arm as the tick does and once stacked ((B, 6, 6) products, ``eigvalsh`` and
``solve``: numpy runs the same LAPACK routine on each slice), the two compared bit for bit; and on 200 random
Jacobians, half of them within the damping's threshold of a singularity (the damped branch).

Both get the same commands (each arm its own joint-velocity sines). The check: every arm's joint positions,
velocities, controls and sampled wrench in the one model equal its world's, bit for bit, at every tick, outside the
timed work (``--no-check``: at the end only); exit status 1 where they differ. Printed per tick of all B arms: median
and p99 [µs] of both (CPU time, the two alternated tick by tick), the ratio, and the cost per trial-tick. It measures
the world stage alone: the control tick's arm stage (kinematics, the DLS step, the safety layer) and the simulated
hand stay per arm here, as they are in the loop today.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from coassist.robot.arm_mjcf import build_arm_spec  # noqa: E402
from coassist.robot.mujoco_world import MAX_TRACKING_ERROR, MujocoArmWorld  # noqa: E402
from coassist.runtime.world import Command  # noqa: E402
from coassist.spatial import dls_joint_velocity  # noqa: E402

#: MuJoCo's force/torque sensor reads the tool's reaction on the flange: the world flips its sign (a drift from the
#: world's convention fails the bit-for-bit check below)
SENSOR_SIGN = -1.0


class ArmsTogether:
    """B copies of a :class:`MujocoArmWorld`'s arm in one MuJoCo model, stepped as the worlds step (no hand)."""

    def __init__(self, worlds: list[MujocoArmWorld], tool: str) -> None:
        w0 = worlds[0]
        parent = mujoco.MjSpec()
        parent.option.timestep = w0.model.opt.timestep
        parent.option.gravity = w0.model.opt.gravity.copy()
        parent.option.integrator = w0.model.opt.integrator
        for i in range(len(worlds)):
            child = build_arm_spec(w0.robot, tool, physics_dt=w0.physics_dt, servo_time_constant=w0.servo_time_constant)
            parent.attach(child, prefix=f"a{i}/", frame=parent.worldbody.add_frame())
        self.model = m = parent.compile()
        self.data = d = mujoco.MjData(m)
        B, n = len(worlds), w0.n_joints
        if m.nq != B * n or m.nv != B * n or m.nu != B * n:
            raise SystemExit(f"the combined model has {m.nq} joints, expected {B * n}")
        self.B, self.n = B, n
        self.h, self.alpha, self.kd, self.kp = w0.physics_dt, w0._alpha, w0._kd, w0._kp
        self.n_substeps, self.rate = w0.n_substeps, w0.sensor.rate_hz
        self.limits = np.tile(w0.velocity_limits, (B, 1))
        self.v_ref = np.array([w._v_ref for w in worlds], dtype=float)
        self.q_ref = np.array([w._q_ref for w in worlds], dtype=float)
        self.target = np.zeros((B, n))
        self.q = d.qpos.reshape(B, n)
        self.qd = d.qvel.reshape(B, n)
        self.u = np.zeros(B * n)
        self.u2 = self.u.reshape(B, n)
        self.q[:] = [w.data.qpos for w in worlds]
        self.qd[:] = 0.0
        self.force_adr = [int(m.sensor(f"a{i}/ft_force").adr[0]) for i in range(B)]
        self.torque_adr = [int(m.sensor(f"a{i}/ft_torque").adr[0]) for i in range(B)]
        # the worlds' generators, copied: each arm's noise is its own stream, as in its world
        self.rngs = [np.random.default_rng() for _ in worlds]
        for r, w in zip(self.rngs, worlds):
            r.bit_generator.state = w._rng.bit_generator.state
        self.sigma, self.range, self.bias = w0._sigma, w0._range, w0._bias
        self.wrench = np.array([w._wrench for w in worlds])
        self.steps, self.sample_index = w0._steps, w0._sample_index
        mujoco.mj_forward(m, d)
        self._servo(hold=True)
        mujoco.mj_forward(m, d)

    def _servo(self, hold: bool = False) -> None:
        # the world's _set_servo on (B, n) arrays: u = dv/h + kd (v − q̇) + kp (q_ref − q), the same order of operations
        v = self.v_ref
        dv = np.zeros_like(v) if hold else self.alpha * (self.target - v)
        u = self.u2
        np.divide(dv, self.h, out=u)
        u += self.kd * (v - self.qd)
        u += self.kp * (self.q_ref - self.q)
        if not hold:
            v += dv
            self.q_ref += self.h * v
        mujoco.mj_mulM(self.model, self.data, self.data.ctrl, self.u)
        self.data.ctrl += self.data.qfrc_bias

    def apply(self, qd: np.ndarray) -> None:
        """One control period for every arm: ``qd`` (B, n) the commanded joint velocities (finite)."""
        np.minimum(np.maximum(qd, -self.limits), self.limits, out=self.target)
        err = self.q_ref - self.q
        far = (np.abs(err) > MAX_TRACKING_ERROR).any(axis=1)
        if far.any():
            self.q_ref[far] = self.q[far] + np.clip(err[far], -MAX_TRACKING_ERROR, MAX_TRACKING_ERROR)
        m, d = self.model, self.data
        for _ in range(self.n_substeps):
            self._servo()
            mujoco.mj_step2(m, d)
            mujoco.mj_step1(m, d)
            self.steps += 1
            idx = math.floor(self.steps * self.h * self.rate + 1e-9)
            if idx != self.sample_index:
                self.sample_index = idx
                self._sample()

    def _sample(self) -> None:
        s = self.data.sensordata
        for i in range(self.B):
            fa, ta = self.force_adr[i], self.torque_adr[i]
            raw = np.concatenate((s[fa : fa + 3], s[ta : ta + 3]))
            raw *= SENSOR_SIGN
            raw += self.bias
            noise = self.rngs[i].standard_normal(6)
            noise *= self.sigma
            raw += noise
            np.minimum(raw, self.range, out=raw)
            self.wrench[i] = np.maximum(raw, -self.range, out=raw)


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


def same(worlds: list[MujocoArmWorld], together: ArmsTogether) -> bool:
    n = together.n
    for i, w in enumerate(worlds):
        if not (
            np.array_equal(w.data.qpos, together.q[i])
            and np.array_equal(w.data.qvel, together.qd[i])
            and np.array_equal(w._wrench, together.wrench[i])
            and np.array_equal(w.data.ctrl, together.data.ctrl[i * n : (i + 1) * n])
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
    if args.arms < 1 or args.ticks < 10:
        parser.error("--arms must be ≥ 1 and --ticks ≥ 10")
    worlds = [MujocoArmWorld(args.tool, seed=i) for i in range(args.arms)]
    together = ArmsTogether(worlds, args.tool)
    if not same(worlds, together):
        raise SystemExit("the arms together differ from their worlds before the first tick")
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
                together.apply(qd[k])
                t_tog.append(clock() - t0)
        if not args.no_check and first_diff is None and not same(worlds, together):
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
    if first_diff is None and not same(worlds, together):
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
        f"{out['separate_us']['median']:.0f} µs, p99 {out['separate_us']['p99']:.0f}; one model median "
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
