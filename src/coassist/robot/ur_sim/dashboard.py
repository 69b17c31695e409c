"""The dashboard server's text protocol (port 29999): one command a line, one reply a line.

On connect the server greets with ``Connected: Universal Robots Dashboard Server``. The replies
ur_rtde's ``DashboardClient`` checks word for word are kept word for word (``Starting program``,
``Stopped``, ``Pausing program``, ``Protective stop releasing``); the others follow UR's
dashboard server manual. A command the server does not know: ``could not understand: '<line>'``.
With remote control off (an e-Series in local mode) a command that would change the robot's
state is refused with a line starting ``Failed to execute:``.
"""

from __future__ import annotations

from typing import Protocol

__all__ = ["GREETING", "DashboardState", "reply"]

GREETING = "Connected: Universal Robots Dashboard Server"

ROBOT_MODES = {
    -1: "NO_CONTROLLER",
    0: "DISCONNECTED",
    1: "CONFIRM_SAFETY",
    2: "BOOTING",
    3: "POWER_OFF",
    4: "POWER_ON",
    5: "IDLE",
    6: "BACKDRIVE",
    7: "RUNNING",
}
SAFETY_MODES = {
    1: "NORMAL",
    2: "REDUCED",
    3: "PROTECTIVE_STOP",
    4: "RECOVERY",
    5: "SAFEGUARD_STOP",
    6: "SYSTEM_EMERGENCY_STOP",
    7: "ROBOT_EMERGENCY_STOP",
    8: "VIOLATION",
    9: "FAULT",
}
#: Commands that change the robot's state: refused in local control.
_REMOTE_ONLY = (
    "play",
    "stop",
    "pause",
    "power on",
    "power off",
    "brake release",
    "unlock protective stop",
    "restart safety",
    "load",
    "shutdown",
)


class DashboardState(Protocol):
    """What the dashboard reads and changes on the controller (:class:`~coassist.robot.ur_sim.controller.Controller`)."""

    version: tuple[int, int, int, int]
    serial: str
    robot_mode: int
    safety_mode: int

    @property
    def remote_control(self) -> bool: ...

    def program_state(self) -> tuple[str, str]:
        """("PLAYING" | "STOPPED" | "PAUSED", program name)."""
        ...

    def stop_program(self) -> bool: ...

    def unlock_protective_stop(self) -> str | None:
        """None when unlocked, else why not."""
        ...

    def power(self, on: bool) -> None: ...

    def brake_release(self) -> None: ...

    def restart_safety(self) -> None: ...


def version_text(version: tuple[int, int, int, int]) -> str:
    major, minor, bugfix, build = version
    return f"URSoftware {major}.{minor}.{bugfix}.{build} (Jul 06 2021)"


def reply(state: DashboardState, line: str) -> tuple[str, bool]:
    """The reply to one command line, and whether the server then closes the connection (``quit``)."""
    cmd = line.strip()
    low = cmd.lower()
    if not state.remote_control and any(low == c or low.startswith(c + " ") for c in _REMOTE_ONLY):
        return f"Failed to execute: {cmd}: the robot is in local control (remote control is off)", False
    if low == "quit":
        return "Disconnected", True
    if low in ("polyscopeversion", "version"):
        return version_text(state.version), False
    if low == "get serial number":
        return state.serial, False
    if low == "get robot model":
        return "UR5", False
    if low == "is in remote control":
        return "true" if state.remote_control else "false", False
    if low == "robotmode":
        return f"Robotmode: {ROBOT_MODES.get(state.robot_mode, 'UNKNOWN')}", False
    if low == "safetymode":
        return f"Safetymode: {SAFETY_MODES.get(state.safety_mode, 'UNKNOWN')}", False
    if low == "safetystatus":
        return f"Safetystatus: {SAFETY_MODES.get(state.safety_mode, 'UNKNOWN')}", False
    if low == "programstate":
        status, name = state.program_state()
        return f"{status} {name}", False
    if low == "running":
        return f"Program running: {'true' if state.program_state()[0] == 'PLAYING' else 'false'}", False
    if low == "stop":
        return ("Stopped" if state.stop_program() else "Failed to execute: stop"), False
    if low == "play":
        return "Failed to execute: play (no program loaded: send the program to a script port)", False
    if low == "pause":
        return "Failed to execute: pause", False
    if low == "unlock protective stop":
        why = state.unlock_protective_stop()
        return ("Protective stop releasing" if why is None else why), False
    if low == "close safety popup":
        return "closing safety popup", False
    if low in ("close popup",):
        return "closing popup", False
    if low.startswith("popup"):
        return "showing popup", False
    if low == "power on":
        state.power(True)
        return "Powering on", False
    if low == "power off":
        state.power(False)
        return "Powering off", False
    if low == "brake release":
        state.brake_release()
        return "Brake releasing", False
    if low == "restart safety":
        state.restart_safety()
        return "Restarting safety", False
    if low == "get loaded program":
        return "No program loaded", False
    if low.startswith("load "):
        return f"File not found: {cmd[5:]}", False
    if low.startswith("addtolog"):
        return "Added log message", False
    if low == "isprogramsaved":
        return "true <unnamed>", False
    return f"could not understand: '{cmd}'", False
