"""franky-sim (the libfranka protocol over loopback, MuJoCo behind it) in its own process, for the tests.

Prints ``HOST <address>`` once the server listens. Reads commands on stdin, one a line:
``push fx fy fz`` sets a constant force [N] (base frame) on the hand body from the next
physics step on (the person at the handle); ``quit`` ends the process. Run by
tests/robot/test_franka_world.py; not part of coassist.
"""

from __future__ import annotations

import os
import sys

import mujoco
import numpy as np
from franky_sim import SimulationServer
from franky_sim.mujoco_simulator import MujocoSimulator

#: The server's niceness: the simulated arm's 1 kHz loop stands for a robot controller on its own real-time
#: computer, so a busy test machine must not starve it (two busy loops on 2 cores stalled it past the
#: client's 0.1 s link timeout). Lowering the niceness needs privileges; without them it stays as it is.
NICENESS = -10


def main() -> None:
    try:
        os.setpriority(os.PRIO_PROCESS, 0, NICENESS)
    except (OSError, AttributeError):  # not permitted (an unprivileged CI runner), or not POSIX
        pass
    push = np.zeros(3)

    def listen() -> None:
        for line in sys.stdin:
            parts = line.split()
            if parts[:1] == ["push"] and len(parts) == 4:
                push[:] = [float(v) for v in parts[1:]]
            elif parts[:1] == ["quit"]:
                break

    with MujocoSimulator(enable_visualization=False) as sim:
        robot = sim.add_robot()

        def apply_push(s) -> None:
            data, model = s.data, s.model
            body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "robot0_hand")
            data.xfrc_applied[body, :3] = push

        sim.register_pre_step_callback(apply_push)
        with SimulationServer(sim) as server:
            server.run_async()
            print(f"HOST {robot.hostname}", flush=True)
            listen()


if __name__ == "__main__":
    main()
