"""``python -m coassist.robot.ur_sim '<config JSON>'``: the simulator for :class:`~coassist.robot.ur_sim.process.URSimProcess`.

With ``-`` for the config, the config is the first line of stdin, read once the imports are done
(:func:`~coassist.robot.ur_sim.process.spawn`: a process started ahead of its simulator); at the end
of stdin before it, the process ends.
"""

import sys

from coassist.robot.ur_sim.process import CONFIG_ON_STDIN, config_from_json, serve

if sys.argv[1:] == [CONFIG_ON_STDIN]:
    line = sys.stdin.readline()
    if not line.strip():  # its parent ended (or closed stdin) before it was needed
        sys.exit(0)
    config = config_from_json(line)
else:
    config = config_from_json(sys.argv[1] if len(sys.argv) > 1 else "{}")
# its parent (URSimProcess) holds its stdin: when that closes, the parent is gone, and so is the simulator
serve(config, quit_at_eof=True)
