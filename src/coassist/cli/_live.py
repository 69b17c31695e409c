"""The live view (``--foxglove``) of the commands that run trials: its optional port and its feed."""

from __future__ import annotations

import re

from coassist.cli._common import console, err_console, fail

#: The bare ``--foxglove`` port of the commands without a page (the Foxglove app's default), and of
#: play and study run, whose page listens on 8765.
FOXGLOVE_PORT, FOXGLOVE_PAGE_PORT = 8765, 8766
LIVE_HELP = (
    "Serve the run live to the Foxglove app on this port (bare --foxglove: {port}; the viz extra): "
    "ws://127.0.0.1:PORT, the MCAP file's topics and the scene at 30 Hz (docs/foxglove.md)."
)


def live_command(port: int) -> type:
    """A command class whose ``--foxglove`` takes an optional port: bare (followed by nothing, another
    option or an argument that is not a number) it means ``port`` (typer has no optional values)."""
    from typer.core import TyperCommand

    class LiveCommand(TyperCommand):
        def parse_args(self, ctx, args):
            out = list(args)
            for i, arg in enumerate(out):
                if arg == "--":
                    break
                if arg == "--foxglove" and not (i + 1 < len(out) and re.fullmatch(r"[+-]?\d+", out[i + 1])):
                    out[i] = f"--foxglove={port}"
            return super().parse_args(ctx, out)

    return LiveCommand


def open_live(port: int | None, page_port: int | None = None):
    """The live view's feed on ``port`` (None: no --foxglove), or one line saying why not: a port out
    of range, the page's own, one in use, the viz extra missing. Started before anything moves."""
    if port is None:
        return None
    if not 0 <= port <= 65535:
        fail(f"--foxglove must be a port in 1 … 65535 (0: any free one), got {port}", 2)
    if page_port is not None and port == page_port and port != 0:
        fail(
            f"--foxglove {port}: the page listens on it (--port); give the live view another, e.g. --foxglove {port + 1}",
            2,
        )
    from coassist.runtime.foxglove import LiveServerError, open_foxglove

    try:
        feed, sink = open_foxglove(port)
    except ImportError as exc:
        fail(f"--foxglove: {exc}", 2)
    except (LiveServerError, ValueError) as exc:
        fail(f"--foxglove {port}: {exc}", 2)
    console.print(
        f"live view: open {sink.url} in Foxglove (Open connection, Foxglove WebSocket)",
        highlight=False,
        markup=False,
        soft_wrap=True,
    )
    return feed


def close_live(feed) -> None:
    """Publish the last tick and stop the live view; say so if publishing failed on the way."""
    if feed is None:
        return
    feed.close()
    if feed.failures:
        err_console.print(f"live view: {feed.failures} tick(s) not published ({feed.last_error})", markup=False)
