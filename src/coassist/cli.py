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


if __name__ == "__main__":  # pragma: no cover
    app()
