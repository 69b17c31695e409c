"""Point-mass trials in lockstep as arrays: every stage of the tick for B trials at once.

:func:`~coassist.runtime.batched_loops.run_loops` runs B trials tick by tick, but each trial's
world, operator, wrench pipeline, tick and safety layer still do their own scalar Python
every tick (a few hundred microseconds per trial-tick); only the network and the shared
controller are called once for all. Here the simulated :class:`~coassist.sim.point_mass.PointMassWorld`
trials of a group advance as arrays of shape (B, ·): per tick k, for the trials still going::

    read      x, v (B, 2), the sensor's latest sample w (B, 2), its counter
    wrench    new sample? stale? frozen? spike? saturated?    WrenchPipelineBatch (runtime.wrench)
    intent    rows (B, 8) → one ring buffer per model → one predict_batch call (models);
              WindowIntentBatch (runtime.intent); the tick's own intent stage per trial
              (oracle, constant velocity); none (nominal)
    control   z = [x − x0; v], ref_h from the predictions (human_reference, runtime.tick),
              ref_r from the plan → one effort_batch per shared controller; one
              arbitrated_effort_batch per group of online-α runs (each its own α); one
              probed_efforts per group of calibration runs (MG + the probe: each its own
              push); any other stateful one: its own step per trial
    safety    contact force, tool speed (the effort stage)   SafetyLayerBatch (runtime.safety)
    world     operator arm (eq. 4.1: delay, adaptation, noise, force limit), board yaw,
              exact ZOH plant, the sensor's next sample        PointMassWorldBatch (sim.point_mass),
              OperatorArmBatch (scenario.operator), plant_step (model.plant)
    log       row k; the target-dwell rule                    TargetDwellBatch (runtime.loop)

Each stage is the array twin of the per-trial stage, written beside it in the same module
(with a test there that its rows equal the scalar code's, bit for bit): every formula the
scalar code's own, elementwise in the same order of operations (numpy's elementwise
+ − × ÷ and sqrt are IEEE operations, as Python's), and where one formula serves both
(the plant step, ref_h, the operator's force, the board, the sensor) written once; the
window's ring, the wrench checks, the safety checks and the dwell rule are written twice,
the twin beside its original and tested row for row against it. This
module only orchestrates them, so a trial here gives what the per-trial loop gives bit
for bit. The controller is the same object's ``effort_batch`` (row for row its ``step``;
the online-α ones :func:`~coassist.control.arbitration.arbitrated_effort_batch`, row for
row each run's ``step``), the network the same batcher.

The fast path covers the fault-free tick, which is every tick of every simulated trial
in practice (no fault bit in any of 138 trials sampled from a full ``coassist reproduce``).
A trial in which anything unusual happens — any fault flag (a stale, frozen, spiking or
saturated sensor, a prediction fallback, a saturated or refusing controller, the tool
speed or contact limit), a non-finite state, a batched call that raises — leaves the fast
path at that tick: :func:`run_point_mass_lockstep` returns None for it, and the caller runs
it again from its spec on the reference path (:func:`coassist.sim.trial_runner.run_spec_lockstep`
does), which handles every branch. The result is the reference path's trial either way.

With a model in the loop the network's float32 rows depend on the batch (see
:mod:`coassist.runtime.batched_loops`): here the batch holds the same trials in the same order as
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
from coassist.control.probe import probed_efforts
from coassist.interfaces import Fault
from coassist.runtime.batched_loops import Loop, intent_batcher, probed_groups, shared_controller
from coassist.runtime.intent import WindowIntent, WindowIntentBatch, accept_together
from coassist.runtime.loop import LoopLog, TargetDwellBatch, alpha_reader
from coassist.runtime.safety import SafetyLayerBatch
from coassist.runtime.tick import human_reference
from coassist.runtime.wrench import WrenchPipelineBatch
from coassist.sim.point_mass import PointMassWorldBatch

__all__ = ["fast_path_eligible", "run_point_mass_lockstep"]


def fast_path_eligible(loop: Loop) -> bool:
    """Whether a run can take the array path: a fresh :class:`~coassist.sim.point_mass.PointMassWorld`
    under an effort tick on x-y, the point-mass wrench pipeline (no filter, deadband, payload
    or zeroing), a safety layer that has not stopped, the target-dwell rule (or none): each
    stage one its array twin takes (``accepts``)."""
    tick = loop.tick
    if not PointMassWorldBatch.accepts(loop.world):
        return False
    if tick.command_space != "effort" or tick.config.dofs != (0, 1):
        return False
    # any intent stage: nominal, a shared model's batcher, or the tick's own predict() per run
    return (
        WrenchPipelineBatch.accepts(tick.wrench)
        and SafetyLayerBatch.accepts(tick.safety)
        and TargetDwellBatch.accepts(loop.termination)
    )


def run_point_mass_lockstep(
    loops: Sequence[Loop],
    clock: Callable[[], float] = time.perf_counter,
    on_end: Callable[[int, LoopLog], None] | None = None,
) -> list[LoopLog | None]:
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
    """The B runs as the array twins of their stages, the groups that share a call, and the logs."""

    def __init__(self, loops: Sequence[Loop]) -> None:
        B = len(loops)
        ticks = [lp.tick for lp in loops]
        self.ticks = ticks
        self.n_max = np.array([int(lp.n_max) for lp in loops], dtype=np.intp)
        N = int(self.n_max.max()) if B else 0
        # --- the stages' array twins (each beside its original, row for row the same floats)
        worlds: list[Any] = [lp.world for lp in loops]  # PointMassWorlds (fast_path_eligible)
        self.world = PointMassWorldBatch(worlds)
        self.dt = dt = self.world.dt
        if any(float(t.dt) != dt for t in ticks):
            raise ValueError("the runs of a point-mass lockstep batch must share one period dt")
        self.wrench = WrenchPipelineBatch([t.wrench for t in ticks], self.world.sensor_rotation)
        self.safety = SafetyLayerBatch([t.safety for t in ticks])
        rules: list[Any] = [lp.termination for lp in loops]  # TargetDwell or None (fast_path_eligible)
        self.dwell = TargetDwellBatch(rules)
        # --- the tick: start, references, controllers, intents
        refs = [t.references() for t in ticks]
        self.x0 = np.array([r.x0 for r in refs], dtype=float)
        self.H = np.array([t.H for t in ticks], dtype=np.intp)
        self.Hs = np.array([t.Hs for t in ticks], dtype=np.intp)
        rows = max(r.ref_ctrl.shape[0] for r in refs)
        self.ref_ctrl = _ragged_rows([r.ref_ctrl for r in refs], rows)
        self.ref_pos = _ragged_rows([r.ref_pos for r in refs], rows)
        # Groups as arrays: run i's shared controller is self.ctrl_list[self.ctrl_gid[i]] (None:
        # each run steps its own), its model self.model_list[self.model_gid[i]] (−1: none shared).
        ctrl_groups = list(_groups([shared_controller(t) for t in ticks]).values())
        self.ctrl_list = [c for c, _ in ctrl_groups]
        self.ctrl_gid = np.empty(B, dtype=np.intp)
        for g, (_, members) in enumerate(ctrl_groups):
            self.ctrl_gid[members] = g
        # runs with the online-α arbitration (stateful: no shared step_batch) sharing a guard:
        # one arbitrated_effort_batch per group and tick, each run on its own α
        # (a controller or game shared by two runs keeps the per-run order of update and step)
        self.arb_gid = np.full(B, -1, dtype=np.intp)
        keys: dict[tuple, int] = {}
        arbitrated = [
            i
            for i, t in enumerate(ticks)
            if self.ctrl_list[self.ctrl_gid[i]] is None and type(t.controller) is ArbitratedController
        ]
        uses: dict[int, int] = {}
        for i in arbitrated:
            for obj in (ticks[i].controller, ticks[i].controller.game):
                uses[id(obj)] = uses.get(id(obj), 0) + 1
        for i in arbitrated:
            c = ticks[i].controller
            if uses[id(c)] == 1 and uses[id(c.game)] == 1:
                self.arb_gid[i] = keys.setdefault(guard_key(c), len(keys))
        self.n_arb = len(keys)
        # calibration runs (MG + the probe, each its own clock and phases) of one probe_key: one probed_efforts a tick
        probed = probed_groups(ticks)
        self.probe_gid = np.array([-1 if g is None else g for g in probed], dtype=np.intp)
        self.n_probe = int(self.probe_gid.max(initial=-1)) + 1
        self.nominal = np.array([bool(t.intent.nominal) for t in ticks])
        # rows a prediction must have: the intent stage's need and the controller's horizon
        self.rows_needed = np.maximum([int(getattr(t.intent, "need", 0)) for t in ticks], self.H)
        batchers = [intent_batcher(t) for t in ticks]  # None: nominal, or an intent stage called alone
        model_groups = [g for g in _groups(batchers).values() if g[0] is not None]
        self.model_list = [batcher for batcher, _ in model_groups]
        self.model_gid = np.full(B, -1, dtype=np.intp)
        self.model_slot = np.full(B, -1, dtype=np.intp)  # run i's row in its group's WindowIntentBatch
        self.windows = []
        for g, (_, members) in enumerate(model_groups):
            self.model_gid[members] = g
            self.model_slot[members] = np.arange(len(members))
            self.windows.append(WindowIntentBatch([ticks[i].intent for i in members]))
        self.alone = [i for i in range(B) if not self.nominal[i] and batchers[i] is None]
        # --- logs
        self.pose_log = np.empty((B, N, 2))
        self.vel_log = np.empty((B, N, 2))
        self.wrench_log = np.empty((B, N, 2))
        self.ref_log = np.empty((B, N, 2))
        Hs_max = 0 if self.nominal.all() else int(self.Hs.max())  # the nominal runs log no prediction
        # filled row by row as the runs tick (NaN, then the rows predicted): a (B, N, H, 2) np.full
        # here wrote tens of MB per group at the time limit's N, most of it never read
        self.pred_log = np.empty((B, N, Hs_max, 2))
        self.eff_h_log = np.empty((B, N, 2))
        self.eff_r_log = np.empty((B, N, 2))
        self.compute = np.zeros((B, N))
        # the game's α each tick (LoopLog.alpha), read as LoopRun reads it: an arbitration moves it, and so may what
        # wraps one (decel-damping's), so every run's is read every tick, not only an ArbitratedController's
        self.alpha_of = [alpha_reader(t.controller) for t in ticks]
        self.has_alpha = np.array([r is not None for r in self.alpha_of], dtype=bool)
        self.alpha_log = np.zeros((B, N)) if self.has_alpha.any() else None
        # what a tick reads of the runs still going that only changes when one ends (_Rows)
        self._rows: _Rows | None = None

    # ------------------------------------------------------------------ one tick
    def tick(self, k: int, act: np.ndarray) -> tuple[np.ndarray, list[tuple[int, str]]]:
        """Tick k for the runs ``act`` (indices, ascending): which go on, and (i, why) for those
        that ended; a run that leaves the fast path is neither (its log stays None)."""
        world = self.world
        rows = self._rows
        if rows is None or not rows.holds(act):
            rows = self._rows = _Rows(self, act)
        x, v = world.position[act], world.velocity[act]
        # 1. the wrench pipeline on the world's reading (a row it cannot answer for leaves)
        hand, clean = self.wrench.update(act, world.wrench[act], world.wrench_seq[act], k * self.dt)
        left = ~clean  # leaves the fast path at this tick
        # the state's glitch check (tick.sense): a non-finite pose or twist is flagged
        left |= ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
        ref_pos = self.ref_pos[act, k]
        # 2. intent: the controllers' ref_h (B, Hmax, 4), the plan's rows where nothing is predicted
        B = act.size
        H = rows.H
        Hmax = rows.Hmax
        ref_r_all = self.ref_ctrl[act, k + 1 : k + 1 + Hmax]
        ref_h_all = ref_r_all
        predicted: list[tuple[np.ndarray, np.ndarray]] = []  # (positions in act, positions (n, m, 2) in use)
        if self.model_list:
            features = np.concatenate([x, v, hand[:, :2], ref_pos], axis=1)
            for g, js, slots, needed in rows.models:
                batcher = self.model_list[g]
                windows = self.windows[g]
                try:
                    p, ok = windows.accept(slots, batcher.predict_batch(windows.push(k, slots, features[js])))
                    # fewer rows than the controller's horizon: the reference path decides
                    ok &= p.shape[1] >= needed
                except Exception:  # the reference path predicts these rows one by one (and flags the failures)
                    left[js] = True
                    continue
                left[js[~ok]] = True
                if ok.any():
                    predicted.append((js[ok], p[ok]))
        if self.alone:
            # each run's own source (a filter with a trial's state), one at a time; their rows then go to
            # human_reference together, grouped by how many rows they give (elementwise: the same values; rows.alone
            # is in ascending positions, so a group of every run is act's order, as the paths below assume)
            answered: dict[int, tuple[list[int], list[np.ndarray]]] = {}
            # a window stage's answer is checked with the others' (accept_together: each stage's accept, bit for bit)
            waiting: list[tuple[int, int]] = []
            stages: list[WindowIntent] = []
            answers: list = []
            results: list[tuple[int, int, tuple[np.ndarray | None, Fault]]] = []
            for i, j in rows.alone:
                row = (x[j, 0], x[j, 1], v[j, 0], v[j, 1], hand[j, 0], hand[j, 1], ref_pos[j, 0], ref_pos[j, 1])
                stage = self.ticks[i].intent
                if type(stage) is WindowIntent:
                    waiting.append((i, j))
                    stages.append(stage)
                    answers.append(stage.answer(k, row))
                else:
                    results.append((i, j, self.ticks[i].predict(k, row)))
            if waiting:
                results += [(i, j, r) for (i, j), r in zip(waiting, accept_together(stages, answers))]
                results.sort(key=lambda r: r[1])  # act's order, as rows.alone gives it
            for i, j, (answer, pf) in results:
                if pf or answer is None or answer.shape[0] < self.rows_needed[i]:
                    left[j] = True
                else:
                    js_m, ps_m = answered.setdefault(answer.shape[0], ([], []))
                    js_m.append(j)
                    ps_m.append(answer)
            for js_m, ps_m in answered.values():
                predicted.append((np.array(js_m), np.stack(ps_m)))
        # 3. the controllers' arguments (ControlTick.control_inputs) and steps
        z = np.empty((B, 4))
        x0 = rows.x0
        np.subtract(x, x0, out=z[:, :2])
        z[:, 2:] = v
        w2 = np.ascontiguousarray(hand[:, :2])
        u_r = np.zeros((B, 2))
        inv_dt = 1.0 / self.dt
        if len(predicted) == 1 and predicted[0][0].size == B and predicted[0][1].shape[1] == Hmax:
            # one group predicted every row over the whole horizon (a shared model): human_reference
            # writes every entry of every row, so straight into ref_h (the same values as through a buffer)
            ref_h_all = np.empty_like(ref_r_all)
            human_reference(predicted[0][1], x0, inv_dt, ref_h_all)
            predicted_rows = []
        else:
            predicted_rows = predicted
        for js, p in predicted_rows:  # ref_h from the positions (the tick's own human_reference)
            if ref_h_all is ref_r_all:
                ref_h_all = ref_r_all.copy()
            m = p.shape[1]
            buf = np.zeros((js.size, m, 4))
            human_reference(p, x0[js], inv_dt, buf)
            h = min(m, Hmax)
            ref_h_all[js, :h] = buf[:, :h]
        for g, members in rows.controllers:
            controller = self.ctrl_list[g]
            js = members[~left[members]]
            if not js.size:
                continue
            if controller is None:  # each run's own controller (state between ticks)
                ag, pg = rows.arb_gid[js], rows.probe_gid[js]
                # the arbitrated runs sharing a guard (each its own α), the calibration runs of one probe key (each
                # its own push): one batched step per group
                for gid, n_groups, batch in (
                    (ag, self.n_arb, arbitrated_effort_batch),
                    (pg, self.n_probe, probed_efforts),
                ):
                    for a in range(n_groups):
                        sel = js[gid == a]
                        if sel.size:
                            h = int(H[sel[0]])
                            u, ok = batch(
                                [self.ticks[i].controller for i in act[sel].tolist()],
                                z[sel],
                                ref_h_all[sel, :h],
                                ref_r_all[sel, :h],
                                w2[sel],
                            )
                            left[sel[~ok]] = True
                            u_r[sel[ok]] = u[ok]
                for j in js[(ag < 0) & (pg < 0)].tolist():  # any other: its own step, its horizon
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
                u, ok = controller.effort_batch(z[js], rh, rr, w2[js])
                left[js[~ok]] = True
                u_r[js[ok]] = u[ok]
        # 4. safety, effort stage (SafetyLayer.limit_effort on a fault-free tick)
        left |= ~self.safety.limit_effort(act, u_r, v, hand)
        # 5. the world over one period (PointMassWorld.apply)
        fh = world.apply(k, act, u_r)
        # 6. log row k and the termination rule
        self.pose_log[act, k] = x
        self.vel_log[act, k] = v
        self.wrench_log[act, k] = hand[:, :2]
        self.ref_log[act, k] = ref_pos
        Hs_max = self.pred_log.shape[2]
        if len(predicted) == 1 and predicted[0][0].size == B and predicted[0][1].shape[1] >= Hs_max:
            # one group predicted every row's whole width (a shared model): nothing of row k stays NaN
            # (positions in act ascending and distinct: the same rows as act)
            self.pred_log[act, k] = predicted[0][1][:, :Hs_max]
        else:
            if Hs_max:
                self.pred_log[act, k] = np.nan
            for js, p in predicted:
                self.pred_log[act[js], k, : p.shape[1]] = p
        self.eff_r_log[act, k] = u_r
        if self.alpha_log is not None:
            read = act[self.has_alpha[act]]
            self.alpha_log[read, k] = [self.alpha_of[i]() for i in read.tolist()]
        self.eff_h_log[act, k] = fh
        done_target = self.dwell(k, act, x)
        done_time = k + 1 >= rows.n_max
        go = ~left
        stop = go & (done_target | done_time)
        ended = [(int(act[j]), "target" if done_target[j] else "time_limit") for j in np.flatnonzero(stop).tolist()]
        return act[go & ~stop], ended

    def log(self, i: int, n: int, ended: str) -> LoopLog:
        tick = self.ticks[i]
        Hs = int(self.Hs[i])
        return LoopLog(
            pose=self.pose_log[i, :n].copy(),
            velocity=self.vel_log[i, :n].copy(),
            wrench=self.wrench_log[i, :n].copy(),
            reference=self.ref_log[i, :n].copy(),
            prediction=None if tick.intent.nominal else self.pred_log[i, :n, :Hs].copy(),
            effort_h=self.eff_h_log[i, :n].copy(),
            effort_r=self.eff_r_log[i, :n].copy(),
            fault=np.zeros(n, dtype=np.int64),
            joints=None,
            joint_velocity=None,
            compute=self.compute[i, :n].copy(),
            ended=ended,
            alpha=self._alpha(i, n),
        )

    def _alpha(self, i: int, n: int) -> np.ndarray | None:
        """Run ``i``'s first ``n`` α (None: its controller has none), as :class:`~coassist.runtime.loop.LoopRun` logs them."""
        return None if self.alpha_log is None or not self.has_alpha[i] else self.alpha_log[i, :n].copy()


class _Rows:
    """What a tick reads of the runs ``act`` still going that changes only when one of them ends:
    their constants (x0, H, n_max, the arbitration groups), the largest horizon, and per
    model or controller group the positions in ``act`` of its runs (ascending), their window
    slots and the prediction rows they need, and the runs whose intent stage is called alone."""

    def __init__(self, batch: _Batch, act: np.ndarray) -> None:
        self.act = act.copy()
        self.x0 = batch.x0[act]
        self.H = batch.H[act]
        self.Hmax = int(self.H.max())
        self.n_max = batch.n_max[act]
        self.arb_gid = batch.arb_gid[act]
        self.probe_gid = batch.probe_gid[act]
        gid = batch.model_gid[act]
        self.models = []
        for g in range(len(batch.model_list)):
            js = np.flatnonzero(gid == g)
            if js.size:
                self.models.append((g, js, batch.model_slot[act[js]], batch.rows_needed[act[js]]))
        cg = batch.ctrl_gid[act]
        self.controllers = [(g, np.flatnonzero(cg == g)) for g in range(len(batch.ctrl_list))]
        at = np.full(batch.H.size, -1, dtype=np.intp)
        at[act] = np.arange(act.size)
        self.alone = [(i, int(at[i])) for i in batch.alone if at[i] >= 0]

    def holds(self, act: np.ndarray) -> bool:
        """Whether these are the runs ``act`` (the same indices in the same order)."""
        return act.shape == self.act.shape and bool((act == self.act).all())


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
