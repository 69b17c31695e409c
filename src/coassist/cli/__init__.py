"""The ``coassist`` command: a thin shell over the experiments and tools.

Each command parses and validates its options, then calls one function of the
library; no computation lives here. One module per command group (``intent``: train,
evaluate, tune; ``collect``; ``robot``: drive, ur-sim; ``ros2``; ``trials``: calibrate,
show; ``play``; ``experiments``: sweep, realism, compare-intents, reproduce; ``study``),
what they share in ``_common`` (the console and the checks) and ``_live`` (``--foxglove``);
this module builds the one typer app from them, in the order ``coassist --help`` lists.
"""

from __future__ import annotations

import typer

from coassist.cli import collect, experiments, intent, play, robot, ros2, study, trials
from coassist.cli._live import FOXGLOVE_PAGE_PORT, FOXGLOVE_PORT, live_command

__all__ = ["app"]

app = typer.Typer(
    help="coassist — assistive pHRI: cooperative game-theoretic MPC with learned human intent.",
    no_args_is_help=True,
    add_completion=False,
    # Plain click help: rich markup would swallow bracketed text ("[s]", "coassist[cluster]"),
    # and its boxed layout leaves a narrow column for the help text at 80 columns.
    rich_markup_mode=None,
)


@app.callback()
def main() -> None:
    """coassist — assistive pHRI: cooperative game-theoretic MPC with learned human intent."""


# The commands, in the order the help lists them. The ones that run trials take --foxglove with an
# optional port (live_command): the Foxglove app's default, or the next one where a page listens.
app.command()(experiments.sweep)
app.command()(intent.train)
app.command()(intent.evaluate)
app.command()(intent.tune)
app.command(cls=live_command(FOXGLOVE_PORT))(collect.collect)
app.command(cls=live_command(FOXGLOVE_PORT))(robot.drive)
app.command(cls=live_command(FOXGLOVE_PORT))(ros2.ros2)
app.command("ros2-watchdog")(ros2.ros2_watchdog)
app.command("ur-sim")(robot.ur_sim)
app.command()(trials.calibrate)
app.command()(trials.show)
app.command(cls=live_command(FOXGLOVE_PAGE_PORT))(play.play)
app.command()(experiments.realism)
app.command("compare-intents")(experiments.compare_intents)
app.command()(experiments.reproduce)
app.add_typer(study.study_app, name="study")
