"""Tests of the MuJoCo UR5 world (coassist.robot.mujoco_world, coassist.robot.ur5_mjcf).

Independent references: UR's published standard-DH table (forward kinematics by hand),
the masses and sizes of coassist.scenario.objects with the tool geometry's centres (statics
by hand), finite differences of the reported poses, scipy's Rotation, and the
admittance's analytic steady state F/D.
"""

from __future__ import annotations

import math
from importlib import metadata

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="the MuJoCo world needs the robot extra: pip install 'coassist[robot]'")
try:
    metadata.distribution("example-robot-data")
except metadata.PackageNotFoundError:
    pytest.skip("the UR5 model needs example-robot-data: pip install 'coassist[robot]'", allow_module_level=True)

from scipy.spatial.transform import Rotation  # noqa: E402

from coassist.robot.arm_mjcf import build_arm_model, build_arm_spec  # noqa: E402
from coassist.robot.mujoco_world import (  # noqa: E402
    DEFAULT_START,
    TOOL_DOWN,
    FTSensorModel,
    MujocoUR5World,
    rotation_vector,
    tool_down_ik,
)
from coassist.robot.ur5_mjcf import MOUNT_MASS, TORQUE_LIMITS, tool_geometry  # noqa: E402
from coassist.runtime.world import Command, RobotState, World  # noqa: E402
from coassist.scenario.objects import OBJECTS  # noqa: E402
from coassist.scenario.tasks import TASK_KINDS, nominal_path  # noqa: E402

G = np.array([0.0, 0.0, -9.81])
QUIET = FTSensorModel(noise_force=0.0, noise_torque=0.0, rate_hz=None)

# UR5 standard DH parameters (Universal Robots).
DH_A = np.array([0.0, -0.425, -0.39225, 0.0, 0.0, 0.0])
DH_D = np.array([0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823])
DH_ALPHA = np.array([math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0])


def dh_flange(q) -> np.ndarray:
    """4×4 pose of the flange in the UR base frame from the standard DH table."""
    T = np.eye(4)
    for a, d, al, th in zip(DH_A, DH_D, DH_ALPHA, q):
        ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
        T = T @ np.array(
            [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0, sa, ca, d], [0, 0, 0, 1]]
        )
    return T


class ConstantHand:
    """A hand pushing with a constant wrench (base frame, at the handle)."""

    def __init__(self, wrench) -> None:
        self.wrench = np.asarray(wrench, dtype=float)
        self.calls = []

    def force(self, t, hand_pose, hand_twist):
        self.calls.append((t, hand_pose.copy(), hand_twist.copy()))
        return self.wrench


def expected_tool(tool: str) -> tuple[float, np.ndarray]:
    """Mass and centre of mass (tool0 frame) of the tool from the objects and the part centres."""
    geo = tool_geometry(tool)
    masses = np.array([p.mass for p in geo.parts])
    centres = np.array([p.pos for p in geo.parts])
    return float(masses.sum()), masses @ centres / masses.sum()


def hold(world: MujocoUR5World, seconds: float) -> RobotState:
    for _ in range(round(seconds / world.dt)):
        world.apply(Command(qd=np.zeros(6)))
    return world.read()


# ----------------------------------------------------------------------------- model


def test_model_frames_match_the_dh_table():
    model = build_arm_model("ur5", "handle")
    data = mujoco.MjData(model)
    assert model.nq == 6 and model.nv == 6 and model.nu == 6
    tool0 = model.body("tool0").id
    # q = 0: the flange at (a2 + a3, −(d4 + d6), d1 − d5) in the base frame.
    mujoco.mj_kinematics(model, data)
    expected = np.array([DH_A[1] + DH_A[2], -(DH_D[3] + DH_D[5]), DH_D[0] - DH_D[4]])
    np.testing.assert_allclose(data.xpos[tool0], expected, atol=1e-4)
    np.testing.assert_allclose(data.xpos[tool0], [-0.81725, -0.19145, -0.00549], atol=1e-4)
    # Random joints: position and orientation of the flange equal the DH chain's (the
    # joint signs and zeros are the UR controller's).
    rng = np.random.default_rng(3)
    for q in rng.uniform(-math.pi, math.pi, (20, 6)):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        T = dh_flange(q)
        np.testing.assert_allclose(data.xpos[tool0], T[:3, 3], atol=1e-4)
        np.testing.assert_allclose(data.xmat[tool0].reshape(3, 3), T[:3, :3], atol=1e-4)


@pytest.mark.parametrize("tool", ["handle", "board", "heavy"])
def test_tool_mass_below_the_sensor(tool):
    model = build_arm_model("ur5", tool)
    mass_below = model.body_subtreemass[model.body("tool0").id]
    assert mass_below == pytest.approx(OBJECTS[tool].mass + MOUNT_MASS, rel=1e-9)
    world = MujocoUR5World(tool, sensor=QUIET)
    mass, com = world.tool_mass_and_com()
    m_exp, c_exp = expected_tool(tool)
    assert mass == pytest.approx(m_exp, rel=1e-9)
    # from the TCP, the point the reading's torque is about: the TCP is the kinematics' (the flange's frame is the
    # sensor's on the UR5)
    np.testing.assert_allclose(world.tcp_lever, world.flange_to_tcp()[:3], atol=1e-12)
    np.testing.assert_allclose(com + world.tcp_lever, c_exp, atol=1e-9)
    if tool == "board":
        # The board's COM 0.2 m off the cup toward the operator (−y base = +y tool).
        board = OBJECTS["board"]
        c_board = (board.mass * 0.20 + MOUNT_MASS * 0.0) / (board.mass + MOUNT_MASS)
        assert com[1] + world.tcp_lever[1] == pytest.approx(c_board, rel=1e-9)
        hand = world.hand_pose()[0][:3] - world.read().tool_pose[:3]
        np.testing.assert_allclose(hand[:2], board.grasp_offset, atol=1e-9)  # hand 0.61 m from the cup, −y


def test_model_has_no_contacts_and_ur5_torque_limits():
    model = build_arm_model("ur5", "board")
    assert np.all(model.geom_contype == 0) and np.all(model.geom_conaffinity == 0)
    np.testing.assert_allclose(model.actuator_forcerange, np.c_[-TORQUE_LIMITS, TORQUE_LIMITS])
    assert model.numeric("servo_time_constant").data[0] == 0.02
    spec = build_arm_spec("ur5", "handle")
    spec.compile()
    xml = spec.to_xml()
    assert "ft_sensor" in xml and "<force" in xml and "<torque" in xml
    assert mujoco.MjModel.from_xml_string(xml).nq == 6


# ----------------------------------------------------------------------------- start pose


def test_start_pose_is_the_requested_tcp_pointing_down():
    world = MujocoUR5World("handle", sensor=QUIET)
    s = world.read()
    np.testing.assert_allclose(s.tool_pose[:3], DEFAULT_START, atol=1e-6)
    R = Rotation.from_rotvec(s.tool_pose[3:]).as_matrix()
    np.testing.assert_allclose(R, TOOL_DOWN, atol=1e-6)
    # Elbow up (the elbow above the shoulder and the wrist), wrist down (q5 = +π/2).
    d = world.data
    elbow = d.xpos[world.model.body("forearm_link").id][2]
    assert elbow > d.xpos[world.model.body("wrist_1_link").id][2] > d.xpos[world.model.body("shoulder_link").id][2]
    assert world.q_start[4] == pytest.approx(math.pi / 2, abs=1e-6)
    np.testing.assert_array_equal(s.q, world.q_start)
    assert s.t == 0.0 and s.wrench_seq == 0


def test_the_tasks_are_reachable_on_one_branch():
    model = build_arm_model("ur5", "handle")
    data = mujoco.MjData(model)
    site = model.site("tcp").id
    jp, jr = np.zeros((3, 6)), np.zeros((3, 6))
    q0 = tool_down_ik(model, DEFAULT_START)
    for kind in TASK_KINDS:
        for x, y in nominal_path(kind).points[::100]:
            q = tool_down_ik(model, [x, y, 0.2])
            # Same branch as the start (elbow up, wrist down) and away from singularities.
            assert q[4] == pytest.approx(math.pi / 2, abs=1e-3)
            assert np.all(np.sign(q[1:4]) == np.sign(q0[1:4]))
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            mujoco.mj_jacSite(model, data, jp, jr, site)
            assert np.linalg.svd(np.vstack([jp, jr]), compute_uv=False)[-1] > 0.05, (kind, x, y)
    with pytest.raises(ValueError, match="start"):
        tool_down_ik(model, [0.5, -0.9, 0.2])  # beyond the UR5's reach


# ----------------------------------------------------------------------------- servo


def test_servo_is_a_first_order_lag():
    tau = 0.02
    world = MujocoUR5World("handle", control_dt=0.002, servo_time_constant=tau, sensor=QUIET)
    cmd = np.array([0.2, -0.15, 0.2, 0.3, -0.3, 0.5])
    t, qd = [0.0], [world.read().qd]
    for _ in range(150):
        world.apply(Command(qd=cmd))
        s = world.read()
        t.append(s.t)
        qd.append(s.qd)
    t, qd = np.array(t), np.array(qd)
    for j in range(6):
        frac = qd[:, j] / cmd[j]
        k = int(np.argmax(frac >= 1.0 - math.exp(-1.0)))
        t63 = t[k - 1] + (1.0 - math.exp(-1.0) - frac[k - 1]) / (frac[k] - frac[k - 1]) * (t[k] - t[k - 1])
        assert t63 == pytest.approx(tau, rel=0.3), j
        assert qd[-1, j] == pytest.approx(cmd[j], rel=0.01)
        # First-order-like: no overshoot beyond 1 %.
        assert np.max(frac) < 1.01


@pytest.mark.parametrize("tool", ["handle", "heavy"])
def test_arm_holds_still_under_gravity(tool):
    world = MujocoUR5World(tool, sensor=QUIET)
    s = hold(world, 1.0)
    assert np.max(np.abs(s.q - world.q_start)) < 1e-4
    assert np.max(np.abs(s.qd)) < 1e-4
    assert world.invalid_commands == 0


def test_twist_is_linear_then_angular_in_the_base_frame():
    world = MujocoUR5World("handle", control_dt=0.002, sensor=QUIET)
    cmd = np.array([0.1, -0.1, 0.15, 0.2, -0.2, 0.4])
    for _ in range(100):  # reach the commanded speed
        world.apply(Command(qd=cmd))
    s0 = world.read()
    world.apply(Command(qd=cmd))
    s1 = world.read()
    world.apply(Command(qd=cmd))
    s2 = world.read()
    dt = s2.t - s0.t
    v_fd = (s2.tool_pose[:3] - s0.tool_pose[:3]) / dt
    R0 = Rotation.from_rotvec(s0.tool_pose[3:])
    R2 = Rotation.from_rotvec(s2.tool_pose[3:])
    w_fd = (R2 * R0.inv()).as_rotvec() / dt  # base-frame angular velocity
    np.testing.assert_allclose(s1.tool_twist[:3], v_fd, atol=2e-3 * np.linalg.norm(v_fd))
    np.testing.assert_allclose(s1.tool_twist[3:], w_fd, atol=2e-3 * np.linalg.norm(w_fd))
    J = world.tcp_jacobian()
    np.testing.assert_allclose(s2.tool_twist, J @ s2.qd, atol=1e-9)


# ----------------------------------------------------------------------------- sensor


@pytest.mark.parametrize("tool", ["handle", "board", "heavy"])
def test_static_reading_is_the_tools_weight(tool):
    world = MujocoUR5World(tool, sensor=QUIET)
    mass, com = expected_tool(tool)
    com = com - world.tcp_lever  # from the TCP, the point the torque is about
    for s in (world.read(), hold(world, 0.2)):
        R = s.sensor_rotation
        weight = mass * R.T @ G  # the force the tool applies to the sensor, sensor frame
        np.testing.assert_allclose(s.wrench[:3], weight, rtol=1e-3, atol=1e-3 * mass * 9.81)
        np.testing.assert_allclose(s.wrench[3:], np.cross(com, weight), atol=1e-3 * mass * 9.81 * 0.1)
    # With the tool down, the weight is along +z of the sensor (its z points down).
    assert s.wrench[2] == pytest.approx(mass * 9.81, rel=1e-3)


def test_push_sign_without_gravity():
    # "A hand pushing a weightless tool along +x_sensor with 10 N reads +10 N."
    hand = ConstantHand([10.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    world = MujocoUR5World("handle", sensor=QUIET, gravity=False, operator=hand)
    s = hold(world, 0.5)
    f_base = s.sensor_rotation @ s.wrench[:3]
    np.testing.assert_allclose(f_base, [10.0, 0.0, 0.0], atol=0.05)
    # The sensor's x is the base's x at the start pose: the raw reading is +10 N too.
    assert s.wrench[0] == pytest.approx(10.0, rel=5e-3)
    assert len(hand.calls) == round(0.5 / world.dt)


@pytest.mark.parametrize("tool", ["handle", "board", "heavy"])
def test_hand_wrench_adds_exactly(tool):
    F = np.array([10.0, -6.0, 4.0])
    T = np.array([0.3, -0.2, 0.5])
    world = MujocoUR5World(tool, sensor=QUIET, operator=ConstantHand(np.r_[F, T]))
    mass, com = expected_tool(tool)
    s = hold(world, 1.0)
    R = s.sensor_rotation
    p_tcp = world.data.site_xpos[world.model.site("tcp").id]  # the point the reading's torque is about
    r_hand = world.hand_pose()[0][:3] - p_tcp
    f_base = R @ s.wrench[:3] - mass * G
    t_base = R @ s.wrench[3:] - np.cross(R @ (com - world.tcp_lever), mass * G)
    np.testing.assert_allclose(f_base, F, atol=5e-3 * np.linalg.norm(F))
    expected_t = T + np.cross(r_hand, F)
    np.testing.assert_allclose(t_base, expected_t, atol=5e-3 * np.linalg.norm(expected_t))
    # The servo holds: the push deflects the arm by about a milliradian at most (the
    # handle's light wrist_3 under the 0.5 N·m twist is the softest).
    assert np.max(np.abs(s.q - world.q_start)) < 2e-3


def test_sensor_samples_at_100_hz_and_holds():
    world = MujocoUR5World("handle", control_dt=0.008, sensor=FTSensorModel(noise_force=0.5), seed=7)
    prev = world.read()
    fresh = 0
    for _ in range(125):
        world.apply(Command(qd=np.zeros(6)))
        s = world.read()
        if s.wrench_seq != prev.wrench_seq:
            assert s.wrench_seq == prev.wrench_seq + 1
            assert not np.array_equal(s.wrench, prev.wrench)  # a new noisy sample
            fresh += 1
        else:
            np.testing.assert_array_equal(s.wrench, prev.wrench)  # held
        prev = s
    assert fresh == 100  # 1 s at 100 Hz over 125 ticks: 80 % fresh
    # At 500 Hz control, one tick in five sees a new sample.
    world = MujocoUR5World("handle", control_dt=0.002, sensor=FTSensorModel(), seed=7)
    seqs = [world.read().wrench_seq]
    for _ in range(50):
        world.apply(Command(qd=np.zeros(6)))
        seqs.append(world.read().wrench_seq)
    assert seqs[-1] == 10 and np.count_nonzero(np.diff(seqs)) == 10


def test_sensor_noise_bias_and_saturation():
    bias = (350.0, -2.0, 0.0, -40.0, 0.1, 0.0)
    world = MujocoUR5World("handle", sensor=FTSensorModel(noise_force=1.0, noise_torque=0.01, bias=bias), seed=1)
    readings = []
    for _ in range(250):
        world.apply(Command(qd=np.zeros(6)))
        readings.append(world.read().wrench)
    w = np.unique(np.array(readings), axis=0)  # one row per sample
    assert np.all(w[:, 0] == 300.0) and np.all(w[:, 3] == -30.0)  # clipped at the range
    assert np.mean(w[:, 1]) == pytest.approx(-2.0, abs=0.3)
    assert np.std(w[:, 1]) == pytest.approx(1.0, rel=0.25)
    mass, _ = expected_tool("handle")
    assert np.mean(w[:, 2]) == pytest.approx(mass * 9.81, abs=0.3)
    with pytest.raises(ValueError, match="noise_force"):
        FTSensorModel(noise_force=-1.0)
    with pytest.raises(ValueError, match="bias"):
        FTSensorModel(bias=(0.0, 1.0))


# ----------------------------------------------------------------------------- determinism


def _run(seed):
    class Wavy:
        def force(self, t, pose, twist):
            return np.array([8.0 * math.sin(3.0 * t), 4.0, 2.0 * math.cos(t), 0.0, 0.1, 0.0])

    world = MujocoUR5World("board", sensor=FTSensorModel(noise_force=0.3), seed=seed, operator=Wavy())
    cmds = np.random.default_rng(0).normal(0.0, 0.1, (100, 6))
    out = []
    for c in cmds:
        world.apply(Command(qd=c))
        s = world.read()
        out.append(np.concatenate([[s.t, s.wrench_seq], s.q, s.qd, s.tool_pose, s.tool_twist, s.wrench]))
    return np.array(out)


def test_same_seed_is_bit_identical():
    a, b = _run(5), _run(5)
    assert np.array_equal(a, b)
    c = _run(6)
    assert not np.array_equal(a[:, -6:], c[:, -6:])  # noise differs
    np.testing.assert_array_equal(a[:, :2], c[:, :2])


def test_the_sensor_noise_is_the_trials_sensor_stream_not_the_tasks():
    # default_rng(seed) is SeedSequence([s, 0]): the task's own stream (where the obstacle sits), which the sensor
    # drew its noise from (a review); it is the trial's sensor stream, the point-mass world's
    from coassist.scenario.seeds import task_rng, trial_rngs

    sigma = 0.5
    world = MujocoUR5World("handle", sensor=FTSensorModel(noise_force=sigma, noise_torque=0.0, rate_hz=None), seed=11)
    quiet = MujocoUR5World("handle", sensor=QUIET, seed=11)
    noise = (world.read().wrench - quiet.read().wrench)[:3] / sigma  # the first sample's draws, at rest
    np.testing.assert_allclose(noise, trial_rngs(11, 3)[2].standard_normal(6)[:3], rtol=1e-9, atol=1e-9)
    assert not np.allclose(noise, task_rng(11).standard_normal(6)[:3], atol=1e-3)


# ----------------------------------------------------------------------------- closed loop


@pytest.mark.parametrize("tool", ["handle", "heavy"])
def test_admittance_smoke_loop_reaches_F_over_D(tool):
    M, D, F, dt = 10.0, 100.0, 10.0, 0.008
    world = MujocoUR5World(tool, control_dt=dt, operator=ConstantHand([F, 0, 0, 0, 0, 0]), seed=2)
    mass, _ = world.tool_mass_and_com()
    v = 0.0
    speeds = []
    for _ in range(round(1.5 / dt)):
        s = world.read()
        f = s.sensor_rotation @ s.wrench[:3] - mass * G  # payload compensated, base frame
        v += dt / M * (f[0] - D * v)
        qd = np.linalg.pinv(world.tcp_jacobian()) @ np.array([v, 0.0, 0.0, 0.0, 0.0, 0.0])
        world.apply(Command(qd=qd))
        speeds.append(s.tool_twist[0])
    assert np.mean(speeds[-25:]) == pytest.approx(F / D, rel=0.05)
    s = world.read()
    assert abs(s.tool_pose[1] - DEFAULT_START[1]) < 2e-3 and abs(s.tool_pose[2] - DEFAULT_START[2]) < 2e-3


# ----------------------------------------------------------------------------- protocol and safety


def test_world_protocol_and_validation(monkeypatch):
    world = MujocoUR5World("handle", sensor=QUIET)
    assert isinstance(world, World)
    assert world.command_space == "joint_velocity" and world.n_joints == 6
    assert world.dt == 0.008 and world.n_substeps == 4 and world.realtime is False
    assert MujocoUR5World("handle", control_dt=0.002).n_substeps == 1
    for kwargs, name in [
        ({"control_dt": 0.003, "physics_dt": 0.002}, "control_dt"),
        ({"control_dt": -0.008}, "control_dt"),
        ({"physics_dt": 0.01}, "physics_dt"),
        ({"start": (0.0, 0.0)}, "start"),
        ({"start": (2.0, 0.0, 0.2)}, "start"),
        ({"servo_time_constant": 0.0}, "servo_time_constant"),
        ({"sensor": "ft300"}, "sensor"),
        ({"operator": object()}, "operator"),
        ({"seed": 1.5}, "seed"),
        ({"tcp_offset": (0.0, 0.0)}, "tcp_offset"),
    ]:
        with pytest.raises(ValueError, match=name):
            MujocoUR5World("handle", **kwargs)
    with pytest.raises(ValueError, match="tool"):
        MujocoUR5World("piano")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(RuntimeError, match="display"):
        MujocoUR5World("handle", view=True)


def test_bad_commands_never_reach_the_physics():
    world = MujocoUR5World("handle", sensor=QUIET)
    for qd in (np.full(6, np.nan), np.array([0.1, 0.0, np.inf, 0.0, 0.0, 0.0]), np.zeros(5), None, "fast"):
        world.apply(Command(qd=qd))
    assert world.invalid_commands == 5
    s = world.read()
    assert np.all(np.isfinite(s.q)) and np.max(np.abs(s.q - world.q_start)) < 1e-6

    class BadHand:
        def force(self, t, pose, twist):
            return np.array([np.nan, 0.0, 0.0])

    world = MujocoUR5World("handle", sensor=QUIET, operator=BadHand())
    s = hold(world, 0.1)
    assert world.invalid_hand_wrenches == round(0.1 / world.dt)
    assert np.all(np.isfinite(s.wrench))


def test_stop_protective_stop_and_close():
    world = MujocoUR5World("handle", sensor=QUIET)
    for _ in range(50):
        world.apply(Command(qd=np.full(6, 0.3)))
    assert np.max(np.abs(world.read().qd)) > 0.29
    world.apply(Command(qd=np.full(6, 0.3), stop=True))
    assert np.max(np.abs(world.read().qd)) < 0.3
    world.stop()
    assert np.max(np.abs(world.read().qd)) < 1e-3
    world.apply(Command(qd=np.full(6, 0.3)))
    world.trigger_protective_stop()
    world.stop()
    q = world.read().q
    for _ in range(20):  # commands are ignored during the protective stop
        world.apply(Command(qd=np.full(6, 0.3)))
    s = world.read()
    assert s.protective_stop and not s.emergency_stop
    assert np.max(np.abs(s.q - q)) < 1e-4
    t = s.t
    world.close()
    world.close()  # twice is fine
    assert world.read().t >= t
    with pytest.raises(RuntimeError, match="close"):
        world.apply(Command(qd=np.zeros(6)))


def test_rotation_vector_matches_scipy():
    rots = Rotation.random(50, random_state=4)
    for r in rots:
        np.testing.assert_allclose(
            Rotation.from_rotvec(rotation_vector(r.as_matrix())).as_matrix(), r.as_matrix(), atol=1e-12
        )
        assert np.linalg.norm(rotation_vector(r.as_matrix())) <= math.pi + 1e-12
    np.testing.assert_allclose(rotation_vector(np.eye(3)), np.zeros(3))
    np.testing.assert_allclose(np.abs(rotation_vector(TOOL_DOWN)), [math.pi, 0.0, 0.0], atol=1e-12)


def test_realtime_paces_apply_to_the_wall_clock():
    import time

    world = MujocoUR5World("handle", sensor=QUIET, realtime=True)
    assert world.realtime is True
    t0 = time.perf_counter()
    for _ in range(25):
        world.apply(Command(qd=np.zeros(6)))
    assert time.perf_counter() - t0 >= 24 * world.dt  # the first period anchors the clock


@pytest.mark.parametrize("tool", ["handle", "board"])
def test_the_readings_torque_is_about_the_tcp_as_a_urs(tool):
    # a UR controller reports its TCP force with the torque about the TCP; the MuJoCo world's sensor sits at the
    # flange, and about the flange a pure push at the handle turned a full-pose drive's tool 4.3°. The same push
    # through the pipeline: the UR simulator's actual_TCP_force and the MuJoCo world's hand agree
    from coassist.robot.ur_sim.arm import SimArm
    from coassist.runtime.wrench import WrenchConfig, WrenchPipeline

    push = ConstantHand([10.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    world = MujocoUR5World(tool, sensor=QUIET, operator=push)
    mass, com = world.tool_mass_and_com()
    config = WrenchConfig(tool_mass=mass, tool_com=tuple(com), cutoff_hz=None, deadband_force=0, deadband_torque=0)
    pipeline = WrenchPipeline(config, world.dt)
    arm = SimArm(0.008, tool=tool, sensor=QUIET)
    arm.operator = push
    for _ in range(50):
        world.apply(Command(qd=np.zeros(6)))
        s = world.read()
        hand = pipeline.update(s.wrench, s.sensor_rotation, s.wrench_seq, s.t).hand
        arm.step()
    r = world.hand_pose()[0][:3] - world.read().tool_pose[:3]  # the hand from the TCP, base frame
    np.testing.assert_allclose(hand[:3], [10.0, 0.0, 0.0], atol=0.05)
    np.testing.assert_allclose(hand[3:], np.cross(r, [10.0, 0.0, 0.0]), atol=0.01)  # 0 at the handle's TCP
    np.testing.assert_allclose(arm.tcp_force, hand, atol=0.01)
