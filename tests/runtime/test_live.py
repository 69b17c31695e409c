"""The live view's feed (coassist.runtime.live): the control thread hands over a snapshot and never
waits for the publisher; the snapshots are the run's own rows; the thread publishes at its rate."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from coassist.runtime.live import LiveFeed, TickSnapshot
from coassist.sim.trial_runner import TrialSpec, spec_episode


class Recorder:
    """A sink that keeps every snapshot it is given."""

    def __init__(self) -> None:
        self.snapshots: list[TickSnapshot] = []
        self.closed = False

    def publish(self, snapshot: TickSnapshot) -> None:
        self.snapshots.append(snapshot)

    def close(self) -> None:
        self.closed = True


class Stalled:
    """A sink whose first publish never returns until released (a viewer whose socket is stalled)."""

    def __init__(self) -> None:
        self.entered = threading.Event()
        self.release = threading.Event()
        self.calls = 0

    def publish(self, snapshot: TickSnapshot) -> None:
        self.calls += 1
        self.entered.set()
        self.release.wait()

    def close(self) -> None:
        self.release.set()


class Broken:
    def publish(self, snapshot: TickSnapshot) -> None:
        raise OSError("the viewer's link is gone")

    def close(self) -> None:
        pass


SPEC = TrialSpec(task="curved", seed=3, intent="oracle")  # a prediction in use and the game's α


def _same_trial(a, b) -> None:
    for name in ("pose", "velocity", "wrench", "reference", "prediction", "effort_r", "fault"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def _run(spec: TrialSpec, feed: LiveFeed | None):
    episode = spec_episode(spec)
    return episode.finish(episode.run(on_tick=None if feed is None else feed.watch(episode)))


def test_a_stalled_sink_never_holds_up_the_run():
    # The sink blocks in its first publish for as long as the run takes. If the control thread
    # waited for the publisher at any point (a queue that fills, a lock the publisher holds, a
    # synchronous send), the run could not finish: it finishes, and is the run without the view.
    sink = Stalled()
    feed = LiveFeed(sink, rate_hz=100.0)
    result: list = []
    runner = threading.Thread(target=lambda: result.append(_run(SPEC, feed)), daemon=True)
    runner.start()
    runner.join(120)
    try:
        assert not runner.is_alive(), "the run waited for the stalled publisher"
        assert sink.entered.is_set() and sink.calls == 1  # the publisher really was stalled throughout
        _same_trial(result[0], _run(SPEC, None))
    finally:
        sink.release.set()
        feed.close()


def test_a_failing_sink_is_counted_and_the_run_goes_on():
    feed = LiveFeed(Broken(), rate_hz=100.0)
    trial = _run(SPEC, feed)
    assert feed.flush(10)
    feed.close()
    assert feed.failures >= 1 and feed.published == 0 and "the viewer's link is gone" in feed.last_error
    _same_trial(trial, _run(SPEC, None))


def test_the_snapshots_are_the_runs_rows_and_the_last_tick_is_published():
    sink = Recorder()
    feed = LiveFeed(sink, rate_hz=100.0)
    episode = spec_episode(SPEC)
    log = episode.run(on_tick=feed.watch(episode))
    trial = episode.finish(log)
    assert feed.flush(10)
    feed.close()
    assert sink.closed
    snaps = sink.snapshots
    assert snaps and snaps[-1].k == trial.n_samples - 1  # the end of the run is shown
    ks = [s.k for s in snaps]
    assert ks == sorted(set(ks))  # each tick at most once, in order
    for s in snaps:
        k = s.k
        np.testing.assert_array_equal(s.pose, trial.pose[k])
        np.testing.assert_array_equal(s.velocity, trial.velocity[k])
        np.testing.assert_array_equal(s.wrench, trial.wrench[k])
        np.testing.assert_array_equal(s.reference, trial.reference[k])
        np.testing.assert_array_equal(s.prediction, trial.prediction[k])
        assert s.fault == trial.fault[k] and s.joints is None and s.joint_command is None
        assert s.alpha == episode.tick.controller.game.alpha
        assert s.trial.stamp(k) == s.trial.start_ns + round(trial.time[k] * 1e9)  # the MCAP file's stamps


def test_the_thread_publishes_at_its_rate_not_the_ticks():
    # A simulated trial runs ~10x faster than real time: thousands of ticks in well under a second.
    # At 20 Hz the publisher hands over at most one snapshot per 50 ms (+1 for the final flush).
    sink = Recorder()
    feed = LiveFeed(sink, rate_hz=20.0)
    t0 = time.monotonic()
    trial = _run(SPEC, feed)
    feed.flush(10)
    wall = time.monotonic() - t0
    feed.close()
    assert 1 <= feed.published <= 20.0 * wall + 2 < trial.n_samples


def test_trials_in_a_row_never_run_a_viewers_clock_backwards():
    sink = Recorder()
    feed = LiveFeed(sink, rate_hz=100.0)
    first = _run(TrialSpec(task="linear", seed=1), feed)
    assert feed.flush(10)
    _run(TrialSpec(task="linear", seed=2), feed)
    assert feed.flush(10)
    feed.close()
    a, b = sink.snapshots[0].trial, sink.snapshots[-1].trial
    assert (a.number, b.number) == (0, 1)
    assert b.start_ns >= a.end_ns >= a.stamp(first.n_samples - 1)  # the second begins after the first's last stamp
    # the scene in the plan's frame: the task's obstacle, path and target
    task = spec_episode(TrialSpec(task="linear", seed=1)).task
    np.testing.assert_array_equal(a.obstacles[0][0], task.obstacle.center)
    np.testing.assert_array_equal(a.path, task.path.points)
    np.testing.assert_array_equal(a.target, task.target)


@pytest.mark.parametrize("rate", [0.0, -1.0, 101.0, float("nan"), "fast"])
def test_a_bad_rate_names_the_field(rate):
    with pytest.raises(ValueError, match="LiveFeed.rate_hz"):
        LiveFeed(Recorder(), rate_hz=rate)


class PolicyRecorder(Recorder):
    """A sink that notes the scheduling policy of the thread that publishes."""

    def __init__(self) -> None:
        super().__init__()
        self.policies: list[int] = []

    def publish(self, snapshot: TickSnapshot) -> None:
        import os

        self.policies.append(os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK)
        super().publish(snapshot)


def test_the_publisher_runs_at_the_watching_threads_policy():
    """A real-time loop's publisher runs at its priority (else, preempted with the interpreter lock held,
    it would make the loop wait behind the machine's other processes), and back at normal priority
    for a loop at normal priority."""
    import os

    if not hasattr(os, "sched_setscheduler"):
        pytest.skip("no scheduling policies on this OS")
    seen: dict[str, object] = {}

    def fifo_run(feed: LiveFeed) -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(5))
        except OSError:
            seen["refused"] = True
            return
        try:
            # two runs: before its first frame the publisher is still at normal priority, and on a loaded
            # machine the FIFO run can starve it to the run's end (one frame: 6 of 6 at load 6); the
            # second run's frames, the last one at least (flush), come from a publisher already at FIFO
            for _ in range(2):
                _run(SPEC, feed)
                assert feed.flush(10)
        finally:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))

    recorder = PolicyRecorder()
    with LiveFeed(recorder, rate_hz=100.0) as feed:
        thread = threading.Thread(target=fifo_run, args=(feed,))  # this thread's policy stays as it is
        thread.start()
        thread.join()
        if seen.get("refused"):
            pytest.skip("SCHED_FIFO is not allowed here")
        assert feed.policy == (os.SCHED_FIFO, 5)
        n = len(recorder.policies)
        assert n >= 2 and set(recorder.policies[1:]) == {os.SCHED_FIFO}  # the first may precede the change
        _run(SPEC, feed)  # a loop at normal priority: the publisher follows it back
        assert feed.flush(10)
        assert feed.policy == (os.SCHED_OTHER, 0) and recorder.policies[-1] == os.SCHED_OTHER
        assert os.sched_getscheduler(0) == os.SCHED_OTHER  # the test's own thread untouched


def test_the_scene_shows_the_obstacles_the_intent_source_is_told_of():
    # The live view draws what the run's source was told: the context build_episode reset the tick with (the rule,
    # on every world: tests/robot/test_drive_calibration.py). Here the point mass's simulated operator: the task's
    # box, moved with the plan.
    from coassist.runtime.live import told_obstacles

    episode = spec_episode(SPEC)
    (box,) = told_obstacles(episode)
    shift = np.asarray(episode.plan)[0, :2] - np.asarray(episode.task.start)
    np.testing.assert_array_equal(box[0], np.asarray(episode.task.obstacle.center) + shift)
    np.testing.assert_array_equal(box[1], episode.task.obstacle.size)


def test_watching_records_the_live_start_in_the_trial():
    sink = Recorder()
    with LiveFeed(sink, rate_hz=100.0) as feed:
        trial = _run(SPEC, feed)
        feed.flush(10)
    assert trial.meta.extra["live_start_ns"] == sink.snapshots[0].trial.start_ns
    assert "live_start_ns" not in _run(SPEC, None).meta.extra
