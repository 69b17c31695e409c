"""A UR controller at the protocol level, with the MuJoCo UR5 behind it: what ``coassist ur-sim`` runs.

The real ur_rtde client (``rtde_control``, ``rtde_receive``) connects to it as to a robot:
the dashboard server (29999), the script ports (30001-30003: ur_rtde's control script is run
as the controller would, register by register), RTDE (30004: recipes, the output stream at
125 Hz on a CB3 or 500 Hz on an e-Series). Faults a real controller shows can be injected.

Modules, one concept each: :mod:`.rtde` (the wire format), :mod:`.dashboard` (the dashboard's
text protocol), :mod:`.registers` (ur_rtde's control script and its register protocol),
:mod:`.arm` (the MuJoCo UR5 and UR's motion commands and conventions), :mod:`.controller`
(the cycle, safety and program state, the faults), :mod:`.server` (sockets and the clock:
:class:`URSim`), :mod:`.process` (the simulator in its own process, driven over stdin).
docs/robots.md says what it emulates and what it leaves out.
"""

from coassist.robot.ur_sim.server import PORTS, SERIES, URSim, URSimConfig

__all__ = ["PORTS", "SERIES", "URSim", "URSimConfig"]
