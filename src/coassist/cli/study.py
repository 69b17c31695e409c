"""``coassist study``: plan, run and report a study with people (or simulated participants)."""

from __future__ import annotations

import socket
from pathlib import Path

import typer

from coassist.cli._arm_runs import confirm_move
from coassist.cli._common import (
    console,
    fail,
    folder_out,
    results_out,
    wrote,
)
from coassist.cli._live import FOXGLOVE_PAGE_PORT, LIVE_HELP, close_live, live_command, open_live

study_app = typer.Typer(
    help="Run a study with people (or simulated participants): plan, run, report.",
    no_args_is_help=True,
    rich_markup_mode=None,
)


@study_app.command("init")
def study_init(
    plan: Path = typer.Argument(..., help="The study plan (TOML; docs/study.md)."),
    out: Path = typer.Option(..., "--out", "-o", help="The study folder to make (e.g. studies/<name>)."),
) -> None:
    """Check a study plan whole (every field, model and calibration; the session's time and memory) and make its
    study folder (the plan, its hash, the blinding key, the Latin square)."""
    from coassist.study.folder import StudyFolderError, init_study
    from coassist.study.plan import PlanError

    folder_out(out, "--out")
    try:
        study = init_study(plan, out)
    except PlanError as exc:
        fail(f"{plan}: {exc}", 2)
    except StudyFolderError as exc:
        fail(str(exc), 2)
    rec = study.record
    console.print(
        f"study {rec['name']!r}: protocol {rec['protocol']}, world {rec['world']}"
        + (f", conditions shown as {', '.join(sorted(rec['labels'].values()))}" if rec["labels"] else ""),
        highlight=False,
        markup=False,
    )
    estimate = study.estimate()
    for line in estimate.lines() if estimate is not None else ():
        console.print(line, highlight=False, markup=False, soft_wrap=True)
    if "rehearsal" in out.name:
        advice = f"rehearse it: coassist study run {out} --simulate --participant S01"
    else:
        rehearsal = out.with_name(out.name + "-rehearsal")
        advice = (
            "rehearse it before anyone sits down (a simulated participant, in a folder of its own): coassist study "
            f"init {plan} --out {rehearsal} && coassist study run {rehearsal} --simulate --participant S01"
        )
    console.print(advice, highlight=False, markup=False, soft_wrap=True)
    wrote(str(out))


@study_app.command("amend")
def study_amend(
    folder: Path = typer.Argument(..., help="The study folder."),
    plan: Path = typer.Argument(..., help="The amended plan (TOML): the study's plan with safe fields changed."),
    reason: str = typer.Option(..., "--reason", help="Why (one line, recorded in study.json with the change)."),
) -> None:
    """Amend the plan's safe fields (rests, the stop criterion, planned participants, id pattern, training threads)
    after trials have run; the change and its reason are recorded, the old plan kept in plans/."""
    from coassist.study.folder import StudyFolderError, amend_study
    from coassist.study.plan import PlanError

    try:
        amendment = amend_study(folder, plan, reason)
    except PlanError as exc:
        fail(f"{plan}: {exc}", 2)
    except StudyFolderError as exc:
        fail(str(exc), 2)
    for name, (old, new) in amendment["fields"].items():
        console.print(f"{name}: {old!r} -> {new!r}", highlight=False, markup=False)
    for name, began in amendment.get("not_reached", {}).items():
        console.print(
            f"{name}: {', '.join(began)} began with none there (a participant's steps are fixed at their first run): "
            "the new rest reaches the participants who begin from now",
            highlight=False,
            markup=False,
        )
    wrote(f"{folder} (plan {amendment['to_sha256'][:12]}; the old plan in plans/{amendment['from_sha256']}.toml)")


@study_app.command("run", cls=live_command(FOXGLOVE_PAGE_PORT))
def study_run(
    folder: Path = typer.Argument(..., help="The study folder (coassist study init)."),
    participant: str = typer.Option(
        None,
        "--participant",
        "-p",
        help="The participant's pseudonymous id (e.g. P07; nothing personal). With --simulate, default: every planned participant, S01, S02, …",
    ),
    simulate: bool = typer.Option(
        False, help="Simulated participants from the operator population stand in for people (a dry run)."
    ),
    page: bool = typer.Option(
        None, "--page/--no-page", help="Serve the page (default: on for a person, off with --simulate)."
    ),
    realtime: bool = typer.Option(False, help="Pace simulated participants to the wall clock, as a person's trials."),
    host: str = typer.Option("127.0.0.1", help="Address the page listens on; anything but this machine needs --token."),
    port: int = typer.Option(8765, help="Port of the page (0: any free port)."),
    token: str = typer.Option(None, help="Token the page must present (made for you on a non-local --host)."),
    robot_host: str = typer.Option(None, help="The real arm's address (world ur or franka)."),
    open_browser: bool = typer.Option(True, "--open/--no-open", help="Open the page in your web browser."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask before a real arm moves (scripts)."),
    foxglove: int = typer.Option(
        None,
        metavar="[PORT]",
        help=LIVE_HELP.format(port=FOXGLOVE_PAGE_PORT)
        + " For the experimenter: alpha and the prediction tell the conditions apart.",
    ),
) -> None:
    """Run a participant's steps in their recorded order (continuing where they stopped)."""
    from coassist._io import OutputBusyError
    from coassist.study.folder import StudyFolder, StudyFolderError
    from coassist.study.plan import PlanError, is_real_arm
    from coassist.study.runner import ParticipantRun, simulated_ids

    if not 0 <= port <= 65535:
        fail(f"--port must be 0..65535, got {port}", 2)
    use_page = (not simulate) if page is None else page
    try:
        study = StudyFolder(folder)
        plan = study.plan()
    except (StudyFolderError, PlanError) as exc:
        fail(str(exc), 2)
    if participant is None and not simulate:
        fail("--participant is needed for a person (a pseudonymous id such as P07)", 2)
    ids = [participant] if participant is not None else simulated_ids(plan.participants)
    if use_page:
        try:
            import starlette  # noqa: F401  (the web extra)

            from coassist.play.server import check_token, is_loopback, new_token
        except ImportError as exc:
            fail(f"the page needs the web extra ({exc.name} missing): pip install 'coassist[web]'")
        if token is None and not is_loopback(host):
            token = new_token()
        # before anyone is registered: a refused option must not start a participant (it would lock the plan)
        try:
            check_token(token, host)
            socket.getaddrinfo(host, None)
        except ValueError as exc:
            fail(str(exc), 2)
        except OSError as exc:
            fail(f"--host {host!r}: not an address this machine can listen on ({exc.strerror or exc})", 2)
    confirm = confirm_move(yes, "the emergency stop") if is_real_arm(plan.world) else None
    live = open_live(foxglove, page_port=port if use_page else None)  # stopped with the process on a failure
    for pid in ids:
        try:
            with ParticipantRun(
                study,
                pid,
                simulate=simulate,
                page=(host, port, token) if use_page else None,
                realtime=realtime,
                host=robot_host,
                confirm=confirm,
                say=lambda line: console.print(line, highlight=False, markup=False),
                live=live,
            ) as run:
                if run.complete:
                    console.print(f"{pid}: already complete", highlight=False)
                    continue
                if run.url is not None:
                    console.print(f"{pid}: open {run.url} (Ctrl+C stops; the same command continues)", highlight=False)
                    if open_browser:
                        import webbrowser

                        webbrowser.open(run.url)
                run.run()
        except KeyboardInterrupt:
            fail(f"{pid}: stopped; what finished is kept, and the same command continues where it stopped", 130)
        except (StudyFolderError, PlanError, OutputBusyError) as exc:
            fail(f"{pid}: {exc}")
        except Exception as exc:  # whatever failed, the participant is resumable: say so in one line
            what = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            fail(
                f"{pid}: {what} ({type(exc).__name__}); what finished is kept: fix the cause (coassist study "
                "amend changes the plan's safe fields) and the same command continues where it stopped"
            )
        console.print(f"{pid}: complete", highlight=False)
    close_live(live)
    wrote(str(folder))


@study_app.command("report")
def study_report(
    folder: Path = typer.Argument(..., help="The study folder."),
    out: Path = typer.Option(None, help="Folder for report.html and summary.json (default: <folder>/report)."),
) -> None:
    """The study's report: per participant and pooled measures, paired tests, questionnaires, order effects."""
    from coassist.study.folder import StudyFolderError
    from coassist.study.plan import PlanError
    from coassist.study.report import write_report

    if out is not None:  # another program's summary.json or page there is not replaced
        results_out(out, "--out", ("summary.json", "report.html"), (("study", "protocol", "plan_sha256"),))
    try:
        html_path, json_path = write_report(folder, out)
    except (StudyFolderError, PlanError, OSError) as exc:
        fail(str(exc), 2)
    wrote(f"{html_path} and {json_path}")
