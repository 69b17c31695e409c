"""What a UR controller reports, in words: its safety status, its software, what to do about a stop.

:class:`SafetyStatus` names the bits of ur-rtde's ``getSafetyStatusBits()``, and
:func:`stop_message` turns a stop (those bits and a :class:`~coassist.runtime.world.RobotState`'s
two stop flags) into what stopped the robot and what the operator does next.
:func:`controller_version` asks the dashboard server (port 29999) for the software version;
:func:`check_software` refuses software ur-rtde 1.6.5 cannot drive (:data:`MIN_SOFTWARE`) before
it connects, and :func:`connect_hint` says what to do about a failed connect. The world that
drives the arm is :class:`~coassist.robot.ur_rtde_world.URRTDEWorld`.
"""

from __future__ import annotations

import re

from coassist.runtime.world import RobotLinkError, RobotState

__all__ = ["MIN_SOFTWARE", "SafetyStatus", "check_software", "connect_hint", "controller_version", "stop_message"]


class SafetyStatus:
    """Bits of ``getSafetyStatusBits()`` (ur-rtde docstring order, bits 0–10)."""

    NORMAL = 1 << 0
    REDUCED = 1 << 1
    PROTECTIVE_STOPPED = 1 << 2
    RECOVERY = 1 << 3
    SAFEGUARD_STOPPED = 1 << 4
    SYSTEM_EMERGENCY_STOPPED = 1 << 5
    ROBOT_EMERGENCY_STOPPED = 1 << 6
    EMERGENCY_STOPPED = 1 << 7
    VIOLATION = 1 << 8
    FAULT = 1 << 9
    STOPPED_DUE_TO_SAFETY = 1 << 10

    #: Reported as ``RobotState.protective_stop``: the safety system halted the arm and a
    #: person must clear it (a protective or safeguard stop, a violation or a fault).
    PROTECTIVE = PROTECTIVE_STOPPED | SAFEGUARD_STOPPED | VIOLATION | FAULT | STOPPED_DUE_TO_SAFETY
    #: Reported as ``RobotState.emergency_stop``.
    EMERGENCY = SYSTEM_EMERGENCY_STOPPED | ROBOT_EMERGENCY_STOPPED | EMERGENCY_STOPPED


def stop_message(state: RobotState, safety_status_bits: int | None = None) -> str | None:
    """What stopped the robot and what to do next, or None when it is not stopped.

    ``safety_status_bits`` (:attr:`URRTDEWorld.safety_status_bits`) refines the message
    (safeguard stop, violation, fault); without it the two flags of ``state`` decide.
    """
    bits = int(safety_status_bits or 0)
    if state.emergency_stop or bits & SafetyStatus.EMERGENCY:
        return (
            "Emergency stop: the robot's emergency stop circuit is open (a pressed button or "
            "the external e-stop input). Make the workspace safe, release the button, reset "
            "the robot on the teach pendant (power on, release the brakes), then rerun."
        )
    if bits & (SafetyStatus.VIOLATION | SafetyStatus.FAULT):
        return (
            "Safety fault: the robot's safety system reports a violation or a fault and has "
            "stopped the arm. Read the error on the teach pendant, restart the safety system "
            "there (or with the dashboard's restartSafety), power on, then rerun."
        )
    if bits & SafetyStatus.SAFEGUARD_STOPPED:
        return (
            "Safeguard stop: the safeguard stop input is active (a light curtain, a door or a "
            "safety mat). Clear the safeguarded area, reset the safeguard, then rerun."
        )
    if state.protective_stop or bits & SafetyStatus.PROTECTIVE:
        return (
            "Protective stop: the robot's safety system stopped the arm (a force or speed "
            "limit, or a collision). Check the workspace and the person, clear the stop on "
            "the teach pendant (or with the dashboard's 'unlock protective stop', at least 5 s "
            "after it happened), then rerun."
        )
    return None


def controller_version(host: str, timeout: float = 1.0) -> str | None:
    """The controller's software version from its dashboard server (``PolyscopeVersion``), or None.

    ur-rtde 1.6.5's Python interfaces do not expose it; one line over port 29999 does.
    """
    import socket

    try:
        with socket.create_connection((host, 29999), timeout=timeout) as s:
            f = s.makefile("rwb")
            f.readline()  # the greeting
            f.write(b"PolyscopeVersion\n")
            f.flush()
            line = f.readline().decode("utf-8", errors="replace").strip()
    except OSError:
        return None
    return line or None


#: The oldest software ur-rtde 1.6.5 runs on: the general-purpose output registers its control script
#: answers through came with PolyScope 3.4 (older, its client reads registers the controller never
#: sends and the process crashes).
MIN_SOFTWARE = {3: (3, 4), 5: (5, 0)}


def check_software(host: str) -> None:
    """RobotLinkError before ur-rtde connects when the dashboard reports software it cannot drive."""
    text = controller_version(host)
    m = re.search(r"(\d+)\.(\d+)\.(\d+)", text or "")
    if m is None:
        return  # no dashboard answer: ur-rtde's own connect says what is wrong
    major, minor = int(m.group(1)), int(m.group(2))
    need = MIN_SOFTWARE.get(major)
    if need is None or (major, minor) < need:
        wanted = " or ".join(f"{a}.{b}" for a, b in MIN_SOFTWARE.values())
        raise RobotLinkError(
            f"the controller at {host} runs {text}; ur-rtde 1.6.5 needs PolyScope {wanted} or later: "
            "update PolyScope (CB3 3.15, e-Series 5.11 or later), then rerun"
        )


def connect_hint(host: str, exc: BaseException) -> str:
    """What to do about a failed connect, from ur-rtde's words (the common causes first)."""
    text = str(exc)
    if "remote control" in text:
        return (
            f"the UR at {host} is not in remote control: switch it to Remote Control on the teach "
            "pendant (the icon top right), then rerun"
        )
    if "already in use" in text:
        return (
            f"another client writes the RTDE input registers of the UR at {host} (an EtherNet/IP, "
            "PROFINET or MODBUS unit, or another ur-rtde program): disable it or close the other "
            "client, then rerun"
        )
    if "control script" in text or "program is not running" in text:
        return (
            f"the UR at {host} did not start ur-rtde's control script: check on the teach pendant "
            "that the arm is powered on with its brakes released, not in a protective or emergency "
            "stop, and in remote control, then rerun"
        )
    if "not found by the controller" in text or "register" in text:
        version = controller_version(host)
        return (
            f"the controller at {host} (software {version or 'unknown'}) lacks RTDE fields ur-rtde "
            "1.6.5 needs: update PolyScope to 3.15 (CB3) or 5.11 (e-Series) or later, then rerun"
        )
    return (
        "check the IP address, that the robot is powered on and its brakes released, that "
        "an e-Series is in remote control mode, and that no other program holds the RTDE "
        "interface"
    )
