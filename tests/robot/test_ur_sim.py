"""The UR simulator's parts without a clock: the RTDE wire format, the dashboard, ur_rtde's register
protocol cycle by cycle, the controller's safety state, and the arm's motion and conventions.

The real client against the running simulator: tests/robot/test_ur_sim_world.py.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the simulator's arm is the MuJoCo UR5: pip install 'coassist[robot]'")

from coassist.robot.ur_sim import dashboard, rtde  # noqa: E402
from coassist.robot.ur_sim.arm import JOINT_SPEED_LIMIT, SimArm  # noqa: E402
from coassist.robot.ur_sim.controller import Controller, OutputStream  # noqa: E402
from coassist.robot.ur_sim.registers import DONE, READY, ControlScript, RegisterFile, parse_program  # noqa: E402
from coassist.robot.ur_sim.server import URSimConfig  # noqa: E402
from coassist.runtime.operators import ScriptedForce  # noqa: E402

# A program with the markers of ur_rtde's control script (its text is ur_rtde's, not copied here).
CONTROL = """def rtde_control():
    global reg_offset_float = # float register offset
{offset}    global reg_offset_int = # int register offset
{offset}    textmsg("RTDE Control Script Loaded (test)")
{body}
end
"""
E_SERIES_BODY = '    step_time = get_steptime()\n    tcp_offset = get_tcp_offset()\n    zero_ftsensor()\n    rtde_set_watchdog("input_int_register_0", 10, "stop")'


def control_program(offset: int = 0, body: str = E_SERIES_BODY):
    return parse_program(CONTROL.format(offset=offset, body=body))


# ------------------------------------------------------------------ the wire format


def test_a_data_package_is_the_guides_layout_byte_for_byte():
    recipe = rtde.Recipe(
        3, ("timestamp", "runtime_state", "actual_q", "joint_mode"), ("DOUBLE", "UINT32", "VECTOR6D", "VECTOR6INT32")
    )
    q = [0.1, -0.2, 0.3, -0.4, 0.5, -0.6]
    data = recipe.pack([12.5, 2, q, [253] * 6])
    # by hand: uint16 size (the 3 header bytes included), uint8 'U', uint8 recipe id, then big-endian values
    body = (
        bytes([3])
        + struct.pack(">d", 12.5)
        + struct.pack(">I", 2)
        + struct.pack(">6d", *q)
        + struct.pack(">6i", *[253] * 6)
    )
    assert data == struct.pack(">HB", 3 + len(body), ord("U")) + body
    assert len(body) == 1 + 8 + 4 + 48 + 24
    values = recipe.unpack(data[4:])
    assert values == {"timestamp": 12.5, "runtime_state": 2, "actual_q": tuple(q), "joint_mode": (253,) * 6}
    with pytest.raises(ValueError, match="recipe 3: 85 bytes of values, expected 84"):
        recipe.unpack(data[4:] + b"\0")


def test_the_reader_splits_fragments_and_runs_of_packages():
    a = rtde.package(rtde.CONTROL_PACKAGE_START)
    b = rtde.package(rtde.DATA_PACKAGE, b"\x01" + struct.pack(">i", 9))
    reader = rtde.PackageReader()
    stream = a + b + a
    got = []
    for i in range(len(stream)):  # one byte at a time
        got += list(reader.feed(stream[i : i + 1]))
    assert got == [(83, b""), (85, b"\x01" + struct.pack(">i", 9)), (83, b"")]
    with pytest.raises(ValueError, match="size 2"):
        list(rtde.PackageReader().feed(struct.pack(">HB", 2, 85)))


def test_a_text_message_is_protocol_2s():
    data = rtde.text_message("hi", "src", 2)
    assert data == struct.pack(">HB", 3 + 1 + 2 + 1 + 3 + 1, ord("M")) + b"\x02hi\x03src\x02"


def test_newer_fields_are_not_found_on_older_controllers():
    assert not rtde.field_available("payload", (3, 10, 0, 0)) and rtde.field_available("payload", (3, 11, 0, 0))
    assert not rtde.field_available("payload", (5, 5, 0, 0)) and rtde.field_available("payload", (5, 5, 1, 0))
    assert not rtde.field_available("ft_raw_wrench", (3, 15, 7, 0))  # a CB3 has no flange sensor
    assert rtde.field_available("ft_raw_wrench", (5, 11, 1, 0))
    assert not rtde.field_available("output_double_register_0", (3, 3, 0, 0))  # came with 3.4
    assert not rtde.field_available("output_int_register_30", (5, 2, 0, 0)) and rtde.field_available(
        "output_int_register_30", (5, 3, 0, 0)
    )
    assert rtde.field_available("actual_q", (3, 0, 0, 0))


# ------------------------------------------------------------------ the dashboard


class Board:
    version = (5, 11, 1, 108318)
    serial = "20185500020"
    robot_mode, safety_mode = 7, 1
    remote_control = True
    stopped = unlocked = 0

    def program_state(self):
        return "PLAYING", "rtde_control"

    def stop_program(self):
        self.stopped += 1
        return True

    def unlock_protective_stop(self):
        self.unlocked += 1
        return None

    def power(self, on):
        pass

    def brake_release(self):
        pass

    def restart_safety(self):
        pass


def test_the_dashboard_answers_as_urs_and_refuses_in_local_mode():
    b = Board()
    assert dashboard.reply(b, "PolyscopeVersion")[0] == "URSoftware 5.11.1.108318 (Jul 06 2021)"
    assert dashboard.reply(b, "get serial number") == ("20185500020", False)
    assert dashboard.reply(b, "is in remote control")[0] == "true"
    assert dashboard.reply(b, "robotmode")[0] == "Robotmode: RUNNING"
    assert dashboard.reply(b, "safetystatus")[0] == "Safetystatus: NORMAL"
    assert dashboard.reply(b, "programState")[0] == "PLAYING rtde_control"
    # the replies ur_rtde's DashboardClient compares word for word
    assert dashboard.reply(b, "stop")[0] == "Stopped" and b.stopped == 1
    assert dashboard.reply(b, "unlock protective stop")[0] == "Protective stop releasing"
    assert dashboard.reply(b, "quit") == ("Disconnected", True)
    assert dashboard.reply(b, "fly away")[0] == "could not understand: 'fly away'"
    b.remote_control = False
    assert dashboard.reply(b, "is in remote control")[0] == "false"
    assert dashboard.reply(b, "stop")[0].startswith("Failed to execute: stop") and b.stopped == 1


# ------------------------------------------------------------------ ur_rtde's control script


def test_programs_are_recognised_with_their_register_offset():
    p = control_program(24)
    assert p.is_control_script and p.offset == 24 and p.name == "rtde_control" and p.calls("get_steptime")
    assert not control_program(body="    pass").calls("get_steptime")
    other = parse_program('def hello():\n  textmsg("hi")\nend\n')
    assert other is not None and not other.is_control_script
    assert parse_program('def hello():\n  textmsg("hi")\n') is None  # not ended yet
    with pytest.raises(ValueError, match="offset is 7"):
        control_program(7)


@pytest.fixture(scope="module")
def arm():
    return SimArm(0.002)


def script_for(arm, offset=0, body=E_SERIES_BODY):
    regs = RegisterFile()
    calls = []
    script = ControlScript(
        control_program(offset, body),
        regs,
        arm,
        0.002,
        lambda v, f: calls.append(("watchdog", v, f)),
        lambda: calls.append(("pstop",)),
    )
    script.cycle()  # the lines before the loop: ready
    return script, regs, calls


def test_the_script_signals_ready_runs_a_command_once_and_is_ready_after_the_clear(arm):
    script, regs, calls = script_for(arm)
    assert regs.output_int[0] == READY
    regs.input_int[0] = 40  # getTCPOffset, not real-time
    script.cycle()
    assert regs.output_int[0] == DONE and regs.output_double[:6] == list(arm.tcp_offset)
    regs.output_double[0] = -1.0
    script.cycle()  # still 40: the script does not run it again
    assert regs.output_double[0] == -1.0 and script.processed == [40]
    regs.input_int[0] = 0  # the client's clear
    script.cycle()
    assert regs.output_int[0] == READY


def test_get_step_time_is_written_one_cycle_late_and_not_at_all_by_a_cb3_script(arm):
    script, regs, _ = script_for(arm)
    regs.input_int[0] = 26
    assert regs.output_double[0] == 0.0  # what the client reads right after sending: nothing yet
    script.cycle()
    assert regs.output_double[0] == 0.002 and regs.output_int[0] == READY  # real-time: ready, not done
    # ur_rtde deletes get_steptime's line (it needs 5.4) from a CB3's script
    script, regs, _ = script_for(arm, body="    tcp_offset = get_tcp_offset()")
    regs.input_int[0] = 26
    script.cycle()
    assert regs.output_double[0] == 0.0


def test_set_watchdog_watches_the_command_register_at_the_programs_offset(arm):
    for offset in (0, 24):
        script, regs, calls = script_for(arm, offset)
        regs.input_int[offset] = 35
        regs.input_double[offset] = 12.5
        script.cycle()
        assert calls == [("watchdog", f"input_int_register_{offset}", 12.5)]
        assert regs.output_int[offset] == DONE


def test_speed_stop_holds_the_loop_until_the_arm_is_at_rest():
    arm = SimArm(0.002)
    script, regs, _ = script_for(arm)
    regs.input_int[0], regs.input_double[:8] = 9, [0.3, 0, 0, 0, 0, 0, 10.0, 0.002]
    for _ in range(20):
        script.cycle()
        arm.step()
    assert arm.v_ref[0] == pytest.approx(0.3)
    regs.input_int[0], regs.input_double[0] = 15, 4.0  # speedStop(4 rad/s²)
    cycles = 0
    while regs.output_int[0] != DONE:
        script.cycle()
        arm.step()
        cycles += 1
        assert cycles < 1000
    # 0.3 rad/s at 4 rad/s² is 75 ms: the answer comes after the arm stopped, not before
    assert cycles * 0.002 == pytest.approx(0.3 / 4.0, abs=0.0041) and arm.at_rest


def test_stop_script_ends_the_program(arm):
    script, regs, _ = script_for(arm)
    regs.input_int[0] = 255
    script.cycle()
    assert not script.running and regs.output_int[0] == READY  # no done signal: the program ended


# ------------------------------------------------------------------ the controller


def make_controller(**kwargs):
    arm = SimArm(0.002)
    ctrl = Controller(arm, rate_hz=500.0, version=(5, 11, 1, 0), program_start_delay=0.0, **kwargs)
    ctrl.load_program(control_program())
    ctrl.cycle()  # starts the program
    ctrl.cycle()  # its first loop iteration: ready
    return ctrl, arm


def speedj(qd):
    return {"input_int_register_0": 9, **{f"input_double_register_{i}": v for i, v in enumerate([*qd, 10.0, 0.002])}}


def test_two_packages_in_one_cycle_the_script_sees_the_second():
    ctrl, arm = make_controller()
    assert ctrl.runtime_state == 2 and ctrl.regs.output_int[0] == READY
    ctrl.receive(speedj([0.2, 0, 0, 0, 0, 0]))
    ctrl.receive({"input_int_register_0": 0})  # kickWatchdog right behind it
    ctrl.cycle()
    ctrl.cycle()
    assert arm.v_ref[0] == 0.0  # the speedJ was never run
    ctrl.receive(speedj([0.2, 0, 0, 0, 0, 0]))
    ctrl.cycle()
    ctrl.receive({"input_int_register_0": 0})  # a cycle later
    ctrl.cycle()
    # ran, and the speed thread goes on after the clear: two cycles of the 10 rad/s² ramp
    assert arm.v_ref[0] == pytest.approx(0.04)


def test_an_output_stream_gets_every_cycle_its_rate_falls_on():
    ctrl, _ = make_controller()
    names = ("timestamp", "output_int_register_0")
    sent: list[bytes] = []
    ctrl.streams.append(OutputStream(rtde.Recipe(1, names, ("DOUBLE", "INT32")), 125.0, sent.append, started=True))
    k0 = ctrl.k
    for _ in range(40):
        ctrl.cycle()
    stamps = [struct.unpack(">d", p[4:12])[0] for p in sent]
    assert len(sent) == 10 and np.allclose(np.diff(stamps), 0.008)  # 125 Hz of a 500 Hz controller
    assert stamps[0] == pytest.approx((k0 + 3) * 0.002)  # the timestamp is the cycle's: k·dt


def test_a_protective_stop_brakes_stops_the_program_and_unlocks_after_its_delay():
    ctrl, arm = make_controller(unlock_delay=0.05)
    ctrl.receive(speedj([0.4, 0, 0, 0, 0, 0]))
    for _ in range(50):
        ctrl.cycle()
    ctrl.protective_stop()
    assert ctrl.safety_status_bits == (1 << 2) | (1 << 10) and ctrl.runtime_state == 1
    assert ctrl.unlock_protective_stop().startswith("Cannot unlock protective stop until 0.05s")
    for _ in range(30):
        ctrl.cycle()
    assert arm.at_rest  # 0.4 rad/s at 10 rad/s² takes 40 ms
    import time

    time.sleep(0.06)
    assert ctrl.unlock_protective_stop() is None and ctrl.safety_status_bits == 1


def test_an_emergency_stop_powers_the_arm_off_until_released_powered_and_unbraked():
    ctrl, _ = make_controller()
    ctrl.emergency_stop()
    assert ctrl.safety_status_bits == (1 << 6) | (1 << 7) | (1 << 10) and ctrl.robot_mode == 3
    ctrl.power(True)
    assert ctrl.robot_mode == 3  # the button is still pressed
    ctrl.release_emergency_stop()
    ctrl.power(True)
    ctrl.brake_release()
    assert ctrl.robot_mode == 7 and ctrl.safety_mode == 1 and ctrl.robot_status_bits == 1  # no program


def test_a_late_stream_keeps_its_order():
    ctrl, _ = make_controller()
    ctrl.streams.append(OutputStream(rtde.Recipe(1, ("timestamp",), ("DOUBLE",)), 500.0, lambda b: None, started=True))
    ctrl.faults.jitter = 0.01
    for _ in range(50):
        ctrl.cycle()
    due = [d for d, _, _ in ctrl.outbox]
    assert len(due) == 50 and all(b >= a for a, b in zip(due, due[1:]))


# ------------------------------------------------------------------ the arm


def test_speedj_ramps_the_leading_joint_at_a_and_the_others_with_it():
    arm = SimArm(0.002)
    arm.speedj([0.2, -0.1, 0.05, 0, 0, 0], 5.0)
    for k in range(1, 30):
        arm.step()
        lead = min(5.0 * 0.002 * k, 0.2)
        np.testing.assert_allclose(arm.v_ref, np.array([0.2, -0.1, 0.05, 0, 0, 0]) * lead / 0.2, atol=1e-12)
    assert arm.out_of_limits == 0
    arm.speedj([4.0, 0, 0, 0, 0, 0], 100.0)  # beyond the joint speed and ur_rtde's 40 rad/s²
    for _ in range(200):
        arm.step()
    assert arm.out_of_limits == 2 and arm.v_ref[0] == pytest.approx(JOINT_SPEED_LIMIT)


def test_the_tcp_pose_is_the_flange_and_the_installations_tcp_as_urs_kinematics_say():
    pytest.importorskip("pinocchio")
    from coassist.robot.kinematics import UR5Kinematics

    arm = SimArm(0.002)
    np.testing.assert_allclose(arm.tcp_pose[:3], (-0.10, -0.615, 0.20), atol=1e-9)  # the start, tool down
    assert abs(np.linalg.norm(arm.tcp_pose[3:]) - math.pi) < 1e-9  # a rotation vector of angle π about x
    arm.speedj([0.1, -0.2, 0.3, 0.2, -0.1, 0.3], 2.0)
    for _ in range(100):
        arm.step()
    for offset in (arm.tcp_offset.copy(), np.array([0.01, -0.02, 0.15, 0.1, 0.2, -0.3])):
        arm.set_tcp(offset)
        p, R = UR5Kinematics(tcp_offset=offset).forward(arm.q)  # pinocchio on the URDF: independent of MuJoCo
        np.testing.assert_allclose(arm.tcp_position, p, atol=1e-9)
        np.testing.assert_allclose(arm.tcp_rotation, R, atol=1e-9)


def test_the_tcp_force_is_the_external_wrench_in_base_axes_about_the_tcp():
    arm = SimArm(0.002)
    assert np.abs(arm.tcp_force[:3]).max() < 0.25  # at rest the payload's weight is compensated
    assert arm.ft_raw[2] == pytest.approx(-0.3 * 9.81, abs=0.25)  # the raw reading holds it: the 0.3 kg mount
    arm.operator = ScriptedForce.constant([10.0, 0.0, -5.0, 0, 0, 0])  # a hand pushes +x and down, at the handle
    for _ in range(50):
        arm.step()
    np.testing.assert_allclose(arm.tcp_force[:3], [10.0, 0.0, -5.0], atol=0.3)  # UR's sign: the push's
    assert np.abs(arm.tcp_force[3:]).max() < 0.02  # the TCP is the handle: no lever
    arm.set_tcp([0, 0, 0, 0, 0, 0])  # the TCP at the flange, 6 cm above the hand (tool down)
    arm.step()
    r = np.array([0.0, 0.0, -0.06])  # hand − flange, base frame
    np.testing.assert_allclose(arm.tcp_force[3:], np.cross(r, [10.0, 0.0, -5.0]), atol=0.03)
    arm.set_payload(0.0, None)  # no payload set: the tool's weight shows
    arm.step()
    assert arm.tcp_force[2] == pytest.approx(-5.0 - 0.3 * 9.81, abs=0.3)
    arm.zero_ftsensor()
    arm.step()
    assert np.abs(arm.tcp_force[:3]).max() < 0.3  # zeroed: the present load reads 0


def test_movej_and_movel_reach_their_targets_movel_on_a_straight_line():
    arm = SimArm(0.002)
    q1 = arm.q + np.array([0.2, -0.1, 0.1, 0.0, 0.1, -0.2])
    arm.movej(q1, 1.0, 2.0)
    n = 0
    while not arm.move_done:
        arm.step()
        n += 1
        assert n < 5000
    np.testing.assert_allclose(arm.q, q1, atol=2e-3)
    p0 = arm.tcp_position.copy()
    goal = arm.tcp_pose.copy()
    goal[:3] += [0.1, 0.05, -0.05]
    arm.movel(goal, 0.2, 1.0)
    path = []
    while not arm.move_done:
        arm.step()
        path.append(arm.tcp_position.copy())
    path = np.array(path)
    d = goal[:3] - p0
    off_line = np.linalg.norm(np.cross(path - p0, d / np.linalg.norm(d)), axis=1)
    assert off_line.max() < 1e-3 and np.linalg.norm(arm.tcp_position - goal[:3]) < 1e-3


def test_stopj_decelerates_at_its_rate_and_a_safety_stop_overrides_commands():
    arm = SimArm(0.002)
    arm.speedj([0.5, 0, 0, 0, 0, 0], 40.0)
    for _ in range(20):
        arm.step()
    arm.stop(2.0)
    arm.step()
    assert arm.v_ref[0] == pytest.approx(0.5 - 2.0 * 0.002)
    arm.safety_stop()
    arm.speedj([0.5, 0, 0, 0, 0, 0], 1.0)  # refused while stopped
    for _ in range(100):
        arm.step()
    assert arm.at_rest and arm.mode == "idle"


def test_a_config_names_its_bad_field():
    with pytest.raises(ValueError, match="URSimConfig.series"):
        URSimConfig(series="cb2")
    with pytest.raises(ValueError, match="URSimConfig.version"):
        URSimConfig(version=(5, 11))
    with pytest.raises(ValueError, match="URSimConfig.rt_priority"):
        URSimConfig(rt_priority=0)
    with pytest.raises(ValueError, match="URSimConfig.start"):
        URSimConfig(start=(0.0, math.nan, 0.2))
    assert URSimConfig(series="cb3").rate == 125.0 and URSimConfig(series="cb3").controller_version[0] == 3


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--series", "cb2"], "--series must be one of ('e-series', 'cb3'), got 'cb2'"),
        (["--software", "5.x"], "--software '5.x': give four numbers"),
        (["--object", "box"], "--object must be one of ('handle', 'board', 'heavy'), got 'box'"),
        (["--start", "0,nan,0.2"], "--start must be 3 finite numbers"),
        (["--rt-priority", "120"], "--rt-priority must be an int in [1, 99]"),
    ],
)
def test_ur_sim_names_the_option_it_refuses(args, words):
    from typer.testing import CliRunner

    from coassist.cli import app

    result = CliRunner().invoke(app, ["ur-sim", *args])
    assert result.exit_code == 2 and words in result.output, result.output


def test_the_simulator_process_answers_its_stdin_commands():
    from coassist.robot.ur_sim.process import URSim, _command

    sim = URSim(URSimConfig(host="127.0.0.1"))  # not started: the commands act on its state only
    assert _command(sim, "protective-stop") == ("ok", False) and sim.controller.safety_mode == 3
    assert _command(sim, "delay 0.01 0.002") == ("ok", False) and sim.controller.faults.jitter == 0.002
    assert _command(sim, "delay -1")[0].startswith("error: late must be")
    assert _command(sim, "push 1 2")[0].startswith("error: unknown command")
    assert _command(sim, "push 10 0 0") == ("ok", False) and sim.arm.operator is not None
    assert _command(sim, "remote off") == ("ok", False) and not sim.controller.faults.remote_control
    reply, _ = _command(sim, "status")
    assert reply.startswith("status {") and '"safety_mode": 3' in reply
    assert _command(sim, "quit") == ("ok", True)


def test_a_process_started_ahead_builds_nothing_until_its_config_and_ends_without_one():
    from coassist.robot.ur_sim.process import spawn

    proc = spawn()  # ``python -m coassist.robot.ur_sim -``: waits for its config on stdin
    assert proc.stdin is not None and proc.stdout is not None
    proc.stdin.close()  # its parent gone before it was needed
    assert proc.wait(60) == 0 and proc.stdout.read() == ""  # no simulator built, no port bound, no error


def test_the_simulators_hand_is_asked_once_per_its_own_tick():
    from coassist.robot.ur_sim.hand import TickedHand

    class Counting:
        dt = 0.008

        def __init__(self):
            self.calls = []

        def force(self, t, pose, twist):
            self.calls.append(t)
            return np.full(6, float(len(self.calls)))

    inner = Counting()
    hand = TickedHand(inner)
    assert not hand.force(0.0, np.zeros(6), np.zeros(6)).any() and inner.calls == []  # still until go
    hand.go()
    seen = [hand.force(1.0 + 0.002 * i, np.zeros(6), np.zeros(6))[0] for i in range(20)]  # 500 Hz for 40 ms
    # asked at its tick 0 (the first cycle after go), then every 8 ms: 4 controller cycles each
    assert (
        inner.calls == pytest.approx([1.0, 1.008, 1.016, 1.024, 1.032])
        and seen == [1] * 4 + [2] * 4 + [3] * 4 + [4] * 4 + [5] * 4
    )
    # with the lead the simulator gives it (one 2 ms cycle): its ticks fall on the cycle go arrived in
    # (0.998 s, whose state the client's first tick reads) + 8 ms each; tick 0 asked at the first call
    inner = Counting()
    hand = TickedHand(inner, lead=0.002)
    hand.go()
    seen = [hand.force(1.0 + 0.002 * i, np.zeros(6), np.zeros(6))[0] for i in range(20)]
    assert inner.calls == pytest.approx([1.0, 1.006, 1.014, 1.022, 1.030, 1.038])
    assert seen == [1] * 3 + [2] * 4 + [3] * 4 + [4] * 4 + [5] * 4 + [6]


def test_the_simulators_coassist_commands_and_a_reset_to_the_start():
    from coassist.robot.ur_sim.hand import reply

    ctrl, arm = make_controller()
    assert reply(ctrl, "e-series", "coassist hello") == "coassist ur-sim e-series 500 Hz"
    assert reply(ctrl, "e-series", "coassist start 0.05 -0.5 0.3") == "ok"
    np.testing.assert_allclose(arm.tcp_position, [0.05, -0.5, 0.3], atol=1e-6)
    assert arm.at_rest and np.abs(arm.qd).max() == 0.0
    assert reply(ctrl, "e-series", "coassist start 5 0 0").startswith("error: start [5.0, 0.0, 0.0] is not reachable")
    values = [float(v) for v in reply(ctrl, "e-series", "coassist handle").split()]
    np.testing.assert_allclose(values[:3], [0.05, -0.5, 0.3], atol=1e-6)  # the handle is the TCP (the handle tool)
    assert reply(ctrl, "e-series", "coassist hand {").startswith("error:")
    assert reply(ctrl, "e-series", "coassist hand go").startswith("error: no hand")
    assert reply(ctrl, "e-series", "coassist fly").startswith("could not understand")
