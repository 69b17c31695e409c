"""``coassist collect``: simulated trials written as a dataset."""

from __future__ import annotations

from pathlib import Path

import typer

from coassist.cli._arm_runs import intent_option
from coassist.cli._common import (
    INTENT_DEFAULT_HELP,
    choose,
    console,
    fail,
    folder_out,
    int_list,
    lookup,
    name_list,
    typed,
    way_option,
    wrote,
)
from coassist.cli._live import FOXGLOVE_PORT, LIVE_HELP, close_live, open_live
from coassist.config import APPLICATION_PRESET, COLLECTION_PRESET
from coassist.interfaces import NETWORK_BACKENDS
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.intent_registry import intent_choices


def print_forces(folder: Path) -> None:
    """The hand's and the robot's f_RMS (eq. 5.9) over a dataset: how much the robot helped."""
    import numpy as np

    from coassist.data.datasets import manifest_files, read_dataset_trial
    from coassist.metrics import f_rms

    # one trial in memory at a time: the summary's memory does not grow with the dataset
    hand, robot = [], []
    for i in range(len(manifest_files(folder))):
        trial = read_dataset_trial(folder, i)
        hand.append(f_rms(trial.wrench))
        robot.append(f_rms(trial.effort_r))
    console.print(
        f"f_RMS (eq. 5.9), mean over {len(hand)} trials: hand {float(np.mean(hand)):.2f} N, "
        f"robot {float(np.mean(robot)):.2f} N",
        highlight=False,
    )


def _check_people(
    intent: str, users: list[int] | None, population: str, population_seed: int, tasks: list[str], seed: int
) -> None:
    """Refuse, before any trial, an intent folder that cannot be read, and a person model that does not hold each of the simulated people asked for, naming the
    first (as ``drive`` and ``play`` do for the person at the handle): they would get no path of their own. Say the
    tasks whose plan a person's paths were not recorded on (their trials get the present estimate held, with their
    arm, as ``drive`` says; the trials still name the model)."""
    from coassist.scenario.assistance import check_person, check_person_world
    from coassist.scenario.intent_registry import intent_folder_kind, load_intent_source
    from coassist.scenario.person_intent import same_plan
    from coassist.scenario.populations import population_profile
    from coassist.scenario.tasks import task_for_seed

    if intent_folder_kind(intent) is None:
        return  # a named source
    try:  # every intent folder read now: a damaged one is refused before the collection starts (a traceback once)
        source = load_intent_source(intent, horizon=2)
    except (ValueError, OSError) as exc:
        fail(f"--intent {intent}: {exc}", 2)
    if intent_folder_kind(intent) != "person-model":
        return
    try:
        check_person_world(source, "sim", "point-mass", intent)  # the origin a collection's trials record
    except ValueError as exc:
        fail(f"--{exc}", 2)  # "--intent …"
    for u in users if users is not None else (0,):
        try:
            name = population_profile(population, u, population_seed).name
            check_person(source, name, intent, fix="collect the people it holds (--users), or calibrate them")
        except ValueError as exc:
            fail(f"--users {u}: {exc}", 2)
        model = getattr(source, "paths", {}).get(name, getattr(source, "default_paths", None))  # PersonPathsIntent's
        other = [
            t for t in tasks if model is not None and not same_plan(model.nominal, task_for_seed(t, seed).path.points)
        ]
        if other:
            console.print(
                f"note: --intent {intent}: {name}'s paths were recorded on another plan than task {', '.join(other)}'s:"
                " those trials get the present estimate held, with their arm (calibrate on the task to lead them)",
                markup=False,
                highlight=False,
                soft_wrap=True,
            )


def collect(
    out: Path = typer.Option(..., help="Dataset folder to write (trial Parquet files + manifest.json)."),
    controller: str = typer.Option(
        "cooperative",
        help="cooperative | cooperative-arbitrated | cooperative-damped | impedance | manual | manual-probe (calibration trials: MG plus the probe, for coassist calibrate).",
    ),
    users: str = typer.Option("0", help="Simulated operators, comma-separated (0 = the thesis' author)."),
    tasks: str = typer.Option("linear,curved,sinusoidal", help="Nominal paths: linear, curved, sinusoidal, z."),
    objects: str = typer.Option("handle", help="Objects: handle, board, heavy."),
    trials: int = typer.Option(20, help="Trials per user, object and task."),
    seed: int = typer.Option(0, help="Seed of the first trial; trial i uses seed + i."),
    preset: str = typer.Option(
        COLLECTION_PRESET,
        help=f"Control preset: {COLLECTION_PRESET} (the main job's for collection), {APPLICATION_PRESET} (the main job's with a learned model in the loop), thesis-application-dm, or one without -dm (SI units: the robot barely helps).",
    ),
    intent: str = typer.Option(
        DEFAULT_INTENT,
        help=f"Intent source: {intent_choices()}. {INTENT_DEFAULT_HELP} The thesis' dataset D0 (Algorithm 4.1) is --intent nominal.",
    ),
    obstacle: str = typer.Option(
        "small",
        help="The obstacle the operators go around: small (the evaluation's box) or large (the application's 12 cm box, no path shown).",
    ),
    population: str = typer.Option(
        "thesis",
        help="Who the simulated operators are: thesis (the main job's: user 0 the thesis' author), varied (detour families to tune on), held-out and unseen (other kinds of detour, to report only); docs/realism.md.",
    ),
    population_seed: int = typer.Option(0, help="Seed of the population the users are drawn from."),
    ask_way: str = typer.Option(
        None,
        help="left | right: the operators are asked to go round the obstacle that way in every trial (calibration trials for a way coassist calibrate says was shown too seldom; each trial records it, and the person model counts its path but not as their preference). Default: they choose.",
    ),
    dataset_id: str = typer.Option(None, help="Dataset id (default: the folder's name)."),
    workers: int = typer.Option(None, help="Local worker processes (default: one per CPU)."),
    ray_address: str = typer.Option(None, help="Run on a Ray cluster at this address (needs coassist[cluster])."),
    overwrite: bool = typer.Option(
        False, help="Replace an existing dataset folder (only once the new one is complete)."
    ),
    lockstep: bool = typer.Option(
        True,
        "--lockstep/--per-trial",
        help="Advance each worker's trials together: one controller call and, with a model in the loop, one network call per tick for all (~6x faster with a model, ~2x without; with a model equal to the per-trial run to the network's float32 rounding, without it bit for bit). --per-trial: every trial alone, bit for bit the same whatever else runs (e.g. across a resumed collection).",
    ),
    network: str = typer.Option(
        "auto",
        help="What evaluates a model's network: onnx (ONNX Runtime, 1.6-1.9x faster at the loop's batch sizes; the onnx extra), torch, or auto (onnx where installed). The two agree to float32 rounding; each trial records which ran.",
    ),
    foxglove: int = typer.Option(
        None,
        metavar="[PORT]",
        help=LIVE_HELP.format(port=FOXGLOVE_PORT)
        + " Shows the first trial still to run, which then runs first, in this process.",
    ),
) -> None:
    """Simulate trials and write them as a dataset (thesis §5.2.2: 60 trials; D0 with --intent nominal).

    Each trial is written as it finishes; if the run is stopped, the same command
    continues where it stopped. Another command's unfinished trials in --out are kept and
    refused, naming them (--overwrite discards them).
    """
    from coassist._io import OutputBusyError
    from coassist.config import CONTROL_PRESETS
    from coassist.control.presets import CONTROLLERS
    from coassist.scenario import OBJECTS, OBSTACLES, POPULATIONS
    from coassist.scenario.tasks import TASKS
    from coassist.sim.collect import collect_dataset

    choose(controller, CONTROLLERS, "--controller", "controller")
    choose(population, POPULATIONS, "--population", "population")
    choose(obstacle, OBSTACLES, "--obstacle", "obstacle")
    choose(network, NETWORK_BACKENDS, "--network", "network backend")
    way = way_option(ask_way)
    lookup(CONTROL_PRESETS, preset, "--preset")
    for value, option, minimum in (
        (trials, "--trials", 1),
        (seed, "--seed", 0),
        (workers, "--workers", 1),
        (population_seed, "--population-seed", 0),
    ):
        if value is not None and value < minimum:
            fail(f"{option} must be >= {minimum}, got {value}", 2)
    user_list = int_list(users, "--users")
    task_list = name_list(tasks, "--tasks", tuple(TASKS), "task")
    object_list = name_list(objects, "--objects", tuple(OBJECTS), "object")
    intent_option(intent)
    _check_people(intent, user_list, population, population_seed, task_list, seed)
    folder_out(out, "--out")  # told as typed
    out = out.absolute()  # "--out ." is a folder with a name (the dataset's id), swapped into place by its path
    live = open_live(foxglove)
    try:
        folder = collect_dataset(
            out,
            dataset_id=dataset_id,
            workers=workers,
            progress=True,
            ray_address=ray_address,
            overwrite=overwrite,
            controller=controller,
            users=user_list,
            tasks=task_list,
            objects=object_list,
            trials=trials,
            seed=seed,
            preset=preset,
            obstacle=obstacle,
            lockstep=lockstep,
            network=network,
            intent=intent,
            population=population,
            population_seed=population_seed,
            way=way,
            say=lambda line: console.print(line, highlight=False),
            live=live,
        )
    except ConnectionError as exc:  # only the cluster is reached over a network here
        fail(f"--ray-address {ray_address}: {exc}", 2)
    except (ValueError, FileExistsError, NotADirectoryError, RuntimeError, OutputBusyError) as exc:
        fail(typed(str(exc), {"overwrite=True": "--overwrite"}))  # the library's argument, as typed here
    except OSError as exc:
        fail(f"cannot write {exc.filename or out}: {exc.strerror}")
    finally:
        close_live(live)
    wrote(str(folder))
    print_forces(Path(folder))
