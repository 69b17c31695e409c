"""``coassist play``: a live page where a person is the hand on the robot."""

from __future__ import annotations

from pathlib import Path

import typer

from coassist.cli._arm_runs import intent_option
from coassist.cli._common import (
    ASK_WAY_HELP,
    INTENT_DEFAULT_HELP,
    SCENE_HELP,
    STABILITY_HELP,
    choose,
    console,
    fail,
    folder_out,
    lookup,
    name_list,
    need_bags,
    real_arm_hosts,
    say,
    scene_option,
    stability_option,
    typed,
    way_option,
)
from coassist.cli._live import FOXGLOVE_PAGE_PORT, LIVE_HELP, close_live, open_live
from coassist.config import APPLICATION_PRESET
from coassist.robot.worlds import WORLDS, arm_worlds
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.intent_registry import INTENT_SOURCES, intent_choices
from coassist.scenario.path_model import WAY_NAMES

#: PlayConfig's fields as the options that set them, for its refusals.
PLAY_OPTIONS = {
    "PlayConfig.user": "--user",
    "PlayConfig.out": "--out",
    "PlayConfig.controllers": "--controller",
    "PlayConfig.intent": "--intent",
    "PlayConfig.preset": "--preset",
    "PlayConfig.tasks": "--tasks",
    "PlayConfig.seed": "--seed",
    "PlayConfig.motion_time": "--motion-time",
    "PlayConfig.way": "--ask-way",
}


def _simulation_only(intent: str) -> bool:
    """Whether ``intent`` names a source only a simulation can run (the oracle)."""
    return intent in INTENT_SOURCES and INTENT_SOURCES[intent].simulation_only


def play(
    user: str = typer.Option(
        "me", help="Your id (letters, digits, - and _): it names your session folder <out>/<user>."
    ),
    out: Path = typer.Option(
        Path("runs/play"), help="Parent folder of the session folders (each a dataset coassist train reads)."
    ),
    controller: str = typer.Option(
        "manual,impedance,cooperative",
        help="Controllers the page offers, comma-separated: manual (MG), impedance (IMP), cooperative (assistive), cooperative-arbitrated, cooperative-damped, manual-probe (calibration trials: MG plus the probe, no assistance).",
    ),
    intent: str = typer.Option(
        DEFAULT_INTENT,
        help=f"Intent source (its prediction is drawn live): {intent_choices(simulation=False)}. {INTENT_DEFAULT_HELP}",
    ),
    preset: str = typer.Option(
        APPLICATION_PRESET,
        help=f"Control preset (default: the main job's application preset, {APPLICATION_PRESET}, safe with a learned model in the loop; also thesis-evaluation[-dm], thesis-application[-dm]).",
    ),
    tasks: str = typer.Option("linear,curved,sinusoidal,z", help="The protocol's paths, in order (repeated)."),
    seed: int = typer.Option(0, help="Trial i's obstacle is drawn from seed + i."),
    motion_time: float = typer.Option(
        None, help="Planned motion time of every path in seconds (default: the thesis' per path)."
    ),
    host: str = typer.Option("127.0.0.1", help="Address to listen on; anything but this machine needs --token."),
    port: int = typer.Option(8765, help="Port to listen on (0: any free port)."),
    token: str = typer.Option(None, help="Token the page must present (made for you on a non-local --host)."),
    open_browser: bool = typer.Option(True, "--open/--no-open", help="Open the page in your web browser."),
    drive: str = typer.Option(
        None,
        help=f"Watch a coassist drive run instead (read-only): {' | '.join(arm_worlds())}; uses the first --controller and --tasks.",
    ),
    robot_host: str = typer.Option(
        None,
        help=f"The real arm's address: {real_arm_hosts('--drive')}.",
    ),
    mcap: bool = typer.Option(
        False, help="Also write each trial as <trial>.mcap beside its Parquet file (ROS 2 messages Foxglove opens)."
    ),
    scene: Path = typer.Option(None, help=f"With --drive: {SCENE_HELP}"),
    stability_guard: bool = typer.Option(
        True, "--stability-guard/--no-stability-guard", help=f"With --drive: {STABILITY_HELP}"
    ),
    foxglove: int = typer.Option(None, metavar="[PORT]", help=LIVE_HELP.format(port=FOXGLOVE_PAGE_PORT)),
    ask_way: str = typer.Option(None, help=f"{ASK_WAY_HELP} The page says it before every trial."),
) -> None:
    """Be the operator: a live page where your mouse, touch screen or gamepad is the hand on the robot."""
    try:
        import starlette  # noqa: F401  (the web extra, checked before anything starts)
        import uvicorn  # noqa: F401

        from coassist._io import OutputBusyError
        from coassist.play.server import PlayServer, check_token, is_loopback, new_token
        from coassist.play.session import PlayConfig, PlaySession
    except ImportError as exc:
        fail(f"coassist play needs the web extra ({exc.name} missing): pip install 'coassist[web]'")
    if not 0 <= port <= 65535:
        raise typer.BadParameter(f"must be 0..65535, got {port}", param_hint="--port")
    if mcap:
        need_bags("--mcap")
    if scene is not None and drive is None:
        fail("--scene: the page's own world tells the robot its obstacle; a scene file is for --drive (an arm)", 2)
    told = scene_option(scene, controller.split(",")[0].strip(), intent)  # the drive's controller: the first
    way = way_option(ask_way)
    folder_out(out, "--out")  # a file there: refused now, not after the person's first trial
    if token is None and not is_loopback(host):
        token = new_token()
    try:
        check_token(token, host)
    except ValueError as exc:
        fail(f"{exc}", 2)
    live = open_live(foxglove, page_port=port)  # stopped with the process when a line below fails
    try:
        from coassist.config import CONTROL_PRESETS
        from coassist.control.presets import CONTROLLERS
        from coassist.scenario.tasks import TASKS

        lookup(CONTROL_PRESETS, preset, "--preset")
        intent_option(intent)
        if drive is not None:
            choose(drive, arm_worlds(), "--drive", "world")
        try:
            config = PlayConfig(
                user=user,
                out=out,
                controllers=tuple(name_list(controller, "--controller", tuple(CONTROLLERS), "controller")),
                intent="nominal" if drive and _simulation_only(intent) else intent,
                preset=preset,
                tasks=tuple(name_list(tasks, "--tasks", tuple(TASKS), "task", distinct=False)),
                seed=seed,
                motion_time=motion_time,
                mcap=mcap,
                way=way,
            )
        except ValueError as exc:  # the options refused: named as typed, exit 2
            fail(typed(str(exc), PLAY_OPTIONS), 2)
        if drive is None:
            session = PlaySession(config, live=live)
            say(_page_assistance(session))
            if way:
                say(
                    f"every trial asks you to go round the obstacle on the {WAY_NAMES[way]} of the plan (the page says "
                    "so); the trials record it, and coassist calibrate counts their paths but not as your preference"
                )
        else:
            from coassist.play.monitor import DriveMonitor
            from coassist.robot.drive import DriveConfig

            if motion_time is not None:  # was ignored: a drive runs its path's planned motion time
                fail("--motion-time does not apply with --drive (the drive runs its path's planned motion time)", 2)

            def confirm(text: str) -> bool:
                console.print(text, markup=False)
                return typer.confirm("Keep the emergency stop within reach. Move the robot?", default=False)

            session = DriveMonitor(
                DriveConfig(
                    world=drive,
                    controller=config.controllers[0],
                    task=config.tasks[0],
                    intent=intent,
                    preset=preset,
                    seed=seed,
                    # at a real arm the page's user is the person at the handle (in MuJoCo, the simulated one)
                    person=None if drive not in arm_worlds() or WORLDS[drive].simulated else user,
                    scene=told,
                    stability=stability_option(stability_guard),
                    way=way,
                ),
                config,
                host=robot_host,
                confirm=None if WORLDS[drive].simulated else confirm,  # asked before a real arm moves (drive's)
                say=say,
                live=live,
            )
        server = PlayServer(session, host=host, port=port, token=token)
    except (ValueError, OSError, OutputBusyError) as exc:  # busy: another play runs this --out/--user
        fail(f"{exc}")
    console.print(
        f"coassist play: open [bold]{server.url}[/] (Ctrl+C to stop); trials go to {config.folder}", highlight=False
    )
    if open_browser:
        import webbrowser

        webbrowser.open(server.url)
    if drive is not None:
        session.start()
    server.run()
    close_live(live)


def _page_assistance(session) -> str:
    """The one-line statement of a play page: what its assisting controller (the first offered) will give."""
    from coassist.scenario.assistance import assistance_line
    from coassist.scenario.tasks import task_for_seed

    cfg = session.config
    kinds = cfg.controllers
    controller = next((c for c in kinds if c.startswith("cooperative")), kinds[0])
    first = session.next_task()
    # each task of the session: a person model serves only the plan it was recorded on, so the line may differ by task
    # (the first task's alone had been said: a session's other tasks then got the present estimate held unsaid)
    by_line: dict[str, list[str]] = {}
    for kind in dict.fromkeys([first.kind, *cfg.tasks]):
        task = first if kind == first.kind else task_for_seed(kind, cfg.seed, motion_time=cfg.motion_time)
        said = assistance_line(
            controller,
            cfg.intent,
            session.source,
            user=cfg.user,
            path=task.path.points,
            # (centre, size), as the episode tells the source (a dict raised KeyError out of `play --intent paths`)
            obstacles=((tuple(task.obstacle.center), tuple(task.obstacle.size)),),
        )
        by_line.setdefault(said, []).append(kind)
    lines = list(by_line)
    line = lines[0]
    if len(lines) > 1:
        head = f"assistance: {controller}, "
        line = head + "; ".join(f"on task {', '.join(by_line[said])}: {said.removeprefix(head)}" for said in lines)
    others = [c for c in kinds if c != controller]
    return line + (f" (the page also offers {', '.join(others)})" if others else "")
