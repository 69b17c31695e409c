"""ROS 2: ``ros2`` (the controller as a node) and ``ros2-watchdog`` (zeros when its commands stop)."""

from __future__ import annotations

from pathlib import Path

import typer

from coassist.cli._arm_runs import (
    DRIVE_OPTIONS,
    confirm_move,
    intent_option,
    run_out,
    write_finished,
    write_interrupted,
    write_run,
)
from coassist.cli._common import (
    ARM_CONTROLLER_HELP,
    ASK_WAY_HELP,
    INTENT_DEFAULT_HELP,
    PERSON_HELP,
    SCENE_HELP,
    STABILITY_HELP,
    choose,
    console,
    err_console,
    fail,
    floats,
    say,
    scene_option,
    stability_option,
    typed,
    way_option,
)
from coassist.cli._live import FOXGLOVE_PORT, LIVE_HELP, close_live, open_live
from coassist.config import APPLICATION_PRESET
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.intent_registry import intent_choices

ROS2_OPTIONS = {
    **DRIVE_OPTIONS,
    **{
        f"Ros2Config.{name}": f"--{name.replace('_', '-')}"
        for name in (
            "wrench_topic",
            "joint_state_topic",
            "command_topic",
            "base_frame",
            "joint_names",
            "domain_id",
            "stale_after",
            "tcp_offset",
            "node_name",
            "namespace",
            "connect_timeout",
            "wrench_frame",
        )
    },
    "Ros2Config.rate_hz": "--rate",
}


def ros2(
    out: Path = typer.Option(Path("runs/ros2/trial.parquet"), help="Trial file to write (as coassist drive writes)."),
    controller: str = typer.Option("cooperative", help=ARM_CONTROLLER_HELP),
    task: str = typer.Option(
        "linear", help="Nominal path, laid out from where the tool is: linear, curved, sinusoidal, z."
    ),
    obj: str = typer.Option("handle", "--object", help="Carried object: handle, board, heavy."),
    intent: str = typer.Option(
        DEFAULT_INTENT, help=f"Intent source: {intent_choices(simulation=False)}. {INTENT_DEFAULT_HELP}"
    ),
    person: str = typer.Option(None, help=PERSON_HELP),
    scene: Path = typer.Option(None, help=SCENE_HELP),
    predictor_backend: str = typer.Option(
        "process", help="Where a model runs: process (own worker process), onnx or torch (thread)."
    ),
    preset: str = typer.Option(
        APPLICATION_PRESET,
        help=f"Control preset (default: the main job's application preset, {APPLICATION_PRESET}, safe with a learned model in the loop; the -dm presets ring with one).",
    ),
    rate: int = typer.Option(125, help="Control rate in Hz: 125 (UR CB3) or 500 (e-Series)."),
    full_pose: bool = typer.Option(False, help="Control all 6 DOFs instead of the x-y plane."),
    time_limit: float = typer.Option(None, help="Longest run in seconds (default: 2 x the plan + 10 s)."),
    tool_speed: float = typer.Option(0.25, help="Safety: largest tool speed in m/s."),
    contact_force: float = typer.Option(120.0, help="Safety: hand force in N that makes a protective stop."),
    wrench_topic: str = typer.Option(
        "/force_torque_sensor_broadcaster/wrench",
        help="geometry_msgs/WrenchStamped in: the F/T reading (sensor frame).",
    ),
    joint_state_topic: str = typer.Option("/joint_states", help="sensor_msgs/JointState in."),
    command_topic: str = typer.Option(
        "/forward_velocity_controller/commands", help="std_msgs/Float64MultiArray out: joint velocities."
    ),
    joint_names: str = typer.Option(
        None,
        help="The joints from the base to the tool, comma-separated: the order of the commands (default: the UR's, shoulder_pan_joint … wrist_3_joint).",
    ),
    base_frame: str = typer.Option(
        "base", help="frame_id of the published poses (a wrench in it is rotated into the sensor's)."
    ),
    wrench_frame: str = typer.Option(
        "tool0",
        help="frame_id of a wrench in the sensor frame (the flange's axes); a wrench in any other frame but --base-frame stops the run.",
    ),
    wrench_in_base: bool = typer.Option(False, help="Kept for scripts: each wrench message's frame_id says its frame."),
    tcp_offset: str = typer.Option(None, help="TCP in the flange frame: x,y,z,rx,ry,rz [m, rad] (default 0)."),
    node_name: str = typer.Option("coassist", help="The node's name (monitor topics go to /<node>/…)."),
    namespace: str = typer.Option("", help="The node's namespace."),
    domain_id: int = typer.Option(None, help="ROS_DOMAIN_ID (default: the environment's)."),
    stale_after: float = typer.Option(
        0.1, help="A wrench or joint state older than this (s, at most 0.5) stops the arm."
    ),
    connect_timeout: float = typer.Option(5.0, help="Wait this long (s) for the first messages."),
    lockstep: bool = typer.Option(
        False, help="A simulated robot that steps once per command: wait for its answer every tick."
    ),
    robot_clock: bool = typer.Option(
        False,
        help="The robot stamps on a clock of its own (a simulator's time): order its messages by their stamps but "
        "do not refuse one stamped more than --stale-after before this computer's clock (by default an old message: "
        "a recording replayed, a buffering bridge, or the driver's clock behind).",
    ),
    yes: bool = typer.Option(False, "--yes", help="Do not ask for confirmation before the robot moves (scripts)."),
    mcap: bool = typer.Option(False, help="Also write the run as <out>.mcap (ROS 2 messages Foxglove opens)."),
    plot: bool = typer.Option(True, help="Also write the monitor figure (<out>.png)."),
    overwrite: bool = typer.Option(False, help="Replace an existing run at --out (its trial and its .mcap)."),
    stability_guard: bool = typer.Option(True, "--stability-guard/--no-stability-guard", help=STABILITY_HELP),
    ask_way: str = typer.Option(None, help=ASK_WAY_HELP),
    foxglove: int = typer.Option(None, metavar="[PORT]", help=LIVE_HELP.format(port=FOXGLOVE_PORT)),
) -> None:
    """Run the assistive controller, IMP or MG as a ROS 2 node: ros2_control's forward velocity controller."""
    try:
        import rclpy  # noqa: F401  (the ros2 extra, checked before anything starts)
    except ImportError as exc:
        fail(f"coassist ros2 needs the ros2 extra ({exc.name} missing): pip install 'coassist[ros2]'", 2)
    intent_option(intent)
    from coassist.robot.drive import DriveConfig
    from coassist.robot.drive import drive as run_drive
    from coassist.robot.ros2_world import UR_JOINT_NAMES, Ros2Config, Ros2World
    from coassist.runtime.loop import InterruptsHeld, RunInterrupted
    from coassist.runtime.safety_limits import SafetyLimits
    from coassist.scenario.objects import OBJECTS

    choose(obj, OBJECTS, "--object", "object")
    try:
        limits = SafetyLimits(tool_speed=tool_speed, contact_force=contact_force)
        config = DriveConfig(
            world="ros2",
            controller=controller,
            task=task,
            object=obj,
            preset=preset,
            intent=intent,
            rate_hz=rate,
            full_pose=full_pose,
            time_limit=time_limit,
            limits=limits,
            predictor_backend=predictor_backend,
            person=person,
            scene=scene_option(scene, controller, intent),
            stability=stability_option(stability_guard),
            way=way_option(ask_way),
        )
        rcfg = Ros2Config(
            node_name=node_name,
            namespace=namespace,
            wrench_topic=wrench_topic,
            joint_state_topic=joint_state_topic,
            command_topic=command_topic,
            base_frame=base_frame,
            wrench_frame=wrench_frame,
            joint_names=UR_JOINT_NAMES if joint_names is None else tuple(n.strip() for n in joint_names.split(",")),
            wrench_in_base=wrench_in_base,
            rate_hz=float(rate),
            stale_after=stale_after,
            connect_timeout=connect_timeout,
            lockstep=lockstep,
            pace=not lockstep,
            stamps_on_this_clock=not robot_clock,
            domain_id=domain_id,
            tcp_offset=floats(tcp_offset, "--tcp-offset") or (0.0,) * 6,
        )
    except ValueError as exc:
        fail(typed(str(exc), ROS2_OPTIONS), 2)
    if wrench_in_base:
        # accepted so that scripts written for it keep running, but said: the option no longer decides anything
        err_console.print(
            f"note: --wrench-in-base does nothing: each wrench message's frame_id says its frame ({base_frame!r}: the "
            f"base frame's axes; {wrench_frame!r}: the sensor's, rotated to the base); another frame stops the run",
            markup=False,
            soft_wrap=True,
        )
    out = run_out(out, overwrite, mcap, plot)

    confirm = confirm_move(yes, "the emergency stop")
    live = open_live(foxglove)

    def write(trial) -> None:
        write_run(trial, out, mcap=mcap, plot=plot, joint_names=rcfg.joint_names, frame_id=rcfg.base_frame)

    held = InterruptsHeld()  # while the world closes after the run: a Ctrl-C there must not lose the trial
    try:
        try:
            world = Ros2World(rcfg)
            try:
                trial = run_drive(
                    config,
                    world=world,
                    confirm=confirm,
                    on_tick=world.publish_monitor,
                    live=live,
                    joint_names=rcfg.joint_names,
                    say=say,
                )
            finally:
                with held:
                    try:
                        world.close()
                    except Exception as exc:  # the teardown after the run must not lose its trial (as drive's)
                        err_console.print(f"warning: closing the ROS 2 world raised {exc}", markup=False)
        except (ValueError, RuntimeError, ImportError, ConnectionError, OSError) as exc:
            fail(str(exc))
        except RunInterrupted as stop:  # Ctrl-C: the arm stopped; the ticks before it are written, as on an error
            write_interrupted(stop, write)
        # the run is written before the live view closes: whatever became of the view, the trial is kept
        write_finished(trial, write, interrupted=held.pending)
    finally:
        close_live(live)


def ros2_watchdog(
    input_topic: str = typer.Option(
        "/coassist/joint_velocity_command",
        "--input",
        help="Where coassist ros2 sends its commands (its --command-topic).",
    ),
    output_topic: str = typer.Option(
        "/forward_velocity_controller/commands", "--output", help="The forward velocity controller's command topic."
    ),
    joints: int = typer.Option(6, help="Joints per command."),
    timeout: float = typer.Option(0.05, help="Seconds without a command after which zeros are sent (at most 0.5)."),
    period: float = typer.Option(0.008, help="How often (s) the silence is checked and zeros repeated."),
    domain_id: int = typer.Option(None, help="ROS_DOMAIN_ID (default: the environment's)."),
) -> None:
    """Relay commands to ros2_control's forward velocity controller; send zeros when they stop (run it beside the controller)."""
    try:
        import rclpy  # noqa: F401  (the ros2 extra, checked before anything starts)
    except ImportError as exc:
        fail(f"coassist ros2-watchdog needs the ros2 extra ({exc.name} missing): pip install 'coassist[ros2]'", 2)
    import time

    from coassist.robot.ros2_watchdog import CommandWatchdog, WatchdogConfig

    options = {
        "WatchdogConfig.input_topic": "--input",
        "WatchdogConfig.output_topic": "--output",
        "WatchdogConfig.n_joints": "--joints",
        "WatchdogConfig.timeout": "--timeout",
        "WatchdogConfig.period": "--period",
        "WatchdogConfig.domain_id": "--domain-id",
    }
    try:
        config = WatchdogConfig(
            input_topic=input_topic,
            output_topic=output_topic,
            n_joints=joints,
            timeout=timeout,
            period=period,
            domain_id=domain_id,
        )
    except ValueError as exc:
        fail(typed(str(exc), options), 2)
    console.print(
        f"relaying {input_topic} -> {output_topic}; zeros after {timeout:g} s without a command (Ctrl-C ends it)",
        markup=False,
    )
    with CommandWatchdog(config) as dog:
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        console.print(
            f"forwarded {dog.forwarded} commands, {dog.timeouts} silences, {dog.malformed} malformed", markup=False
        )
