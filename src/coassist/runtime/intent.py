"""The intent stage of the tick: ŷ_ref,h from a window-based source or the real-time predictor.

Two kinds of predictor plug into the loop through :class:`TickIntent`:

- :class:`WindowIntent` wraps an :class:`~coassist.interfaces.IntentSource` (the
  simulator's sources, a trained model computed inside the tick): the stage keeps the
  last ``history`` feature rows in a ring buffer twice as long (so every window is one
  contiguous slice) and calls ``predict`` once per tick. Deterministic.
- :class:`RealtimeIntent` wraps a :class:`coassist.intent.RealtimePredictor` (duck-typed
  here: ``tick(sample, nominal)``, ``horizon``, ``errors``; ``worker_alive`` if it
  has one), which never waits for the network. For real robots and paced worlds.

Both return the (H, 2) predicted positions in use at tick k for ticks k+1 … k+H [m], or
None (fallback: the loop uses the nominal reference, eq. 4.7), and the tick's flags:
PREDICTION_FALLBACK, PREDICTION_STALE, and PREDICTOR_STALLED once the predictor has
given nothing usable for ``stall_ticks`` ticks in a row after its history filled (a
hung network, implausible rows), and at once on a tick whose worker is dead or whose
real-time prediction failed (raised, non-finite or misshapen: a network that gave NaN once is
not trusted with the next, though a prediction still in use may be fresh enough). A stalled
predictor is a bad tick for the safety layer: the robot decelerates, and stops if it persists.

What a row may ask of the controller is bounded: either stage uses a prediction only when it
is an array of real numbers (float or int; complex, object, boolean or string answers are a
failing source's), finite *and* plausible for a hand (:func:`coassist.interfaces.prediction_plausible`
against the tool's position of the row pushed: every row within
``PlausibilityLimits.max_distance`` of the tool, consecutive rows no faster than
``max_speed``). The real-time stage checks this itself, whatever its predictor checked. Anything
else is a fault (PREDICTION_FALLBACK, and PREDICTOR_STALLED when it persists), never a push
toward it nor a tick that fails on it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from coassist._checks import check_int_at_least
from coassist.interfaces import FEATURES, Fault, IntentSource, PlausibilityLimits, TrialContext, missing_members

__all__ = ["RealtimeIntent", "TickIntent", "WindowIntent", "WindowIntentBatch", "accept_together"]

_N_FEATURES = len(FEATURES)
_FALLBACK = Fault.PREDICTION_FALLBACK
_FALLBACK_I, _STALE_I, _STALLED_I = int(_FALLBACK), int(Fault.PREDICTION_STALE), int(Fault.PREDICTOR_STALLED)


class TickIntent(Protocol):
    """What the tick asks of its intent stage."""

    horizon: int  # rows of positions returned
    model_id: str | None
    nominal: bool  # True: the source is the nominal plan itself (ref_h = ref_r exactly)
    reads_true_intent: bool  # the source reads TrialContext.true_intent (the oracle: simulation only)

    def reset(self, context: TrialContext) -> None: ...

    def update(self, k: int, row: tuple[float, ...], nominal: np.ndarray) -> tuple[np.ndarray | None, Fault]:
        """Push tick k's feature row (8 floats, FEATURES order); get (positions or None, flags)."""
        ...


class WindowIntent:
    """A window-based :class:`IntentSource` inside the tick (module docstring).

    Parameters
    ----------
    source : the predictor.
    horizon : rows the controller needs (the source must give at least these).
    stall_ticks : consecutive unusable predictions (after the history has filled)
        that make the predictor stalled (≥ 1).
    plausibility : what a prediction may look like (module docstring): rows farther from the
        tool, or faster, are a fallback.
    """

    def __init__(
        self,
        source: IntentSource,
        horizon: int,
        stall_ticks: int = 25,
        plausibility: PlausibilityLimits | None = None,
    ) -> None:
        if plausibility is not None and not isinstance(plausibility, PlausibilityLimits):
            raise ValueError(f"plausibility must be a PlausibilityLimits, got {type(plausibility).__name__}")
        self.plausibility = PlausibilityLimits() if plausibility is None else plausibility
        if not isinstance(source, IntentSource):
            raise ValueError(
                f"intent source must implement IntentSource, got {type(source).__name__}, which lacks "
                f"{', '.join(missing_members(source, IntentSource))}"
            )
        self.source = source
        self.need = check_int_at_least(horizon, "horizon", 1)
        self.horizon = int(source.horizon)
        if self.horizon < self.need:
            raise ValueError(f"intent source horizon ({self.horizon}) must be >= the controller's ({self.need})")
        self.history = int(source.history)
        self.model_id = source.model_id
        self.stall_ticks = check_int_at_least(stall_ticks, "stall_ticks", 1)
        # model_id None means the nominal plan (IntentSource's contract): ref_h is then the
        # planner's own rows (analytic velocities), as eq. 4.7 means, and nothing is predicted.
        self.nominal = source.model_id is None
        # the episode hands the simulated operator's intent to a source that declares it reads it, and no other
        self.reads_true_intent = getattr(source, "reads_true_intent", False) is True
        L = self.history
        self._hist = np.zeros((2 * L, _N_FEATURES)) if L > 0 else np.zeros((0, _N_FEATURES))
        self._empty = self._hist[:0]
        self._empty.setflags(write=False)
        self._bad = 0
        self._x = self._y = 0.0  # the tool's position in the row pushed last [m]
        self.max_step = math.inf  # the most consecutive rows may move apart [m] (max_speed · dt, from reset)

    def reset(self, context: TrialContext) -> None:
        self.source.reset(context)
        self._bad = 0
        self.max_step = self.plausibility.max_speed * float(context.dt)

    def update(self, k: int, row: tuple[float, ...], nominal: np.ndarray) -> tuple[np.ndarray | None, Fault]:
        return self.accept(self.answer(k, row))

    def answer(self, k: int, row: tuple[float, ...]) -> Any:
        """Push tick k's row and get the source's answer as it gave it, unchecked (None where it raised): the
        first half of :meth:`update`, whose :meth:`accept` a runner may do for many stages at once
        (:func:`accept_together`)."""
        window = self.push(k, row)
        try:
            return self.source.predict(window)
        except Exception:  # a failing predictor must not stop the loop
            return None

    # The two halves of :meth:`update`, for a runner that batches the network call over
    # trials (coassist.runtime.batched_loops): push the row, predict elsewhere, accept the result.
    @property
    def batcher(self) -> Any:
        """The object whose ``predict_batch(windows (B, history, 8)) -> (B, horizon, 2)`` serves
        this stage's predictions, row for row what ``source.predict`` gives (up to the float
        rounding of batched kernels); None when the source has none (it is called alone)."""
        return getattr(self.source, "batcher", None)

    def push(self, k: int, row: tuple[float, ...]) -> np.ndarray:
        """Store tick k's feature row; the window the source predicts from, (history, 8), oldest
        first: a view of the ring buffer, valid until the next push."""
        self._x, self._y = row[0], row[1]
        L = self.history
        if L <= 0:
            return self._empty
        hist = self._hist
        if k == 0:
            hist[:] = row  # pad: the robot was at rest before tick 0
        i = k % L
        hist[i] = row
        hist[i + L] = row
        return hist[i + 1 : i + 1 + L]

    def accept(self, pred: Any) -> tuple[np.ndarray | None, Fault]:
        """The source's answer for the last pushed window (None: it raised) → (positions or None, flags).

        Only an array of real numbers is positions (:func:`_real_positions`): a complex, object, boolean
        or string answer is a fallback, never a clean row that the tick's arithmetic then fails on."""
        try:
            ok = isinstance(pred, np.ndarray) and pred.ndim == 2 and pred.shape[0] >= self.need and pred.shape[1] == 2
            if ok:
                pred = _real_positions(pred)
                ok = pred is not None and self._plausible(pred[: self.horizon])
        except Exception:  # a malformed answer is a fallback like any other
            ok = False
        if ok:
            self._bad = 0
            return pred[: self.horizon], Fault.NONE
        self._bad += 1
        return None, (_FALLBACK | Fault.PREDICTOR_STALLED) if self._bad > self.stall_ticks else _FALLBACK

    def _plausible(self, p: np.ndarray) -> bool:
        """:func:`~coassist.interfaces.prediction_plausible` of float64 rows (m, 2) against the tool of
        the row pushed last (:func:`_plausible_rows`)."""
        return _plausible_rows(p, self._x, self._y, self.plausibility.max_distance, self.max_step)


def _real_positions(pred: np.ndarray) -> np.ndarray | None:
    """``pred`` as float64 when its dtype is a real number's (float, signed or unsigned int), else None.

    A complex, object, boolean or string array is no position a controller can follow: a source
    that gives one is failing, and its answer is a fallback (an object array of floats too: the
    tick's arithmetic needs numbers, not what a source's elements may turn out to be). float64,
    the dtype of every source the loop ships, is returned as it is (no copy, so nothing a
    fault-free run computes changes); another real dtype is converted (exact for float16/32).
    """
    if pred.dtype == np.float64:
        return pred
    if pred.dtype.kind not in "fiu":
        return None
    return pred.astype(np.float64)


def _plausible_rows(p: np.ndarray, x: float, y: float, lim: float, max_step: float) -> bool:
    """:func:`~coassist.interfaces.prediction_plausible` of float64 rows p (m, 2), written for the tick:
    every row within ``lim`` of the tool (x, y) on each axis, consecutive rows at most ``max_step``
    apart (a NaN fails every comparison, so finiteness comes with it)."""
    # the same differences and comparisons in fewer calls (this runs every tick of every run with a source
    # of its own: issue 44): both columns' distances at once, and the ufuncs' reduce without np.max's wrapper
    off = p - np.array((x, y))
    np.abs(off, out=off)
    if not np.maximum.reduce(off, axis=None) <= lim:
        return False
    if p.shape[0] > 1:
        step = p[1:] - p[:-1]
        np.abs(step, out=step)
        return bool(np.maximum.reduce(step, axis=None) <= max_step)
    return True


def accept_together(stages: Sequence[WindowIntent], answers: Sequence[Any]) -> list[tuple[np.ndarray | None, Fault]]:
    """Each stage's :meth:`WindowIntent.accept` of its answer (:meth:`WindowIntent.answer`), the same (positions or
    None, flags) to the last bit: the answers of one shape (float64 (m, 2), the stages' horizon) checked in one set of
    array operations (the same subtractions and comparisons as :func:`_plausible_rows`, whose NaN fails them too);
    any other answer, and any that fails, by its own stage's :meth:`~WindowIntent.accept` (which counts the stall)."""
    out: list[tuple[np.ndarray | None, Fault] | None] = [None] * len(answers)
    groups: dict[tuple[int, int], list[int]] = {}
    for n, (stage, a) in enumerate(zip(stages, answers)):
        if isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 2 and a.shape[1] == 2:
            groups.setdefault((a.shape[0], stage.horizon), []).append(n)
        else:
            out[n] = stage.accept(a)
    for (m, horizon), members in groups.items():
        group = [stages[n] for n in members]
        rows = np.stack([answers[n] for n in members])[:, :horizon]
        tools = np.array([(stage._x, stage._y) for stage in group])
        off = rows - tools[:, None, :]
        np.abs(off, out=off)
        ok = np.maximum.reduce(off, axis=(1, 2)) <= np.array([stage.plausibility.max_distance for stage in group])
        ok &= m >= np.array([stage.need for stage in group])
        if rows.shape[1] > 1:
            step = rows[:, 1:] - rows[:, :-1]
            np.abs(step, out=step)
            ok &= np.maximum.reduce(step, axis=(1, 2)) <= np.array([stage.max_step for stage in group])
        for n, stage, good in zip(members, group, ok.tolist()):
            if good:
                stage._bad = 0
                out[n] = (answers[n][:horizon], Fault.NONE)
            else:
                out[n] = stage.accept(answers[n])
    return out  # type: ignore[return-value]


class WindowIntentBatch:
    """The ring buffers and the answer check of B :class:`WindowIntent` stages sharing one source: their array twin.

    :meth:`push` stores each row's feature row and returns the windows, (B, history, 8),
    row for row what each stage's :meth:`WindowIntent.push` returns (the same layout: a
    ring twice as long, so every window is one contiguous slice); one ``predict_batch``
    call on them serves the B stages. :meth:`accept` checks the answers as each stage's
    :meth:`WindowIntent.accept` does (at least ``need`` rows of (x, y), the first
    ``horizon`` finite and plausible) and says which rows pass; a row that does not is a fallback,
    which the caller leaves to the stage itself (it counts its stalls).

    Parameters
    ----------
    intents : the B stages, of one shared history and horizon.
    """

    def __init__(self, intents: Sequence[WindowIntent]) -> None:
        if not intents or not all(type(i) is WindowIntent for i in intents):
            raise ValueError("a WindowIntentBatch takes one or more WindowIntent stages")
        first = intents[0]
        for i in intents:
            if i.history != first.history:
                raise ValueError("runs sharing a model in the loop must share its history")
            if i.horizon != first.horizon:
                raise ValueError("runs sharing a model in the loop must share its horizon")
        self.history, self.horizon = first.history, first.horizon
        self._need = np.array([i.need for i in intents], dtype=np.intp)
        self._hist = np.zeros((len(intents), 2 * self.history, _N_FEATURES))
        # each stage's plausibility (the stages are reset for their runs: max_step is theirs)
        self._max_distance = np.array([i.plausibility.max_distance for i in intents])
        self._max_step = np.array([i.max_step for i in intents])
        self._tool = np.zeros((len(intents), 2))  # the tool's position in each stage's row pushed last

    def push(self, k: int, rows: np.ndarray, features: np.ndarray) -> np.ndarray:
        """Store tick k's feature rows (len(rows), 8) of the stages ``rows`` (indices); their
        windows (len(rows), history, 8), oldest first."""
        self._tool[rows] = features[:, :2]
        L = self.history
        if L <= 0:
            return np.zeros((rows.size, 0, _N_FEATURES))
        hist = self._hist
        if k == 0:
            hist[rows] = features[:, None, :]  # pad: the robot was at rest before tick 0
        i = k % L
        hist[rows, i] = features
        hist[rows, i + L] = features
        return hist[rows, i + 1 : i + 1 + L]

    def accept(self, rows: np.ndarray, answer: object) -> tuple[np.ndarray, np.ndarray]:
        """The source's answer (len(rows), m, 2) for the stages ``rows`` → (positions (len(rows),
        min(m, horizon), 2), ok (len(rows),) bool: the stage would take its row).

        Raises ValueError on an answer that is not such an array of real numbers (every row would be
        a fallback, as :meth:`WindowIntent.accept` makes each: a complex or object answer included)."""
        if not (
            isinstance(answer, np.ndarray)
            and answer.ndim == 3
            and answer.shape[0] == rows.size
            and answer.shape[2] == 2
        ):
            raise ValueError("malformed predictions")
        real = _real_positions(answer)
        if real is None:
            raise ValueError(f"predictions must be real numbers, got dtype {answer.dtype}")
        positions = real[:, : self.horizon]
        # WindowIntent._plausible row by row (the same comparisons: a NaN fails them)
        far = np.abs(positions - self._tool[rows][:, None, :]).max(axis=(1, 2))
        ok = (answer.shape[1] >= self._need[rows]) & (far <= self._max_distance[rows])
        if positions.shape[1] > 1:
            ok &= np.abs(positions[:, 1:] - positions[:, :-1]).max(axis=(1, 2)) <= self._max_step[rows]
        return positions, ok


class RealtimeIntent:
    """A :class:`coassist.intent.RealtimePredictor` inside the tick (module docstring).

    Parameters
    ----------
    predictor : anything with ``tick(sample (8,), nominal (H, 2)) -> (positions, fault,
        age)``, ``horizon``, ``history`` and ``errors`` (and optionally
        ``worker_alive``, ``model_id``).
    stall_ticks : consecutive fallback ticks, after the history has filled, that make
        the predictor stalled (≥ 1; default 25 = 0.2 s at 125 Hz).
    model_id : the id logged with the trial; None: the predictor's ``model_id``, else
        ``"realtime"``.
    plausibility : what a row may ask of the controller (module docstring), checked against the
        tool of the tick's own row: a row farther, or faster, is a fallback (PREDICTOR_STALLED when
        it persists), as a window source's is. A :class:`~coassist.intent.RealtimePredictor` checks
        its predictions against the window it predicted from; this stage checks what reaches the
        controller whatever the predictor is (a duck-typed one may check nothing). None: the
        predictor's own ``config.plausibility`` where it has one (the two checks then agree),
        else the default :class:`~coassist.interfaces.PlausibilityLimits`.
    """

    nominal = False
    reads_true_intent = False  # a network predictor: what an arm measures, nothing else

    def __init__(
        self,
        predictor: Any,
        stall_ticks: int = 25,
        model_id: str | None = None,
        plausibility: PlausibilityLimits | None = None,
    ) -> None:
        if plausibility is None:
            own = getattr(getattr(predictor, "config", None), "plausibility", None)
            plausibility = own if isinstance(own, PlausibilityLimits) else PlausibilityLimits()
        elif not isinstance(plausibility, PlausibilityLimits):
            raise ValueError(f"plausibility must be a PlausibilityLimits, got {type(plausibility).__name__}")
        self.plausibility = plausibility
        for attr in ("tick", "horizon"):
            if not hasattr(predictor, attr):
                raise ValueError(f"predictor must have '{attr}' (a coassist.intent.RealtimePredictor)")
        history = getattr(predictor, "history", None)
        if history is None:
            history = getattr(getattr(predictor, "model", None), "history", 0)
        self.predictor = predictor
        self.horizon = int(predictor.horizon)
        self.history = int(history)
        self.model_id = model_id if model_id is not None else getattr(predictor, "model_id", "realtime")
        self.stall_ticks = check_int_at_least(stall_ticks, "stall_ticks", 1)
        self._sample = np.zeros(_N_FEATURES)
        self._bad = 0
        self._errors = 0
        self.max_step = math.inf  # the most consecutive rows may move apart [m] (max_speed · dt, from reset)

    def reset(self, context: TrialContext) -> None:
        self.predictor.reset(context)
        self._bad = 0
        self._errors = int(getattr(self.predictor, "errors", 0))
        self.max_step = self.plausibility.max_speed * float(context.dt)

    def update(self, k: int, row: tuple[float, ...], nominal: np.ndarray) -> tuple[np.ndarray | None, Fault]:
        self._sample[:] = row
        try:
            pos, fault, _age = self.predictor.tick(self._sample, nominal)
            fault = int(fault)  # plain ints on the hot path: IntFlag arithmetic costs microseconds
        except Exception:
            pos, fault = None, _FALLBACK_I
        errors = int(getattr(self.predictor, "errors", 0))
        new_errors, self._errors = errors > self._errors, errors
        alive = bool(getattr(self.predictor, "worker_alive", True))
        arr = None
        usable = not (fault & _FALLBACK_I) and pos is not None
        if usable:
            # an answer that is no array of real numbers (ragged, strings, complex, objects) is a failing
            # predictor's; a finite one far from the tool, or faster than a hand, is as unusable (module docstring)
            try:
                arr = _real_positions(np.asarray(pos))
                usable = (
                    arr is not None
                    and arr.shape == (self.horizon, 2)
                    and _plausible_rows(arr, row[0], row[1], self.plausibility.max_distance, self.max_step)
                )
            except (TypeError, ValueError):
                usable = False
        warm = k >= self.history  # before the window fills the fallback is expected
        self._bad = 0 if usable else self._bad + (1 if warm else 0)
        flags = (0 if usable else _FALLBACK_I) | (fault & _STALE_I)
        if not alive or new_errors or self._bad > self.stall_ticks:
            flags |= _STALLED_I
        return (arr if usable else None), Fault(flags)
