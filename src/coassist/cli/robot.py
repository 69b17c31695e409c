"""The arms: ``drive`` (MuJoCo or a real arm) and ``ur-sim`` (a simulated UR controller to drive)."""

from __future__ import annotations

import os
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
    fail,
    floats,
    lookup,
    real_arm_hosts,
    say,
    scene_option,
    simulation_only_sources,
    stability_option,
    typed,
    way_option,
)
from coassist.cli._live import FOXGLOVE_PORT, LIVE_HELP, close_live, open_live
from coassist.cli._threads import set_torch_threads
from coassist.config import APPLICATION_PRESET
from coassist.robot.worlds import WORLDS, arm_choices, arm_worlds, world_choices
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.intent_registry import INTENT_SOURCES, intent_choices

#: What the person keeps within reach, by world (asked before an arm moves): a Franka has no teach pendant
STOP_HINTS = {"ur": "the teach pendant's emergency stop", "franka": "the Franka's user stop button"}


def drive(
    out: Path = typer.Option(
        Path("runs/drive/trial.parquet"),
        help="Trial file to write (the same format as collect's trials, plus joint columns).",
    ),
    world: str = typer.Option("mujoco", help=f"{world_choices()}."),
    robot: str = typer.Option(None, help=f"The arm: {arm_choices()}; default the world's first."),
    controller: str = typer.Option("cooperative", help=ARM_CONTROLLER_HELP),
    task: str = typer.Option("linear", help="Nominal path: linear, curved, sinusoidal, z."),
    obj: str = typer.Option("handle", "--object", help="Carried object: handle, board, heavy."),
    intent: str = typer.Option(
        DEFAULT_INTENT,
        help=f"Intent source: {intent_choices()} ("
        + simulation_only_sources()
        + f" in a simulated world only). {INTENT_DEFAULT_HELP}",
    ),
    person: str = typer.Option(None, help=PERSON_HELP),
    scene: Path = typer.Option(None, help=SCENE_HELP),
    realtime_intent: bool = typer.Option(
        None,
        help="Run a model folder (coassist train) off the control thread, never waiting for it (default: on for a real arm, off in a simulated world, where runs are then deterministic); it also paces a simulated world to the wall clock. A named source or a person model is computed in the tick: with one, only the pace changes.",
    ),
    predictor_backend: str = typer.Option(
        "process",
        help="Where a real-time model runs: process (own worker process), onnx (ONNX Runtime thread) or torch (thread); onnx and torch only with a model folder run off the control thread (--realtime-intent, a real arm's default).",
    ),
    preset: str = typer.Option(
        APPLICATION_PRESET,
        help=f"Control preset (default: the main job's application preset, {APPLICATION_PRESET}, safe with a learned model in the loop; the -dm presets ring with one).",
    ),
    user: int = typer.Option(0, help="Simulated operator (MuJoCo world)."),
    population: str = typer.Option(
        "thesis", help="The simulated operator's population: thesis, varied, held-out or unseen (docs/realism.md)."
    ),
    seed: int = typer.Option(0, help="Seed of the task, the simulated operator and the sensor noise."),
    obstacle: str = typer.Option(
        "small", help="The obstacle the simulated operator goes around: small or large (the application's)."
    ),
    rate: int = typer.Option(125, help="Control rate in Hz: 125 (UR CB3) or 500 (e-Series)."),
    full_pose: bool = typer.Option(False, help="Control all 6 DOFs instead of the x-y plane."),
    time_limit: float = typer.Option(None, help="Longest run in seconds (default: 2 x the plan + 10 s)."),
    tool_speed: float = typer.Option(0.25, help="Safety: largest tool speed in m/s."),
    contact_force: float = typer.Option(120.0, help="Safety: hand force in N that makes a protective stop."),
    host: str = typer.Option(
        None,
        help=f"The real arm's address: {real_arm_hosts('--world')}.",
    ),
    yes: bool = typer.Option(False, "--yes", help="Do not ask for confirmation before a real arm moves (scripts)."),
    view: bool = typer.Option(False, help="Open MuJoCo's passive viewer (needs a display) and run in real time."),
    plot: bool = typer.Option(True, help="Also write the monitor figure (<out>.png)."),
    mcap: bool = typer.Option(
        False,
        help="Also write the run as <out>.mcap: ROS 2 messages (poses, wrench, prediction, alpha, faults) that Foxglove opens and train reads.",
    ),
    overwrite: bool = typer.Option(False, help="Replace an existing trial file at --out."),
    stability_guard: bool = typer.Option(True, "--stability-guard/--no-stability-guard", help=STABILITY_HELP),
    ask_way: str = typer.Option(None, help=ASK_WAY_HELP),
    foxglove: int = typer.Option(None, metavar="[PORT]", help=LIVE_HELP.format(port=FOXGLOVE_PORT)),
) -> None:
    """Run the assistive controller, IMP or MG on an arm (UR5, Panda): in MuJoCo, or on a real one."""
    from coassist.config import CONTROL_PRESETS
    from coassist.control.presets import CONTROLLERS
    from coassist.robot.drive import DriveConfig
    from coassist.robot.drive import drive as run_drive
    from coassist.runtime.safety_limits import SafetyLimits
    from coassist.scenario.objects import OBJECTS

    choose(world, arm_worlds(), "--world", "arm world")
    choose(controller, CONTROLLERS, "--controller", "controller")
    choose(obj, OBJECTS, "--object", "object")
    lookup(CONTROL_PRESETS, preset, "--preset")
    intent_option(intent)
    try:
        limits = SafetyLimits(tool_speed=tool_speed, contact_force=contact_force)
        config = DriveConfig(
            world=world,
            controller=controller,
            task=task,
            object=obj,
            preset=preset,
            intent=intent,
            user=user,
            seed=seed,
            obstacle=obstacle,
            rate_hz=rate,
            full_pose=full_pose,
            time_limit=time_limit,
            limits=limits,
            realtime_intent=realtime_intent,
            predictor_backend=predictor_backend,
            robot=robot,
            population=population,
            person=person,
            scene=scene_option(scene, controller, intent),
            stability=stability_option(stability_guard),
            way=way_option(ask_way),
        )
    except ValueError as exc:
        fail(typed(str(exc), DRIVE_OPTIONS), 2)
    if host is not None and WORLDS[world].simulated:  # (the default world then ran in its place, unsaid)
        arms = ", ".join(name for name in arm_worlds() if not WORLDS[name].simulated)
        fail(f"--host {host}: the {world} world is a simulation and has no address; an arm's: --world {arms}", 2)
    if view and world != "mujoco":  # the only world with a viewer: elsewhere --view would do nothing, unsaid
        fail(f"--view opens MuJoCo's viewer: it needs --world mujoco (not {world})", 2)
    if view and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        fail("--view needs a display (DISPLAY / WAYLAND_DISPLAY is not set); run without --view", 2)
    out = run_out(out, overwrite, mcap, plot)
    if intent not in INTENT_SOURCES:
        set_torch_threads(1)  # one core for a model run in this process (the tick's own thread stays free)

    # what stops the arm at hand: a UR's teach pendant, a Franka's user stop (it has no pendant)
    confirm = confirm_move(yes, STOP_HINTS.get(world, "the emergency stop"))
    live = open_live(foxglove)
    try:
        from coassist.robot.ros2_world import UR_JOINT_NAMES  # (no rclpy needed for the names)
        from coassist.runtime.loop import RunInterrupted

        # The UR's joint names; another arm's joints are named joint_1 … joint_n in the MCAP.
        names = UR_JOINT_NAMES if config.robot == "ur5" else None

        def write(trial) -> None:
            write_run(trial, out, mcap=mcap, plot=plot, joint_names=names)

        try:
            trial = run_drive(
                config, host=host, view=view, confirm=None if WORLDS[world].simulated else confirm, live=live, say=say
            )
        except (ValueError, RuntimeError, ImportError, ConnectionError, OSError) as exc:
            fail(str(exc))
        except RunInterrupted as stop:  # Ctrl-C: the arm stopped; the ticks before it are written, as on an error
            write_interrupted(stop, write)
        # the run is written before the live view closes, as ros2 does: whatever became of the view, the trial is kept
        write_finished(trial, write)
    finally:
        close_live(live)


def ur_sim(
    host: str = typer.Option("127.0.0.1", help="Address to listen on (another 127.x.y.z for a second simulator)."),
    series: str = typer.Option("e-series", help="e-series (500 Hz, PolyScope 5) or cb3 (125 Hz, PolyScope 3)."),
    software: str = typer.Option(
        None, help="The software version it reports, e.g. 5.11.1.108318 (default: the series')."
    ),
    obj: str = typer.Option("handle", "--object", help="Carried object: handle, board, heavy."),
    start: str = typer.Option(None, help="x,y,z [m] of the TCP at the start, tool down (default: the tasks' start)."),
    seed: int = typer.Option(0, help="Seed of the sensor noise and of the jitter fault."),
    unlock_delay: float = typer.Option(5.0, help="Seconds after a protective stop before it can be unlocked."),
    rt_priority: int = typer.Option(
        None, help="SCHED_FIFO priority 1-99 for its threads (needs root or CAP_SYS_NICE)."
    ),
) -> None:
    """A UR controller (dashboard, script and RTDE ports) with the MuJoCo UR5 behind it: drive it with --world ur.

    Reads faults on stdin, one a line: protective-stop, emergency-stop, release-emergency-stop,
    pendant-stop, stall, unstall, delay LATE [JITTER], remote on|off, drop [REFUSE_FOR],
    push FX FY FZ, release, status, quit (docs/robots.md).
    """
    from coassist.robot.ur_sim import URSimConfig
    from coassist.robot.ur_sim.process import serve

    names = ("host", "series", "seed", "start", "unlock_delay")
    options = {f"URSimConfig.{n}": f"--{n.replace('_', '-')}" for n in names}
    options.update(
        {
            "URSimConfig.version": "--software",
            "URSimConfig.tool": "--object",
            "URSimConfig.rt_priority": "--rt-priority",
        }
    )
    fields: dict = {"host": host, "series": series, "tool": obj, "seed": seed, "unlock_delay": unlock_delay}
    fields["rt_priority"] = rt_priority
    if software is not None:
        try:
            fields["version"] = tuple(int(v) for v in software.split("."))
        except ValueError:
            fail(f"--software {software!r}: give four numbers, e.g. 5.11.1.108318", 2)
    if start is not None:
        fields["start"] = floats(start, "--start")
    if seed < 0:  # numpy's own refusal names no option
        fail(f"--seed must be >= 0, got {seed}", 2)
    try:
        config = URSimConfig(**fields)
        serve(config)
    except (ValueError, OSError) as exc:
        fail(typed(str(exc), options), 2 if isinstance(exc, ValueError) else 1)
