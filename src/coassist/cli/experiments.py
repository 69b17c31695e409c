"""The thesis' experiments: ``sweep`` (the dMPC study), ``realism``, ``compare-intents`` and ``reproduce``."""

from __future__ import annotations

import re
from pathlib import Path

import typer
from rich.markup import escape

from coassist.cli._common import (
    check_device,
    choose,
    console,
    fail,
    file_out,
    int_list,
    lookup,
    results_out,
    typed,
    wrote,
)
from coassist.cli._threads import set_torch_threads


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
        fail(typed(str(exc), {"duration": "--duration", "position_scale": "--position-scale"}), 2)
    results_out(out, "--out", ("summary.json", "dmpc_sweep.png"), (("experiment", "cases", "si_units"),))
    result = dmpc_study.run_sweep(config, out, progress=True)
    dmpc_study.print_summary(result, console)
    wrote(f"{out / 'summary.json'} and {out / 'dmpc_sweep.png'}")


def realism(
    out: Path = typer.Option(Path("docs/realism.md"), help="Markdown report to write."),
    real: Path = typer.Option(
        None, help="Folder of real trial_* recordings (default: $COASSIST_REAL_DATA/user-a; see README)."
    ),
    trials: int = typer.Option(10, help="Simulated trials per task and preset."),
    seed: int = typer.Option(0, help="Seed of the first simulated trial."),
    workers: int = typer.Option(None, help="Local worker processes (default: one per CPU)."),
    population: list[str] = typer.Option(
        [],
        "--population",
        help="Also a population's users against user-a (repeatable): thesis, varied, held-out or unseen.",
    ),
    population_users: str = typer.Option("0,1,2,3,4,5", help="The users of each --population."),
    population_trials: int = typer.Option(3, help="Trials per --population user and task."),
) -> None:
    """Simulated trials (user 0, handle, cooperative, nominal intent) side by side with real user-a trials."""
    from coassist.data import default_real_data
    from coassist.experiments import realism as realism_exp
    from coassist.scenario import POPULATIONS

    for value, option, minimum in (
        (trials, "--trials", 1),
        (seed, "--seed", 0),
        (workers, "--workers", 1),
        (population_trials, "--population-trials", 1),
    ):
        if value is not None and value < minimum:
            fail(f"{option} must be >= {minimum}, got {value}", 2)
    for name in population:
        choose(name, POPULATIONS, "--population", "population")
    users = int_list(population_users, "--population-users")
    real = real or default_real_data() / "user-a"
    if not real.is_dir():
        fail(f"--real {real}: no such folder (set COASSIST_REAL_DATA to the folder holding user-a/)", 2)
    # an earlier report is replaced, no other file (a CSV of data, notes: overwritten unasked once)
    out = file_out(out, "--out", "realism.md", ours=realism_exp.is_realism_report, ext=".md")
    try:
        result = realism_exp.run_realism(
            real,
            trials_per_task=trials,
            seed=seed,
            workers=workers,
            progress=True,
            populations=population,
            population_users=users,
            population_trials=population_trials,
        )
    except ValueError as exc:
        fail(str(exc))
    console.print(realism_exp.summary_table(result))
    if result.populations:
        console.print(realism_exp.population_table(result))
        console.print(realism_exp.family_table(result))
    wrote(str(realism_exp.write_report(result, out, realism_exp.NOTES)))


def compare_intents(
    source: list[str] = typer.Option(
        ...,
        help="LABEL=INTENT, repeatable: a named source (present, paths, …), a model "
        "folder or a calibration folder; paths alone is calibrated on each base's trials, person alone is "
        "each operator's person model fitted to their probe trials of each base.",
    ),
    out: Path = typer.Option(Path("runs/compare-intents"), help="Folder for the datasets, table.md and summary.json."),
    bases: str = typer.Option(
        "50000,60000", help="Validation seed bases (application_seed(base, j); never the report's 0)."
    ),
    damped: str = typer.Option(
        "", help="Labels to run with the cooperative-damped controller instead of the arbitrated one."
    ),
    cooperative: str = typer.Option(
        "", help="Labels to run with the plain cooperative controller (α fixed; drive's default) instead."
    ),
    trials: int = typer.Option(4, help="Trials per operator, object and base."),
    workers: int = typer.Option(2, help="Simulation processes."),
    population: str = typer.Option(
        "thesis", help="The simulated operators: thesis or varied (the in-family population to tune on)."
    ),
    users: str = typer.Option("0,1,2", help="The operators (user indices of the population), comma-separated."),
    probe_trials: int | None = typer.Option(
        None, help="Probe trials per operator and calibration draw for person (default: the main job's)."
    ),
    asked_trials: int | None = typer.Option(
        None,
        help="Then the most trials each calibration asks of an operator for a way round its probe trials showed too seldom (0: none; default: the main job's).",
    ),
) -> None:
    """Intent sources in the loop on validation seeds, paired against MG and the oracle (docs/precision.md)."""
    import json

    from coassist._io import atomic_write_text
    from coassist.experiments.precision import compare_intents as run
    from coassist.experiments.precision import comparison_table
    from coassist.experiments.reproduce import jsonable

    pairs = {}
    for item in source:
        label, sep, spec = item.partition("=")
        if not sep or not label or not spec:
            fail(f"--source {item!r}: expected LABEL=INTENT", 2)
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_+.-]*", label) or ".." in label:  # it names dataset folders
            fail(f"--source {item!r}: a label is letters, digits and - _ + . (it names folders), got {label!r}", 2)
        if label in pairs:
            fail(f"--source {label}: given twice", 2)
        pairs[label] = spec
    seeds = int_list(bases, "--bases")
    operators = int_list(users, "--users")
    chosen: dict[str, str] = {}
    for option, text, kind in (
        ("--damped", damped, "cooperative-damped"),
        ("--cooperative", cooperative, "cooperative"),
    ):
        for label in (d for d in text.split(",") if d):
            if label not in pairs:
                fail(f"{option} {label}: not a --source label", 2)
            if label in chosen:
                fail(f"{option} {label}: also given another controller", 2)
            chosen[label] = kind
    for value, option in ((trials, "--trials"), (workers, "--workers"), (probe_trials, "--probe-trials")):
        if value is not None and value < 1:
            fail(f"{option} must be >= 1, got {value}", 2)
    if asked_trials is not None and not 0 <= asked_trials <= 8:
        fail(f"--asked-trials must be 0 to 8, got {asked_trials}", 2)
    out = results_out(out, "--out", ("summary.json", "table.md"), (("preset", "models", "cells", "pairs"),))
    try:
        result = run(
            pairs,
            out,
            bases=seeds,
            controllers=chosen,
            trials=trials,
            workers=workers,
            population=population,
            users=operators,
            probe_trials=probe_trials,
            asked_trials=asked_trials,
        )
    except ValueError as exc:
        fail(str(exc), 2)
    # the numbers first: what took the simulations is kept whatever the table's formatting meets
    atomic_write_text(out / "summary.json", json.dumps(jsonable(result.summary()), indent=1, allow_nan=True))
    table = comparison_table(result)
    console.print(table, markup=False, highlight=False)
    atomic_write_text(out / "table.md", table + "\n")
    wrote(str(out / "table.md"))


def reproduce(
    out: Path = typer.Option(
        Path("runs/reproduce"), help="Output folder: report.html, summary.json, datasets, models."
    ),
    preset: str = typer.Option(
        "default",
        help="default (about 10 min on 2 CPU cores), full (the pre-issue-35 default: more training data), "
        "tiny (smoke run) or thesis (thesis sizes; GPU).",
    ),
    seed: int = typer.Option(0, help="Seed of every dataset and training."),
    seeds: str = typer.Option(
        None,
        help="Run on several seeds instead: a count N (seeds 0 … N-1) or a list like 0,1,2; "
        "one report says on how many seeds each claim holds.",
    ),
    workers: int = typer.Option(None, help="Simulation processes (default: the preset's)."),
    device: str = typer.Option(None, help="Torch device for training, e.g. cpu or cuda (default: the preset's)."),
    real_data: Path = typer.Option(
        None, help="Folder with user-a/ and user-b/ recordings (default: $COASSIST_REAL_DATA; see README)."
    ),
    held_out_people: int = typer.Option(
        None,
        help="Which people of the held-out cells' population the report meets: its population seed (default 0, the "
        "operators every report has met; another draws new people of its families, whom no choice has seen).",
    ),
    held_out_population: str = typer.Option(
        None,
        help="Whose detour families the held-out cells meet: held-out (Corrective, Hesitant; the default) or "
        "unseen (Feint, Ringing: families made after every choice of the person model; docs/person-model.md).",
    ),
) -> None:
    """The thesis' experiments end to end in simulation (dMPC study, iterative training, transfer, application, real data): one HTML report."""
    from dataclasses import replace

    from coassist.experiments import reproduce as rep
    from coassist.experiments import seeds as multi

    seed_list = None
    if seeds is not None:
        if seed != 0:
            fail("give --seed or --seeds, not both", 2)
        try:
            seed_list = multi.parse_seeds(seeds)
        except ValueError as exc:
            fail(str(exc), 2)

    chosen = lookup(rep.REPRODUCE_PRESETS, preset, "--preset")
    check_device(device)
    changes = {"seed": seed}
    if workers is not None:
        changes["workers"] = workers
    if device is not None:
        changes["device"] = device
    if held_out_people is not None:
        changes["held_out_people"] = held_out_people
    if held_out_population is not None:
        changes["held_out_population"] = held_out_population
    if real_data is not None:
        if not real_data.is_dir():
            fail(f"--real-data {real_data}: no such folder", 2)
        if not (real_data / "user-a").is_dir():
            fail(f"--real-data {real_data}: has no user-a/ folder of recordings", 2)
        changes["real_data"] = str(real_data)
    try:
        config = replace(chosen, **changes)
    except ValueError as exc:
        fail(
            typed(
                str(exc),
                {
                    "reproduce.seed": "--seed",
                    "reproduce.workers": "--workers",
                    "reproduce.device": "--device",
                    "reproduce.held_out_people": "--held-out-people",
                    "reproduce.held_out_population": "--held-out-population",
                },
            ),
            2,
        )
    # a single run's summary holds its config, several seeds' their list: another program's is not replaced
    results_out(out, "--out", ("summary.json", "report.html"), (("config",), ("preset", "seeds", "claims")))
    set_torch_threads(config.threads)  # training runs in this process
    if seed_list is not None:
        across = multi.run_seeds(
            config, seed_list, out, progress=True, say=lambda line: console.print(line, highlight=False)
        )
        console.print(f"claims: {across['robust']} of {across['n_claims']} hold on every seed")
        for c in across["claims"]:
            mark = {"robust": "[green]robust[/]", "seed-dependent": "[yellow]seed-dependent[/]"}.get(
                c["status"], "[red]not holding[/]"
            )
            console.print(f"  {mark} ({c['holds_on']} of {c['checked_on']})  {escape(c['claim'])}", highlight=False)
        wrote(f"{out / 'report.html'} and {out / 'summary.json'} in {across['total_seconds']:.0f} s")
        return
    summary = rep.run_reproduce(config, out, progress=True, say=lambda line: console.print(line, highlight=False))
    held = sum(1 for c in summary["claims"] if c["holds"])
    console.print(f"claims: {held} of {len(summary['claims'])} hold")
    for c in summary["claims"]:
        mark = "[green]holds[/]" if c["holds"] else "[red]does not hold[/]"
        console.print(f"  {mark}  {escape(c['claim'])}", highlight=False)
    wrote(f"{out / 'report.html'} and {out / 'summary.json'} in {summary['total_seconds']:.0f} s")
