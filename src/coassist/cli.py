"""The ``coassist`` command: a thin shell over the experiments and tools.

Each command parses and validates its options, then calls one function of the
library; no computation lives here.
"""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console

app = typer.Typer(
    help="coassist — assistive pHRI: cooperative game-theoretic MPC with learned human intent.",
    no_args_is_help=True,
    add_completion=False,
)
console = Console()


@app.callback()
def main() -> None:
    """coassist — assistive pHRI: cooperative game-theoretic MPC with learned human intent."""


@app.command()
def sweep(
    out: Path = typer.Option(Path("runs/sweep"), help="Output folder for the figure grid and summary.json."),
    duration: float = typer.Option(10.0, help="Simulated time per case [s]."),
    position_scale: float = typer.Option(
        None,
        help="Output scaling of positions in the cost (see README). Default: the one that reproduces the thesis' figures.",
    ),
) -> None:
    """The dMPC study of thesis §5.2.1 (Fig. 5.2–5.4): α, R_r and horizon swept on sinusoidal references."""
    from coassist.experiments import dmpc_study

    kwargs = {} if position_scale is None else {"position_scale": position_scale}
    try:
        config = dmpc_study.SweepConfig(duration=duration, **kwargs)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    result = dmpc_study.run_sweep(config, out, progress=True)
    dmpc_study.print_summary(result, console)
    console.print(f"[green]wrote[/] {out / 'summary.json'} and {out / 'dmpc_sweep.png'}")



# --------------------------------------------------------------------------- intent model


def _intent_preset(preset: str, **overrides):
    from coassist.intent.training import PRESETS, with_overrides

    if preset not in PRESETS:
        raise typer.BadParameter(f"unknown preset {preset!r}; choose one of {sorted(PRESETS)}", param_hint="--preset")
    try:
        return with_overrides(PRESETS[preset], **overrides)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None


def _intent_trials(paths: list[Path]):
    from coassist.intent import load_trials

    try:
        return load_trials(paths)
    except (FileNotFoundError, ValueError) as exc:
        raise typer.BadParameter(str(exc), param_hint="DATA") from None


@app.command()
def train(
    data: list[Path] = typer.Argument(..., help="Dataset folders, real-recording folders (e.g. .../ur5-thesis/user-a) or single recordings."),
    out: Path = typer.Option(..., "--out", "-o", help="Model folder to write (weights, model.json, history.json, loss.png)."),
    preset: str = typer.Option("default", help="Starting configuration: 'default' (small, fast) or 'thesis' (exact §5.2.2)."),
    init: str = typer.Option("scratch", help="scratch | resume:<model> | finetune:<model> | transfer:<model> (LSTM frozen)."),
    epochs: int = typer.Option(None, help="Override the preset's epochs."),
    lr: float = typer.Option(None, help="Override the initial learning rate."),
    batch_size: int = typer.Option(None, help="Override the batch size."),
    seed: int = typer.Option(None, help="Seed of split, init and batch order (default 0)."),
    threads: int = typer.Option(None, help="Torch threads (default 2; at most the cores you may use)."),
    test_fraction: float = typer.Option(None, help="Share of trials held out (default 0.2)."),
    device: str = typer.Option(None, help="Torch device to train on: cpu (default) or cuda."),
) -> None:
    """Train the intent predictor (thesis §5.2.2; Algorithm 4.1 with resume:, 4.2 with transfer:)."""
    import json

    from coassist._io import atomic_write_text
    from coassist.intent.training import train_model, write_model

    p = _intent_preset(preset, epochs=epochs, lr=lr, batch_size=batch_size, seed=seed, threads=threads,
                       test_fraction=test_fraction, init=init, device=device)  # fmt: skip
    trials = _intent_trials(data)
    history: list = []

    def log(record: dict) -> None:
        history.append(record)
        atomic_write_text(out / "history.json", json.dumps(history, indent=1) + "\n")

    try:
        model = train_model(trials, p, p.train, progress=True, on_epoch=log)
    except ValueError as exc:  # mismatched model, unknown init, too-short trials
        console.print(f"[red]error:[/] {exc}")
        raise typer.Exit(2) from None
    write_model(model, out)
    last = model.info["training_history"][-1]
    console.print(
        f"[green]wrote[/] {out}  train {len(model.info['train_trials'])} / test {len(model.info['test_trials'])} trials, "
        f"final train loss {last['train_loss']:.3e}, test loss {last['test_loss'] if last['test_loss'] is None else format(last['test_loss'], '.3e')}, "
        f"{model.info['train_seconds']:.0f} s"
    )


@app.command()
def evaluate(
    model: Path = typer.Option(..., "--model", "-m", help="Model folder written by `coassist train`."),
    data: list[Path] = typer.Option(..., "--data", "-d", help="Dataset or recording folders to score on (repeatable)."),
    out: Path = typer.Option(None, help="JSON file for the results (default: <model>/evaluation.json)."),
    include_training: bool = typer.Option(False, help="Also score trials the model was trained on."),
) -> None:
    """e_RMS and e_MAX per horizon for the model and the baselines (nominal, constant velocity, ridge)."""
    import json

    from coassist._io import atomic_write_text
    from coassist.intent import ModelFileError, ModelMismatchError, evaluate_model, load_model, results_table

    try:
        m = load_model(model)
    except ModelFileError as exc:
        raise typer.BadParameter(str(exc), param_hint="--model") from None
    trials = _intent_trials(data)
    try:
        result = evaluate_model(m, trials, held_out_only=not include_training)
    except (ModelMismatchError, ValueError) as exc:
        console.print(f"[red]error:[/] {exc}")
        raise typer.Exit(2) from None
    result["model"] = str(model)
    console.print(results_table(result, f"{model}: {len(result['trials'])} trials, {result['n_ticks']} ticks"))
    if result["skipped"]:
        console.print(f"skipped {len(result['skipped'])} training trials (use --include-training to score them)")
    dest = out or model / "evaluation.json"
    atomic_write_text(dest, json.dumps(result, indent=1) + "\n")
    console.print(f"[green]wrote[/] {dest}")


@app.command()
def tune(
    data: list[Path] = typer.Argument(..., help="Dataset or recording folders."),
    preset: str = typer.Option("default", help="Preset whose window and training defaults are searched around."),
    n_trials: int = typer.Option(20, "--trials", help="Optuna trials to run."),
    storage: str = typer.Option("sqlite:///study.db", help="Optuna storage URL (any database URL Optuna accepts)."),
    study_name: str = typer.Option("intent", help="Study name (resumed if it exists)."),
    epochs: int = typer.Option(None, help="Epochs per trial (default: the preset's)."),
    seed: int = typer.Option(0, help="Sampler seed."),
) -> None:
    """Optuna search over optimiser, learning rate and sizes; objective: validation e_RMS at the full horizon."""
    from coassist.intent.tuning import run_study

    if n_trials < 1:
        raise typer.BadParameter("must be >= 1", param_hint="--trials")
    p = _intent_preset(preset)
    trials = _intent_trials(data)
    result = run_study(trials, p, n_trials=n_trials, storage=storage, study_name=study_name, epochs=epochs, seed=seed,
                       progress=True)  # fmt: skip
    console.print(f"best validation e_RMS {1e3 * result['best_value']:.2f} mm with {result['best_params']}")
    console.print(f"study {result['study_name']!r} in {result['storage']} ({result['n_trials']} trials)")


def _int_list(text: str, name: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise typer.BadParameter(f"{name} must be comma-separated integers, got {text!r}") from None
    if not values or any(v < 0 for v in values):
        raise typer.BadParameter(f"{name} must list integers >= 0, got {text!r}")
    return values


def _name_list(text: str, name: str, allowed: tuple[str, ...]) -> list[str]:
    values = [v.strip() for v in text.split(",") if v.strip()]
    bad = [v for v in values if v not in allowed]
    if not values or bad:
        raise typer.BadParameter(f"{name} must be comma-separated values from {', '.join(allowed)}; got {text!r}")
    return values


@app.command()
def collect(
    out: Path = typer.Option(..., help="Dataset folder to write (trial Parquet files + manifest.json)."),
    controller: str = typer.Option("cooperative", help="cooperative | impedance | manual."),
    users: str = typer.Option("0", help="Simulated operators, comma-separated (0 = the thesis' author)."),
    tasks: str = typer.Option("linear,curved,sinusoidal", help="Nominal paths: linear, curved, sinusoidal, z."),
    objects: str = typer.Option("handle", help="Objects: handle, board, heavy."),
    trials: int = typer.Option(20, help="Trials per user, object and task."),
    seed: int = typer.Option(0, help="Seed of the first trial; trial i uses seed + i."),
    preset: str = typer.Option("thesis-evaluation", help="Control preset (thesis-evaluation[-dm], thesis-application[-dm])."),
    intent: str = typer.Option("nominal", help="nominal | oracle | path of an intent model."),
    dataset_id: str = typer.Option(None, help="Dataset id (default: the folder's name)."),
    workers: int = typer.Option(None, help="Local worker processes (default: one per CPU)."),
    ray_address: str = typer.Option(None, help="Run on a Ray cluster at this address (needs coassist[cluster])."),
    overwrite: bool = typer.Option(False, help="Replace an existing dataset folder."),
) -> None:
    """Simulate trials and write them as a dataset (thesis §5.2.2; default: D0, 60 trials)."""
    from coassist.sim import CONTROLLER_KINDS, OBJECTS, PRESETS, TASK_KINDS
    from coassist.sim.collect import collect_dataset

    if controller not in CONTROLLER_KINDS:
        raise typer.BadParameter(f"controller must be one of {', '.join(CONTROLLER_KINDS)}, got {controller!r}")
    if preset not in PRESETS:
        raise typer.BadParameter(f"preset must be one of {', '.join(PRESETS)}, got {preset!r}")
    if trials < 1 or seed < 0 or (workers is not None and workers < 1):
        raise typer.BadParameter("trials and workers must be >= 1 and seed >= 0")
    try:
        folder = collect_dataset(
            out, dataset_id=dataset_id, workers=workers, progress=True, ray_address=ray_address, overwrite=overwrite,
            controller=controller, users=_int_list(users, "users"), tasks=_name_list(tasks, "tasks", TASK_KINDS),
            objects=_name_list(objects, "objects", tuple(OBJECTS)), trials=trials, seed=seed, preset=preset,
            intent=intent,
        )
    except (ValueError, FileExistsError, RuntimeError) as exc:
        console.print(f"[red]error:[/] {exc}")
        raise typer.Exit(1) from None
    console.print(f"[green]wrote[/] {folder}")


@app.command()
def drive(
    out: Path = typer.Option(Path("runs/drive/trial.parquet"), help="Trial file to write (the same format as collect's trials, plus joint columns)."),
    world: str = typer.Option("mujoco", help="mujoco (a UR5 in MuJoCo physics) | ur (a real UR5 through ur-rtde)."),
    controller: str = typer.Option("assistive", help="assistive (the cooperative game) | imp (impedance control) | mg (manual guidance)."),
    task: str = typer.Option("linear", help="Nominal path: linear, curved, sinusoidal, z."),
    obj: str = typer.Option("handle", "--object", help="Carried object: handle, board, heavy."),
    intent: str = typer.Option("nominal", help="nominal | oracle (MuJoCo) | path of an intent model (coassist train)."),
    preset: str = typer.Option("thesis-application-dm", help="Control preset (the main job's by default)."),
    user: int = typer.Option(0, help="Simulated operator (MuJoCo world)."),
    seed: int = typer.Option(0, help="Seed of the task, the simulated operator and the sensor noise."),
    rate: int = typer.Option(125, help="Control rate in Hz: 125 (UR CB3) or 500 (e-Series)."),
    full_pose: bool = typer.Option(False, help="Control all 6 DOFs instead of the x-y plane."),
    time_limit: float = typer.Option(None, help="Longest run in seconds (default: 2 x the plan + 10 s)."),
    tool_speed: float = typer.Option(0.25, help="Safety: largest tool speed in m/s."),
    contact_force: float = typer.Option(120.0, help="Safety: hand force in N that makes a protective stop."),
    host: str = typer.Option(None, help="The real arm's IP address (--world ur)."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask for confirmation before a real arm moves (scripts)."),
    view: bool = typer.Option(False, help="Open MuJoCo's passive viewer (needs a display) and run in real time."),
    plot: bool = typer.Option(True, help="Also write the monitor figure (<out>.png)."),
) -> None:
    """Run the assistive controller, IMP or MG on a UR5: in MuJoCo, or on a real arm."""
    from coassist.data import write_trial
    from coassist.robot.drive import DriveConfig
    from coassist.robot.drive import drive as run_drive
    from coassist.runtime.safety import SafetyLimits

    try:
        limits = SafetyLimits(tool_speed=tool_speed, contact_force=contact_force)
        config = DriveConfig(world=world, controller=controller, task=task, object=obj, preset=preset, intent=intent,
                             user=user, seed=seed, rate_hz=rate, full_pose=full_pose, time_limit=time_limit,
                             limits=limits)  # fmt: skip
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    if out.exists() and out.is_dir():
        raise typer.BadParameter(f"{out} is a folder; give a trial file name", param_hint="--out")

    def confirm(text: str) -> bool:
        console.print("[bold]Limits in force[/] (coassist's safety layer, on top of the robot's own safety system):", markup=True)
        console.print(text, markup=False)
        console.print("Keep the teach pendant's emergency stop within reach.", markup=False)
        return yes or typer.confirm("Move the robot?", default=False)

    try:
        trial = run_drive(config, host=host, view=view, confirm=confirm if world == "ur" else None)
    except (ValueError, RuntimeError, ImportError, ConnectionError, OSError) as exc:
        console.print(f"[red]error:[/] {exc}", markup=True, highlight=False)
        raise typer.Exit(1) from None
    path = write_trial(trial, out)
    extra = trial.meta.extra
    console.print(f"[green]wrote[/] {path}: {trial.n_samples} ticks, ended: {extra['ended']}", highlight=False)
    if extra.get("stop_message"):
        console.print(f"[yellow]{extra['stop_message']}[/]", highlight=False)
    if plot:
        from coassist.sim.monitor import plot_trial

        console.print(f"[green]wrote[/] {plot_trial(trial, path.with_suffix('.png'))}")


@app.command()
def show(
    path: Path = typer.Argument(..., help="A trial file, a dataset folder or a ROS CSV recording folder."),
    out: Path = typer.Option(None, help="PNG to write (default: <name>.png in the current folder)."),
    index: int = typer.Option(0, help="Which trial of a dataset."),
) -> None:
    """The monitor view of a trial (thesis Fig. 5.7–5.8) and its force over time."""
    from coassist.sim.monitor import load_for_show, plot_trial

    try:
        trial = load_for_show(path, index)
    except (ValueError, OSError) as exc:
        console.print(f"[red]error:[/] {exc}")
        raise typer.Exit(1) from None
    if out is None:
        out = Path(f"{path.resolve().name}{'' if index == 0 else f'_{index}'}.png")
    console.print(f"[green]wrote[/] {plot_trial(trial, out)}")


@app.command()
def realism(
    out: Path = typer.Option(Path("docs/realism.md"), help="Markdown report to write."),
    real: Path = typer.Option(None, help="Folder of real trial_* recordings (default: user-a of ../shared/data/ur5-thesis or $COASSIST_REAL_DATA)."),
    trials: int = typer.Option(10, help="Simulated trials per task and preset."),
    seed: int = typer.Option(0, help="Seed of the first simulated trial."),
    workers: int = typer.Option(None, help="Local worker processes (default: one per CPU)."),
) -> None:
    """Simulated trials (user 0, handle, cooperative, nominal intent) side by side with real user-a trials."""
    from coassist.experiments import realism as realism_exp

    from coassist.data import default_real_data

    if trials < 1 or seed < 0:
        raise typer.BadParameter("trials must be >= 1 and seed >= 0")
    real = real or default_real_data() / "user-a"
    try:
        result = realism_exp.run_realism(real, trials_per_task=trials, seed=seed, workers=workers, progress=True)
    except ValueError as exc:
        console.print(f"[red]error:[/] {exc}")
        raise typer.Exit(1) from None
    console.print(realism_exp.summary_table(result))
    console.print(f"[green]wrote[/] {realism_exp.write_report(result, out, realism_exp.NOTES)}")


@app.command()
def reproduce(
    out: Path = typer.Option(Path("runs/reproduce"), help="Output folder: report.html, summary.json, datasets, models."),
    preset: str = typer.Option("default", help="default (≤ 15 min on 2 CPU cores), tiny (smoke run) or thesis (thesis sizes; GPU)."),
    seed: int = typer.Option(0, help="Seed of every dataset and training."),
    workers: int = typer.Option(None, help="Simulation processes (default: the preset's)."),
    device: str = typer.Option(None, help="Torch device for training, e.g. cpu or cuda (default: the preset's)."),
    real_data: Path = typer.Option(None, help="Folder with user-a/ and user-b/ recordings (default: ../shared/data/ur5-thesis or $COASSIST_REAL_DATA)."),
) -> None:
    """The thesis' experiments end to end in simulation (dMPC study, iterative training, transfer, application, real data): one HTML report."""
    from dataclasses import replace

    from coassist.experiments import reproduce as rep

    if preset not in rep.PRESETS:
        raise typer.BadParameter(f"preset must be one of {tuple(rep.PRESETS)}, got {preset!r}", param_hint="--preset")
    changes = {"seed": seed}
    if workers is not None:
        changes["workers"] = workers
    if device is not None:
        changes["device"] = device
    if real_data is not None:
        if not (real_data / "user-a").is_dir():
            raise typer.BadParameter(f"{real_data} has no user-a/ folder of recordings", param_hint="--real-data")
        changes["real_data"] = str(real_data)
    try:
        config = replace(rep.PRESETS[preset], **changes)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    summary = rep.run_reproduce(config, out, progress=True, say=console.print)
    held = sum(1 for c in summary["claims"] if c["holds"])
    console.print(f"claims: {held} of {len(summary['claims'])} hold")
    for c in summary["claims"]:
        mark = "[green]holds[/]" if c["holds"] else "[red]does not hold[/]"
        console.print(f"  {mark}  {c['claim']}")
    console.print(f"[green]wrote[/] {out / 'report.html'} and {out / 'summary.json'} in {summary['total_seconds']:.0f} s")


if __name__ == "__main__":  # pragma: no cover
    app()
