"""Point-mass trials in lockstep as arrays: every stage of the tick for B trials at once.

:func:`~coassist.runtime.lockstep.run_loops` runs B trials tick by tick, but each trial's
world, operator, wrench pipeline, tick and safety layer still do their own scalar Python
every tick (a few hundred microseconds per trial-tick); only the network and the shared
controller are called once for all. Here the simulated :class:`~coassist.sim.world.PointMassWorld`
trials of a group advance as arrays of shape (B, ·): per tick k, for the trials still going::

    read      x, v (B, 2), the sensor's latest sample w (B, 2), its counter
    wrench    new sample? stale? frozen? spike? saturated?            (POINT_MASS_WRENCH's checks)
    intent    rows (B, 8) → one ring buffer per model → one predict_batch call (models);
              the tick's own intent stage per trial (oracle, constant velocity); none (nominal)
    control   z = [x − x0; v], ref_h from the predictions, ref_r from the plan → one
              effort_batch per shared controller; one arbitrated_effort_batch per group of
              online-α runs (each its own α); any other stateful one: its own step per trial
    safety    contact force, tool speed (the effort stage)
    world     operator arm (eq. 4.1: delay, adaptation, noise, force limit), board yaw,
              exact ZOH plant, the sensor's next sample
    log       row k; the target-dwell rule

Every formula is the scalar code's own, written elementwise in the same order of
operations (numpy's elementwise + − × ÷ and sqrt are IEEE operations, as Python's), so a
trial here gives what the per-trial loop gives bit for bit. The controller is the same
object's ``effort_batch`` (row for row its ``step``; the online-α ones
:func:`~coassist.control.arbitration.arbitrated_effort_batch`, row for row each run's
``step``), the network the same batcher.

The fast path covers the fault-free tick, which is every tick of every simulated trial
in practice (no fault bit in any of 138 trials sampled from a full ``coassist reproduce``).
A trial in which anything unusual happens — any fault flag (a stale, frozen, spiking or
saturated sensor, a prediction fallback, a saturated or refusing controller, the tool
speed or contact limit), a non-finite state, a batched call that raises — leaves the fast
path at that tick: :func:`run_point_mass_lockstep` returns None for it, and the caller runs
it again from its spec on the reference path (:func:`coassist.sim.world.run_spec_lockstep`
does), which handles every branch. The result is the reference path's trial either way.

With a model in the loop the network's float32 rows depend on the batch (see
:mod:`coassist.runtime.lockstep`): here the batch holds the same trials in the same order as
``run_loops``' for as long as none leaves early, so the trials equal ``run_loops``' bit for
bit; after a trial leaves, the others' rows may round differently on torch (ONNX Runtime's
rows do not depend on the batch on the project's machines: there they stay bit for bit).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from coassist.control.arbitration import ArbitratedController, arbitrated_effort_batch, guard_key
from coassist.runtime.lockstep import Loop, _batcher, _stepper
from coassist.runtime.loop import LoopLog, TargetDwell
from coassist.runtime.safety import SafetyLayer
from coassist.runtime.wrench import WrenchPipeline

__all__ = ["fast_path_eligible", "run_point_mass_lockstep"]


def fast_path_eligible(loop: Loop) -> bool:
    """Whether a run can take the array path: a fresh :class:`~coassist.sim.world.PointMassWorld`
    under an effort tick on x-y, the point-mass wrench pipeline (no filter, deadband, payload
    or zeroing), a safety layer that has not stopped, the target-dwell rule (or none)."""
    from coassist.sim.world import PointMassWorld

    world, tick = loop.world, loop.tick
    if type(world) is not PointMassWorld or world.k != 0 or world._stopped:
        return False
    if tick.command_space != "effort" or tick.config.dofs != (0, 1):
        return False
    wrench = tick.wrench
    if type(wrench) is not WrenchPipeline or wrench._alpha is not None or wrench._db_f > 0.0 or wrench._db_t > 0.0:
        return False
    if wrench._has_payload or wrench._zero_left > 0 or wrench._seq is not None or wrench._ref is not None:
        return False
    if type(tick.safety) is not SafetyLayer or tick.safety._stopped:
        return False
    # any intent stage: nominal, a shared model's batcher, or the tick's own predict() per run
    return loop.termination is None or (type(loop.termination) is TargetDwell and loop.termination.inside == 0)


def run_point_mass_lockstep(loops: Sequence[Loop], clock: Callable[[], float] = time.perf_counter,
                            on_end: Callable[[int, LoopLog], None] | None = None) -> list[LoopLog | None]:  # fmt: skip
    """Run the loops (each :func:`fast_path_eligible`) as arrays (module docstring).

    Returns each run's :class:`~coassist.runtime.loop.LoopLog`, or None for a run that left
    the fast path (run it again on the reference path). ``on_end(i, log)`` is called as run
    i ends (not for those that left). ``compute`` is each tick's share of the batch's time.
    """
    for i, loop in enumerate(loops):
        if not isinstance(loop, Loop) or not fast_path_eligible(loop):
            raise ValueError(f"loops[{i}] cannot take the point-mass array path (fast_path_eligible is False)")
    B = len(loops)
    if B == 0:
        return []
    state = _Batch(loops)
    logs: list[LoopLog | None] = [None] * B
    active = np.array([i for i in range(B) if state.n_max[i] > 0], dtype=np.intp)
    for i in range(B):
        if state.n_max[i] <= 0:
            logs[i] = log = state.log(i, 0, "time_limit")
            if on_end is not None:
                on_end(i, log)
    k = 0
    while active.size:
        t0 = clock()
        keep, ended = state.tick(k, active)
        share = (clock() - t0) / active.size
        state.compute[active, k] = share
        for i, why in ended:
            logs[i] = log = state.log(i, k + 1, why)
            if on_end is not None:
                on_end(i, log)
        active = keep
        k += 1
    return logs


class _Batch:
    """The B runs' state as arrays and their logs (module docstring)."""

    def __init__(self, loops: Sequence[Loop]) -> None:
        B = len(loops)
        worlds: list[Any] = [lp.world for lp in loops]  # PointMassWorlds (fast_path_eligible)
        ticks = [lp.tick for lp in loops]
        self.ticks = ticks
        self.n_max = np.array([int(lp.n_max) for lp in loops], dtype=np.intp)
        N = int(self.n_max.max()) if B else 0
        self.dt = dt = float(worlds[0].dt)
        if any(float(w.dt) != dt or float(t.dt) != dt for w, t in zip(worlds, ticks)):
            raise ValueError("the runs of a point-mass lockstep batch must share one period dt")
        self.inv_dt_world = 1.0 / dt
        # --- world: plant, object, sensor
        f = lambda seq: np.array(seq, dtype=float)  # noqa: E731
        self.x = f([[w.x, w.y] for w in worlds])
        self.v = f([[w.vx, w.vy] for w in worlds])
        self.wraw = f([[w.wx, w.wy] for w in worlds])
        self.seq = np.array([w._seq for w in worlds], dtype=np.int64)
        self.axv, self.avv = f([w._axv for w in worlds]), f([w._avv for w in worlds])
        self.bx, self.bv = f([w._bx for w in worlds]), f([w._bv for w in worlds])
        self.m = f([w._m for w in worlds])
        self.yaw = np.array([bool(w._yaw) for w in worlds])
        self.any_yaw = bool(self.yaw.any())
        self.rh, self.rc = f([w._rh for w in worlds]), f([w._rc for w in worlds])
        self.k_th, self.c_th, self.I_c = f([w._k_th for w in worlds]), f([w._c_th for w in worlds]), f([w._I_c for w in worlds])
        self.th = f([w._th for w in worlds])
        self.thd = f([w._thd for w in worlds])
        self.a_prev = f([[w._ax_prev, w._ay_prev] for w in worlds])
        self.sat = f([w._sat for w in worlds])
        self.bres = f([w._bres for w in worlds])
        self.fresh = _ragged([w._fresh for w in worlds], N + 1, False, bool)
        self.ns = np.stack([_ragged([w._nsx for w in worlds], N + 1), _ragged([w._nsy for w in worlds], N + 1)], axis=2)
        # --- the operators' arms
        arms = [w._arm for w in worlds]
        self.arm_n = np.array([a._n for a in arms], dtype=np.intp)
        L = int(self.arm_n.max())
        self.intent_xy = np.stack([_ragged([a._ix for a in arms], L), _ragged([a._iy for a in arms], L)], axis=2)
        self.noise_h = np.stack([_ragged([a._nx for a in arms], L), _ragged([a._ny for a in arms], L)], axis=2)
        self.delay = np.array([a.delay_ticks for a in arms], dtype=np.intp)
        self.err = np.zeros((B, N + 1, 2))  # e(k), for the delayed pathway e(k − d)
        self.ebar = f([a._ebar for a in arms])
        self.alpha = f([a._alpha for a in arms])
        prof = [a.profile for a in arms]
        self.k_min, self.k_gain, self.k_max = (f([getattr(p, n) for p in prof]) for n in ("stiffness_min", "stiffness_gain", "stiffness_max"))
        self.reflex = f([p.reflex_share for p in prof])
        self.one_minus_reflex = 1.0 - self.reflex
        self.damping = f([p.damping for p in prof])
        self.force_limit = f([p.force_limit for p in prof])
        # --- wrench pipelines (POINT_MASS_WRENCH: checks, bias, rotation; no filter or deadband)
        pipes = [t.wrench for t in ticks]
        self.max_age = f([p._max_age for p in pipes])
        self.frozen_checked = np.array([p._max_frozen is not None for p in pipes])
        self.max_f, self.sat_f, self.jump_f = f([p._max_f for p in pipes]), f([p._sat_f for p in pipes]), f([p._jump_f for p in pipes])
        self.bias = f([p._bias for p in pipes])  # (B, 6)
        self.pipe_seq = np.full(B, -1, dtype=np.int64)  # nothing seen yet (the world's counter starts at 0)
        self.seq_t = np.zeros(B)
        self.ref_raw = np.zeros((B, 2))  # the last accepted sample (the spike test's reference)
        self.has_ref = np.zeros(B, dtype=bool)
        self.held = np.zeros((B, 3))  # the hand force, base frame
        R = worlds[0].read().sensor_rotation
        self.R = [[float(R[r, c]) for c in range(3)] for r in range(3)]
        # --- the tick: start, references, controllers, intents
        refs = [t.references() for t in ticks]
        self.x0 = f([r.x0 for r in refs])
        self.H = np.array([t.H for t in ticks], dtype=np.intp)
        self.Hs = np.array([t.Hs for t in ticks], dtype=np.intp)
        rows = max(r.ref_ctrl.shape[0] for r in refs)
        self.ref_ctrl = _ragged_rows([r.ref_ctrl for r in refs], rows)
        self.ref_pos = _ragged_rows([r.ref_pos for r in refs], rows)
        self.ref_xy = _ragged_rows([r.ref_xy for r in refs], rows)
        self.safety_speed = f([t.safety.limits.tool_speed for t in ticks])
        self.f2 = f([t.safety._f2 for t in ticks])
        # Groups as arrays: run i's shared controller is self.ctrl_list[self.ctrl_gid[i]] (None:
        # each run steps its own), its model self.model_list[self.model_gid[i]] (−1: none shared).
        ctrl_groups = list(_groups([_stepper(t) for t in ticks]).values())
        self.ctrl_list = [c for c, _ in ctrl_groups]
        self.ctrl_gid = np.empty(B, dtype=np.intp)
        for g, (_, members) in enumerate(ctrl_groups):
            self.ctrl_gid[members] = g
        # runs with the online-α arbitration (stateful: no shared step_batch) sharing a guard:
        # one arbitrated_effort_batch per group and tick, each run on its own α
        # (a controller or game shared by two runs keeps the per-run order of update and step)
        self.arb_gid = np.full(B, -1, dtype=np.intp)
        keys: dict[tuple, int] = {}
        arbitrated = [i for i, t in enumerate(ticks)
                      if self.ctrl_list[self.ctrl_gid[i]] is None and type(t.controller) is ArbitratedController]  # fmt: skip
        uses: dict[int, int] = {}
        for i in arbitrated:
            for obj in (ticks[i].controller, ticks[i].controller.game):
                uses[id(obj)] = uses.get(id(obj), 0) + 1
        for i in arbitrated:
            c = ticks[i].controller
            if uses[id(c)] == 1 and uses[id(c.game)] == 1:
                self.arb_gid[i] = keys.setdefault(guard_key(c), len(keys))
        self.n_arb = len(keys)
        self.nominal = np.array([bool(t.intent.nominal) for t in ticks])
        # rows a prediction must have: the intent stage's need and the controller's horizon
        self.rows_needed = np.maximum([int(getattr(t.intent, "need", 0)) for t in ticks], self.H)
        batchers = [_batcher(t) for t in ticks]  # None: nominal, or an intent stage called alone
        model_groups = [g for g in _groups(batchers).values() if g[0] is not None]
        self.model_list = [batcher for batcher, _ in model_groups]
        self.model_gid = np.full(B, -1, dtype=np.intp)
        self.rings = []
        for g, (_, members) in enumerate(model_groups):
            self.model_gid[members] = g
            ring = _Ring(ticks[members[0]].intent.history, members, B)
            for i in members:
                if int(ticks[i].intent.history) != ring.L:
                    raise ValueError("runs sharing a model in the loop must share its history")
                if int(ticks[i].intent.horizon) != int(ticks[members[0]].intent.horizon):
                    raise ValueError("runs sharing a model in the loop must share its horizon")
            self.rings.append(ring)
        self.alone = [i for i in range(B) if not self.nominal[i] and batchers[i] is None]
        # --- termination
        terms: list[Any] = [lp.termination for lp in loops]  # TargetDwell or None (fast_path_eligible)
        self.has_term = np.array([t is not None for t in terms])
        self.target = f([(t.tx, t.ty) if t is not None else (0.0, 0.0) for t in terms])
        self.r2 = f([t.r2 if t is not None else 0.0 for t in terms])
        self.dwell_ticks = np.array([t.dwell_ticks if t is not None else 0 for t in terms], dtype=np.intp)
        self.after_tick = np.array([t.after_tick if t is not None else 0 for t in terms], dtype=np.intp)
        self.inside = np.zeros(B, dtype=np.intp)
        # --- logs
        self.pose_log = np.empty((B, N, 2))
        self.vel_log = np.empty((B, N, 2))
        self.wrench_log = np.empty((B, N, 2))
        self.ref_log = np.empty((B, N, 2))
        Hs_max = 0 if self.nominal.all() else int(self.Hs.max())  # the nominal runs log no prediction
        self.pred_log = np.full((B, N, Hs_max, 2), np.nan)
        self.eff_h_log = np.empty((B, N, 2))
        self.eff_r_log = np.empty((B, N, 2))
        self.compute = np.zeros((B, N))

    # ------------------------------------------------------------------ one tick
    def tick(self, k: int, act: np.ndarray) -> tuple[np.ndarray, list[tuple[int, str]]]:
        """Tick k for the runs ``act`` (indices, ascending): which go on, and (i, why) for those
        that ended; a run that leaves the fast path is neither (its log stays None)."""
        left = np.zeros(act.size, dtype=bool)  # leaves the fast path at this tick
        x, v = self.x[act], self.v[act]
        t = k * self.dt
        # 1. the wrench pipeline (WrenchPipeline._update on the point-mass world's reading)
        seq = self.seq[act]
        new = seq != self.pipe_seq[act]
        stale = ~new & (t - self.seq_t[act] > self.max_age[act])
        left |= stale
        w = self.wraw[act]
        left |= ~np.isfinite(w).all(axis=1)
        na = act[new]
        if na.size:
            self.pipe_seq[na] = seq[new]
            self.seq_t[na] = t
            wn = w[new]
            ref = self.ref_raw[na]
            repeat = (wn[:, 0] == ref[:, 0]) & (wn[:, 1] == ref[:, 1]) & self.has_ref[na] & self.frozen_checked[na]
            # the reading's f_z and torques are 0 (below every range and jump, which are > 0)
            mf = np.maximum(np.abs(wn[:, 0]), np.abs(wn[:, 1]))
            jf = self.jump_f[na]
            jump = self.has_ref[na] & ((np.abs(wn[:, 0] - ref[:, 0]) > jf) | (np.abs(wn[:, 1] - ref[:, 1]) > jf))
            bad = repeat | jump | (mf > self.max_f[na]) | (mf >= self.sat_f[na])
            left[np.flatnonzero(new)[bad]] = True
            self.ref_raw[na] = wn
            self.has_ref[na] = True
            b = self.bias[na]
            c0, c1, c2 = wn[:, 0] - b[:, 0], wn[:, 1] - b[:, 1], 0.0 - b[:, 2]
            R = self.R
            self.held[na, 0] = R[0][0] * c0 + R[0][1] * c1 + R[0][2] * c2
            self.held[na, 1] = R[1][0] * c0 + R[1][1] * c1 + R[1][2] * c2
            self.held[na, 2] = R[2][0] * c0 + R[2][1] * c1 + R[2][2] * c2
        hand = self.held[act]
        # the state's glitch check (tick.sense): a non-finite pose or twist is flagged
        left |= ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
        ref_pos = self.ref_pos[act, k]
        # 2. intent: the controllers' ref_h (B, Hmax, 4), the plan's rows where nothing is predicted
        B = act.size
        H = self.H[act]
        Hmax = int(H.max())
        ref_r_all = self.ref_ctrl[act, k + 1 : k + 1 + Hmax]
        ref_h_all = ref_r_all
        predicted: list[tuple[np.ndarray, np.ndarray]] = []  # (positions in act, positions (n, m, 2) in use)
        if self.model_list:
            gid = self.model_gid[act]
            rows = np.concatenate([x, v, hand[:, :2], ref_pos], axis=1)
            for g, batcher in enumerate(self.model_list):
                js = np.flatnonzero(gid == g)
                if not js.size:
                    continue
                ring = self.rings[g]
                windows = ring.push(k, ring.slot[act[js]], rows[js])
                try:
                    out = batcher.predict_batch(windows)
                    # WindowIntent.accept, row for row: ≥ need rows of (x, y), the first Hs finite
                    if not (isinstance(out, np.ndarray) and out.ndim == 3 and out.shape[0] == js.size and out.shape[2] == 2):
                        raise ValueError("malformed predictions")
                    p = out[:, : self.Hs[act[js[0]]]]  # the group's runs share the model's horizon
                    # fewer rows than the controller's horizon: the reference path decides
                    ok = (out.shape[1] >= self.rows_needed[act[js]]) & np.isfinite(p).all(axis=(1, 2))
                except Exception:  # the reference path predicts these rows one by one (and flags the failures)
                    left[js] = True
                    continue
                left[js[~ok]] = True
                if ok.any():
                    predicted.append((js[ok], p[ok]))
        if self.alone:
            at = np.full(self.H.size, -1, dtype=np.intp)
            at[act] = np.arange(B)
            for i in self.alone:
                j = int(at[i])
                if j < 0:
                    continue
                row = (x[j, 0], x[j, 1], v[j, 0], v[j, 1], hand[j, 0], hand[j, 1], ref_pos[j, 0], ref_pos[j, 1])
                answer, pf = self.ticks[i].predict(k, row)
                if pf or answer is None or answer.shape[0] < self.rows_needed[i]:
                    left[j] = True
                else:
                    predicted.append((np.array([j]), answer[None]))
        # 3. the controllers' arguments (ControlTick.control_inputs) and steps
        z = np.empty((B, 4))
        np.subtract(x, self.x0[act], out=z[:, :2])
        z[:, 2:] = v
        w2 = np.ascontiguousarray(hand[:, :2])
        u_r = np.zeros((B, 2))
        for js, p in predicted:  # ref_h from the positions: [x̂ − x0; finite-difference velocity]
            if ref_h_all is ref_r_all:
                ref_h_all = ref_r_all.copy()
            m = p.shape[1]
            buf = np.zeros((js.size, m, 4))
            np.subtract(p, self.x0[act[js]][:, None, :], out=buf[:, :, :2])
            if m >= 2:
                np.subtract(p[:, 1:], p[:, :-1], out=buf[:, 1:, 2:4])
                buf[:, 1:, 2:4] *= 1.0 / self.dt
                buf[:, 0, 2:4] = buf[:, 1, 2:4]
            h = min(m, Hmax)
            ref_h_all[js, :h] = buf[:, :h]
        cg = self.ctrl_gid[act]
        for g, controller in enumerate(self.ctrl_list):
            js = np.flatnonzero((cg == g) & ~left)
            if not js.size:
                continue
            if controller is None:  # each run's own controller (state between ticks)
                ag = self.arb_gid[act[js]]
                for a in range(self.n_arb):  # the arbitrated runs sharing a guard: one batched step, each its own α
                    sel = js[ag == a]
                    if sel.size:
                        h = int(H[sel[0]])
                        u, clean = arbitrated_effort_batch([self.ticks[i].controller for i in act[sel].tolist()], z[sel],
                                                           ref_h_all[sel, :h], ref_r_all[sel, :h], w2[sel])  # fmt: skip
                        left[sel[~clean]] = True
                        u_r[sel[clean]] = u[clean]
                for j in js[ag < 0].tolist():  # any other: its own step, its horizon
                    h = int(H[j])
                    s = self.ticks[act[j]].controller.step(z[j], ref_h_all[j, :h], ref_r_all[j, :h], w2[j])
                    if s[2]:
                        left[j] = True
                    else:
                        u_r[j] = s[0]
                continue
            h = int(H[js[0]])  # one controller, one horizon
            rr = ref_r_all[js, :h]
            rh = ref_h_all[js, :h]
            if js.size == 1:
                s = controller.step(z[js[0]], rh[0], rr[0], w2[js[0]])
                if s[2]:
                    left[js[0]] = True
                else:
                    u_r[js[0]] = s[0]
            else:
                u, clean = controller.effort_batch(z[js], rh, rr, w2[js])
                left[js[~clean]] = True
                u_r[js[clean]] = u[clean]
        # 4. safety, effort stage (SafetyLayer.limit_effort on a fault-free tick)
        f2 = hand[:, 0] * hand[:, 0] + hand[:, 1] * hand[:, 1] + hand[:, 2] * hand[:, 2]
        lim2 = self.f2[act]
        left |= f2 > lim2 * (1.0 - 1e-12)  # at the limit np.dot's rounding decides: the reference path does
        speed = np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1])
        along = u_r[:, 0] * v[:, 0] + u_r[:, 1] * v[:, 1]
        left |= (speed > self.safety_speed[act]) & (along > 0.0)
        left |= ~np.isfinite(u_r).all(axis=1)
        # 5. the world over one period (PointMassWorld.apply)
        fh = self._world(k, act, x, v, u_r)
        # 6. log row k and the termination rule
        self.pose_log[act, k] = x
        self.vel_log[act, k] = v
        self.wrench_log[act, k] = hand[:, :2]
        self.ref_log[act, k] = ref_pos
        for js, p in predicted:
            self.pred_log[act[js], k, : p.shape[1]] = p
        self.eff_r_log[act, k] = u_r
        self.eff_h_log[act, k] = fh
        ended: list[tuple[int, str]] = []
        term = self.has_term[act] & (k >= self.after_tick[act])
        d = x - self.target[act]
        inside = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) < self.r2[act]
        count = np.where(term, np.where(inside, self.inside[act] + 1, 0), self.inside[act])
        self.inside[act] = count
        done_target = term & inside & (count >= self.dwell_ticks[act])
        done_time = k + 1 >= self.n_max[act]
        go = ~left
        stop = go & (done_target | done_time)
        for j in np.flatnonzero(stop).tolist():
            ended.append((int(act[j]), "target" if done_target[j] else "time_limit"))
        return act[go & ~stop], ended

    def _world(self, k: int, act: np.ndarray, x: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        """One period of every run's world (PointMassWorld.apply); the hand forces u_h(k) (B, 2)."""
        dt = self.dt
        th, thd = self.th[act], self.thd[act]
        rh = self.rh[act]
        yaw = self.yaw[act]
        if self.any_yaw:
            p = np.where(yaw[:, None], np.stack([x[:, 0] - th * rh[:, 1], x[:, 1] + th * rh[:, 0]], axis=1), x)
            pv = np.where(yaw[:, None], np.stack([v[:, 0] - thd * rh[:, 1], v[:, 1] + thd * rh[:, 0]], axis=1), v)
        else:
            p, pv = x, v
        # the operator's arm (OperatorArm.force)
        i = np.minimum(k, self.arm_n[act] - 1)
        e = self.intent_xy[act, i] - p
        self.err[act, k] = e
        delay = self.delay[act]
        old = np.where(k >= delay, k - delay, 0)
        de = self.err[act, old]
        ebar = self.ebar[act]
        ebar = ebar + self.alpha[act] * (np.sqrt(e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1]) - ebar)
        self.ebar[act] = ebar
        K = self.k_min[act] + self.k_gain[act] * ebar
        kmax = self.k_max[act]
        K = np.where(K > kmax, kmax, K)
        b = self.reflex[act][:, None]
        fh = K[:, None] * (self.one_minus_reflex[act][:, None] * e + b * de) - self.damping[act][:, None] * pv + self.noise_h[act, i]
        norm = np.sqrt(fh[:, 0] * fh[:, 0] + fh[:, 1] * fh[:, 1])
        lim = self.force_limit[act]
        over = norm > lim
        if over.any():
            scale = lim[over] / norm[over]
            fh[over] *= scale[:, None]
        # plant and sensor
        m = self.m[act]
        ns = self.ns[act, k + 1]
        bres = self.bres[act]
        c = np.zeros_like(x)
        if self.any_yaw and yaw.any():
            rc = self.rc[act]
            ap = self.a_prev[act]
            tau = rh[:, 0] * fh[:, 1] - rh[:, 1] * fh[:, 0] - m * (rc[:, 0] * ap[:, 1] - rc[:, 1] * ap[:, 0])
            thdd = (tau - self.k_th[act] * th - self.c_th[act] * thd) / self.I_c[act]
            thd_new = thd + thdd * dt
            th_new = th + thd_new * dt
            self.thd[act] = np.where(yaw, thd_new, thd)
            self.th[act] = np.where(yaw, th_new, th)
            c = np.where(yaw[:, None], np.stack([m * thdd * rc[:, 1], -m * thdd * rc[:, 0]], axis=1), 0.0)
        f = fh + u + ns + bres + c
        v_new = self.avv[act] * v + self.bv[act] * f
        x_new = x + self.axv[act] * v + self.bx[act] * f
        a_prev = (v_new - v) * self.inv_dt_world
        self.a_prev[act] = a_prev
        fresh = self.fresh[act, k + 1]
        if fresh.any():
            fa = act[fresh]
            s = fh[fresh] - m[fresh, None] * a_prev[fresh] + c[fresh] + ns[fresh] + bres[fresh]
            sat = self.sat[fa][:, None]
            self.wraw[fa] = np.where(s > sat, sat, np.where(s < -sat, -sat, s))
            self.seq[fa] += 1
        self.x[act], self.v[act] = x_new, v_new
        return fh

    def log(self, i: int, n: int, ended: str) -> LoopLog:
        tick = self.ticks[i]
        Hs = int(self.Hs[i])
        return LoopLog(
            pose=self.pose_log[i, :n].copy(), velocity=self.vel_log[i, :n].copy(), wrench=self.wrench_log[i, :n].copy(),
            reference=self.ref_log[i, :n].copy(),
            prediction=None if tick.intent.nominal else self.pred_log[i, :n, :Hs].copy(),
            effort_h=self.eff_h_log[i, :n].copy(), effort_r=self.eff_r_log[i, :n].copy(),
            fault=np.zeros(n, dtype=np.int64), joints=None, joint_velocity=None, compute=self.compute[i, :n].copy(),
            ended=ended,
        )  # fmt: skip


class _Ring:
    """The feature windows of the runs sharing one model: (B, 2L, 8), ``WindowIntent.push``'s layout."""

    def __init__(self, L: int, members: list[int], n_runs: int) -> None:
        self.L = int(L)
        self.slot = np.full(n_runs, -1, dtype=np.intp)  # run index -> its row here
        self.slot[members] = np.arange(len(members))
        self.hist = np.zeros((len(members), 2 * self.L, 8))

    def push(self, k: int, slots: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Store tick k's rows (len(slots), 8); the runs' windows (len(slots), L, 8), oldest first."""
        L = self.L
        if L <= 0:
            return np.zeros((slots.size, 0, 8))
        if k == 0:
            self.hist[slots] = rows[:, None, :]  # pad: the robot was at rest before tick 0
        i = k % L
        self.hist[slots, i] = rows
        self.hist[slots, i + L] = rows
        return self.hist[slots, i + 1 : i + 1 + L]


def _ragged(seqs: Sequence[Sequence[Any]], n: int, fill: Any = 0.0, dtype: Any = float) -> np.ndarray:
    out = np.full((len(seqs), n), fill, dtype=dtype)
    for b, s in enumerate(seqs):
        m = min(len(s), n)
        out[b, :m] = s[:m]
    return out


def _ragged_rows(arrays: Sequence[np.ndarray], n: int) -> np.ndarray:
    """(B, n, ...) with each array's rows, padded with its last row."""
    out = np.empty((len(arrays), n, *arrays[0].shape[1:]))
    for b, a in enumerate(arrays):
        out[b, : a.shape[0]] = a
        out[b, a.shape[0] :] = a[-1]
    return out


def _groups(keys: Sequence[Any]) -> dict[int, tuple[Any, list[int]]]:
    """Runs grouped by a shared object (by identity), in order; None keys: one group of runs
    each stepping its own."""
    out: dict[int, tuple[Any, list[int]]] = {}
    for i, key in enumerate(keys):
        out.setdefault(id(key), (key, []))[1].append(i)
    return out
