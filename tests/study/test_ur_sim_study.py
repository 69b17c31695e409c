"""The study's real-arm world end to end through ``coassist ur-sim``: a comparison of two simulated
participants with ``world = "ur"``, the real ur-rtde client driving the simulated UR5 and the simulated
operator at its handle (coassist.robot.ur_sim_world)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from coassist.cli import app
from coassist.data import read_dataset
from coassist.metrics import f_rms

from ..ursim import needs_ur_rtde, realtime_priority, simulator

needs_ur_rtde()
pytest.importorskip("mujoco", reason="the simulator's arm is the MuJoCo UR5: pip install 'coassist[robot]'")
# slow too: four 16 s trials in real time (82 s of the realtime run's 297 s); `./dev test -m slow` runs it.
# The default run drives the ur world through the simulator end to end in tests/robot/test_ur_sim_world.py.
pytestmark = [pytest.mark.realtime, pytest.mark.slow]

PLAN = """
[study]
name = "ur-sim-comparison"
protocol = "comparison"
world = "ur"
participants = 2
seed = 3

[[condition]]
name = "assistive"
controller = "cooperative"

[[condition]]
name = "manual"
controller = "manual"

[trials]
tasks = ["linear"]
per_condition = 1
practice = 0
time_limit = 16.0  # an arm trial's least: the linear path's 10.9 s of planned motion and the 5 s dwell

[rest]
between_conditions = 30.0
"""


def _machine_stall(extra: dict) -> bool:
    """Whether the trial was ended by a stall of this computer (a loaded 2-core machine): the loop held
    past the watchdog's 0.1 s, or its deadlines missed until the safety layer stopped it. Each is the
    right controlled stop (the trial kept, one line); with 16 s trials in real time (an arm trial's
    least: the path's planned motion and the 5 s dwell) a shared machine's stall is not rare."""
    message = extra.get("stop_message") or ""
    return (extra["ended"] == "world_error" and "this loop's period lasted" in message) or (
        extra["ended"] == "safety_stop" and "DEADLINE_MISS" in message
    )


def test_a_comparison_of_two_simulated_participants_on_the_ur_world_through_the_simulator(tmp_path):
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN)
    folder = tmp_path / "study"
    runner = CliRunner()
    with simulator() as sim:
        # a real arm's world: --simulate is refused without a simulator behind --robot-host
        result = runner.invoke(app, ["study", "init", str(plan), "--out", str(folder)])
        assert result.exit_code == 0, result.output
        refused = runner.invoke(app, ["study", "run", str(folder), "--simulate", "--yes"])
        assert refused.exit_code != 0 and "coassist ur-sim" in refused.output
        with realtime_priority():
            result = runner.invoke(app, ["study", "run", str(folder), "--simulate", "--yes", "--robot-host", sim.host])
        assert result.exit_code == 0, result.output
        status = sim.status()
    result = runner.invoke(app, ["study", "report", str(folder)])
    assert result.exit_code == 0, result.output
    summary = json.loads((folder / "report" / "summary.json").read_text())
    assert summary["n_participants"] == summary["n_complete"] == 2 and summary["simulated"]
    assert status["out_of_limits"] == 0
    stalls = 0
    for pid, operator in (("S01", "user-1"), ("S02", "user-2")):
        p = summary["participants"][pid]
        assert p["complete"] and set(p["answers"]) == {"assistive", "manual"}
        for c in ("assistive", "manual"):
            (trial,) = read_dataset(folder / "participants" / pid / c).trials
            extra = trial.meta.extra
            # the ur world, through the real client, with the simulated operator at the simulator's handle
            assert trial.meta.origin == "ur5" and extra["world"] == "ur" and trial.joints is not None
            assert trial.meta.user == pid and extra["study_operator"] == operator, extra
            assert p["means"][c]["f_rms"] == pytest.approx(f_rms(trial.wrench[:, :2]), rel=1e-12)
            if _machine_stall(extra):  # kept and analysed as a study keeps it; its run not judged
                stalls += 1
                continue
            assert extra["ended"] in ("time_limit", "target"), extra.get("stop_message")
            travel = np.linalg.norm(trial.pose[-1, :2] - trial.pose[0, :2])
            assert travel > 0.01  # the hand moved the tool
    assert stalls < 4, "every trial was cut short by a stall of this machine"
