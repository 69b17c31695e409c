"""No run is lost (issue 37): whatever a world raises, whatever its log holds, however it is killed.

On the MuJoCo UR5 (``coassist drive``'s own world, with a fault injected between it and
the tick, as ``test_runtime_faults`` does):

- an exception from the world's ``read`` or ``apply`` (a driver's ``OSError``), or from
  the monitor: a controlled stop (``ended`` says which), one line saying what raised,
  ``world.stop()`` called, every row before it kept, and the trial written;
- a log that holds non-finite values (a sensor rotation of 1e300 once; NaN/±inf/1e300
  fuzzed into 30 % of the wrench, pose, twist, q and R entries): the trial is written and
  read back finite, the bad rows flagged, and ``meta.extra["log_note"]`` says so (it was
  ``ValueError: Trial.wrench has non-finite values`` at the end of the run);
- ``drive --mcap`` beside an existing ``.mcap``: refused without ``--overwrite``; a
  ``kill -9`` at each step of writing the pair never leaves a new trial beside the old
  run's MCAP, and nothing in the temporary folder.
"""

from __future__ import annotations

import importlib.util
import os
import select
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
pytest.importorskip("pinocchio", reason="the UR5 kinematics need the robot extra: pip install 'coassist[robot]'")

from coassist.data import read_trial, write_trial  # noqa: E402
from coassist.interfaces import Fault  # noqa: E402
from coassist.robot.drive import DriveConfig, drive  # noqa: E402
from coassist.robot.mujoco_world import MujocoUR5World  # noqa: E402
from coassist.robot.ros2_world import UR_JOINT_NAMES  # noqa: E402

TESTS = Path(__file__).resolve().parents[1]


def _load(path: Path):
    name = f"_coassist_tests_{path.stem}"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


table = _load(TESTS / "faults" / "test_runtime_faults.py")
CONFIG = DriveConfig(controller="manual", task="linear", time_limit=1.2, limits=table.LIMITS)


class Raising(table.FaultyWorld):
    """The MuJoCo UR5 whose ``read`` or ``apply`` of tick ``at`` raises ``OSError`` (a driver's socket)."""

    def __init__(self, where: str, at: int) -> None:
        super().__init__(MujocoUR5World("handle", control_dt=table.DT, operator=table.PUSH))
        self.where, self.at, self.reads, self.stops = where, at, 0, 0

    def read(self):
        self.reads += 1  # drive's own first read, then tick 0 …: read k + 2 is tick k
        if self.where == "read" and self.reads == self.at + 2:
            raise OSError("F/T driver: read timed out")
        return super().read()

    def apply(self, command):
        if self.where == "apply" and self.k == self.at:
            raise OSError("robot driver: command refused (controller busy)")
        super().apply(command)

    def stop(self):
        self.stops += 1
        super().stop()


def _run(world, **kw):
    try:
        return drive(CONFIG, operator=table.PUSH, world=world, **kw)
    finally:
        world.close()


@pytest.mark.parametrize("where", ["read", "apply"])
def test_an_exception_from_the_world_is_a_controlled_stop_and_the_trial_is_written(where, tmp_path):
    world = Raising(where, at=98)
    trial = _run(world)
    back = read_trial(write_trial(trial, tmp_path / "t.parquet"))
    extra = back.meta.extra
    assert extra["ended"] == "world_error" and back.n_samples == 98  # ticks 0 … 97, whole
    msg = extra["stop_message"]
    assert f"the robot's {where}() failed at tick 98" in msg and "OSError" in msg and "\n" not in msg
    assert world.stops >= 1  # the arm was told to stop
    np.testing.assert_array_equal(back.joint_velocity, trial.joint_velocity)


def test_an_exception_from_the_monitor_is_a_controlled_stop(tmp_path):
    def monitor(k, state, out):
        if k == 50:
            raise RuntimeError("the monitor's socket closed")

    world = Raising("none", at=-1)
    trial = _run(world, on_tick=monitor)
    assert trial.meta.extra["ended"] == "internal_error" and trial.n_samples == 51  # tick 50 was sent and logged
    assert "the monitor (on_tick) failed at tick 50" in trial.meta.extra["stop_message"] and world.stops >= 1


# -------------------------------------------------------------------------- non-finite values in the log


def test_a_sensor_rotation_of_1e300_once_is_one_flagged_tick_and_the_trial_is_written(tmp_path):
    def inject(k, s):
        if k == 50:
            s.sensor_rotation = np.array(s.sensor_rotation, dtype=float)
            s.sensor_rotation[0, 0] = 1e300

    world = table.FaultyWorld(MujocoUR5World("handle", control_dt=table.DT, operator=table.PUSH), inject)
    trial = _run(world)
    back = read_trial(write_trial(trial, tmp_path / "t.parquet"))
    assert back.meta.extra["ended"] == "time_limit"  # one bad sample: one bad tick, not a stop
    assert np.flatnonzero(back.fault & int(Fault.INVALID_INPUT)).tolist() == [50]
    assert np.abs(back.wrench).max() < 16.0  # the 15 N push; nothing of 1e300


def test_a_log_row_that_is_not_finite_is_held_flagged_and_said():
    from coassist.runtime.loop import LoopLog

    # a finished episode's log with a NaN wrench on ticks 3, 4 and an inf velocity on tick 0
    world = table.FaultyWorld(MujocoUR5World("handle", control_dt=table.DT, operator=table.PUSH))
    try:
        from coassist.robot.drive import _prepare

        run = _prepare(CONFIG, operator=table.PUSH, world=world)
        log = run.episode.run()
    finally:
        world.close()
    n = 8
    cut = {
        name: getattr(log, name)[:n].copy()
        for name in ("pose", "velocity", "wrench", "reference", "effort_h", "effort_r", "joints", "joint_velocity")
    }
    cut["wrench"][3:5] = np.nan
    cut["velocity"][0, 1] = np.inf
    bad = LoopLog(prediction=None, fault=np.zeros(n, dtype=np.int64), compute=np.zeros(n), ended="time_limit", **cut)
    trial = run.finish(bad)
    np.testing.assert_array_equal(trial.wrench[3], cut["wrench"][2])  # the last finite row, held
    np.testing.assert_array_equal(trial.wrench[4], cut["wrench"][2])
    np.testing.assert_array_equal(trial.velocity[0], cut["velocity"][1])  # none before: the first finite one after
    assert np.flatnonzero(trial.fault & int(Fault.NONFINITE_WRENCH)).tolist() == [3, 4]
    assert np.flatnonzero(trial.fault & int(Fault.NONFINITE_STATE)).tolist() == [0]
    extra = trial.meta.extra
    assert extra["nonfinite_rows"] == {
        "velocity": {"first_tick": 0, "ticks": 1},
        "wrench": {"first_tick": 3, "ticks": 2},
    }
    assert "wrench: 2 tick(s) from tick 3" in extra["log_note"]
    np.testing.assert_array_equal(trial.pose, cut["pose"])  # the finite columns as they were


def test_a_fuzzed_run_is_written_with_its_mcap_and_figure(tmp_path):
    from coassist.data.bags import load_bag_trial
    from coassist.data.run_pair import write_run_pair
    from coassist.sim.monitor import plot_trial

    rng = np.random.default_rng(37)
    bad_values = np.array([np.nan, np.inf, -np.inf, 1e300])

    def fuzz(k, s):
        if k < 5:
            return  # drive zeroes the sensor on a clean reading
        for name in ("wrench", "tool_pose", "tool_twist", "q", "sensor_rotation"):
            a = np.array(getattr(s, name), dtype=float)
            hit = rng.random(a.shape) < 0.3
            a[hit] = rng.choice(bad_values, size=int(hit.sum()))
            setattr(s, name, a)

    world = table.FaultyWorld(MujocoUR5World("handle", control_dt=table.DT, operator=table.PUSH), fuzz)
    trial = _run(world)
    assert trial.meta.extra["ended"] == "safety_stop"
    path, mcap = write_run_pair(trial, tmp_path / "fuzz.parquet", mcap=True)
    back = read_trial(path)
    assert back.equals(trial) and back.n_samples == trial.n_samples
    assert np.all(back.fault[5:] & int(Fault.NONFINITE_STATE | Fault.NONFINITE_WRENCH | Fault.INVALID_INPUT))
    # the MCAP holds the run's log: an implausible pose or twist (1e300) is a glitch held as a NaN is (since
    # 2026-12-07; the log had kept it, and the MCAP read back as a recording was refused), so the recording reads
    recording = load_bag_trial(mcap)
    assert recording.n_samples == trial.n_samples and np.abs(recording.pose).max() < 1e3
    assert plot_trial(trial, tmp_path / "fuzz.png").stat().st_size > 0


# -------------------------------------------------------------------------- the trial and its MCAP, one pair

DRIVE = ["drive", "--controller", "manual", "--time-limit", "0.2", "--no-plot", "--mcap"]


def test_drive_mcap_does_not_silently_replace_an_existing_mcap(tmp_path):
    pytest.importorskip("rosbags", reason="--mcap needs the bags extra")
    from typer.testing import CliRunner

    from coassist.cli import app

    out = tmp_path / "run.parquet"
    (tmp_path / "run.mcap").write_bytes(b"another run's recording")
    res = CliRunner().invoke(app, [*DRIVE, "--out", str(out)])
    assert res.exit_code == 2 and "run.mcap exists; pass --overwrite" in res.output, res.output
    assert (tmp_path / "run.mcap").read_bytes() == b"another run's recording" and not out.exists()


def test_drive_does_not_silently_replace_a_figure_at_out_png(tmp_path):
    """The monitor figure <out>.png is refused like the MCAP (a figure of an earlier run, or the lab's own file):
    --no-plot writes none and runs; --overwrite replaces it."""
    from typer.testing import CliRunner

    from coassist.cli import app

    out = tmp_path / "run.parquet"
    figure = tmp_path / "run.png"
    figure.write_bytes(b"the lab's figure")
    base = ["drive", "--controller", "manual", "--time-limit", "0.2", "--out", str(out)]
    res = CliRunner().invoke(app, base)
    assert res.exit_code == 2 and "run.png exists; pass --overwrite" in res.output and "--no-plot" in res.output
    assert figure.read_bytes() == b"the lab's figure" and not out.exists()
    res = CliRunner().invoke(app, [*base, "--no-plot"])
    assert res.exit_code == 0, res.output
    assert figure.read_bytes() == b"the lab's figure" and out.exists()


#: The writers' parent: it imports the CLI and runs ``drive`` once (argv[1]: its own output, elsewhere), so that
#: what a fresh interpreter pays once (~1 CPU-s: imports, the UR5's model) is paid once, not by each writer; then,
#: per line n on stdin, it forks a writer that runs ``drive argv[2:]`` (the same command line, a process of its
#: own) and whose n-th rename/replace of the pair write (counted from the run's end) kills it with SIGKILL, and
#: answers the writer's exit status (as subprocess gives it: -9 when killed) on its stdout.
CHILD = """
import os, signal, sys
from coassist.cli import app
import coassist.robot.drive as d
report = os.fdopen(os.dup(1), "w", buffering=1)
os.dup2(os.open(os.devnull, os.O_WRONLY), 1)  # drive's own lines
def run(args):
    try:
        app(args, standalone_mode=True)
    except SystemExit as e:
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    return 0
args = sys.argv[2:]
if run([*args[: args.index("--out") + 1], sys.argv[1], "--overwrite"]) != 0:
    raise SystemExit("the parent's own drive failed")
for line in sys.stdin:
    n = int(line)
    pid = os.fork()
    if pid == 0:
        real_replace, real_rename = os.replace, os.rename
        count = [0]
        def maybe_die():
            count[0] += 1
            if count[0] == n:
                os.kill(os.getpid(), signal.SIGKILL)
        def replace(a, b, **kw):
            maybe_die()
            return real_replace(a, b, **kw)
        def rename(a, b, **kw):
            maybe_die()
            return real_rename(a, b, **kw)
        run_drive = d.drive
        def patched(*a, **kw):  # count only the writes after the run
            trial = run_drive(*a, **kw)
            os.replace, os.rename = replace, rename
            return trial
        d.drive = patched
        code = 1
        try:
            code = run(args)
        finally:
            os._exit(code)
    print(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), file=report)
"""


def _pair(folder: Path) -> tuple[bytes | None, bytes | None]:
    t, m = folder / "run.parquet", folder / "run.mcap"
    return (t.read_bytes() if t.exists() else None), (m.read_bytes() if m.exists() else None)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_kill_during_drive_mcap_never_leaves_a_trial_beside_another_runs_mcap(tmp_path, tmp_path_factory):
    pytest.importorskip("rosbags", reason="--mcap needs the bags extra")
    out = tmp_path / "run.parquet"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "TMPDIR": str(scratch)}
    # Each writer is a process of its own, killed by SIGKILL, as before; forked from one parent that has imported
    # and run drive once (CHILD), not a fresh interpreter each: 11 writers cost 8.7 CPU-s that way (issue 44).
    warm = tmp_path_factory.mktemp("warm") / "run.parquet"
    parent = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent(CHILD),
            str(warm),
            *DRIVE,
            "--out",
            str(out),
            "--seed",
            "2",
            "--overwrite",
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )

    def child(n: int) -> int:
        parent.stdin.write(f"{n}\n")
        parent.stdin.flush()
        if not select.select([parent.stdout], [], [], 300)[0]:
            raise AssertionError(f"the writer killed at rename {n} gave no exit status in 300 s")
        line = parent.stdout.readline()
        assert line, f"the writers' parent ended (exit status {parent.wait()})"
        return int(line)

    from coassist.data.run_pair import write_run_pair

    # the old run (seed 1) and the new one (seed 2), whole, as drive writes them
    pairs = []
    for seed in (1, 2):
        trial = drive(DriveConfig(controller="manual", time_limit=0.2, seed=seed))
        write_run_pair(trial, out, mcap=True, alpha=None, joint_names=UR_JOINT_NAMES)
        pairs.append(_pair(tmp_path))
    old, new = pairs
    assert old[0] != new[0] and old[1] != new[1]
    try:
        seen = set()
        for n in range(1, 12):  # every rename of writing the pair (and of the files inside it)
            # put the old pair back, then kill the new run's write at its n-th rename
            (tmp_path / "run.parquet").write_bytes(old[0])
            (tmp_path / "run.mcap").write_bytes(old[1])
            rc = child(n)
            trial_bytes, mcap = _pair(tmp_path)
            state = (
                "old" if trial_bytes == old[0] else "new" if trial_bytes == new[0] else repr(trial_bytes)[:20],
                "old" if mcap == old[1] else "new" if mcap == new[1] else "none" if mcap is None else "?",
            )
            seen.add(state)
            assert state in {("old", "old"), ("old", "none"), ("new", "none"), ("new", "new")}, (n, state)
            assert list(scratch.iterdir()) == [], (n, list(scratch.iterdir()))  # nothing left in the temp folder
            visible = sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith("."))
            assert visible in (["run.mcap", "run.parquet", "tmp"], ["run.parquet", "tmp"]), (n, visible)
            if rc == 0:
                break
            assert rc == -signal.SIGKILL
    finally:
        parent.stdin.close()  # it ends at EOF
        status = parent.wait(60)
    assert status == 0
    assert rc == 0 and ("new", "new") in seen and ("old", "old") in seen
    # the next write sweeps what the dead writers left
    write_run_pair(trial, out, mcap=True, joint_names=UR_JOINT_NAMES)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap", "run.parquet", "tmp"]
