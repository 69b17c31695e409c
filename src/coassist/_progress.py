"""The terminal progress bar of long work (simulating datasets, training): one look everywhere."""

from __future__ import annotations

from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

__all__ = ["progress_bar"]


def progress_bar(enabled: bool) -> Progress:
    """A rich progress bar: each task's description, the bar, done/total, elapsed and remaining
    time. ``enabled`` False: it draws nothing (the calls still work)."""
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        disable=not enabled,
    )
