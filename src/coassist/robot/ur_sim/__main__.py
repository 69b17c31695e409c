"""``python -m coassist.robot.ur_sim '<config JSON>'``: the simulator for :class:`~coassist.robot.ur_sim.process.URSimProcess`."""

import sys

from coassist.robot.ur_sim.process import config_from_json, serve

# its parent (URSimProcess) holds its stdin: when that closes, the parent is gone, and so is the simulator
serve(config_from_json(sys.argv[1]) if len(sys.argv) > 1 else config_from_json("{}"), quit_at_eof=True)
