"""`coassist play` end to end: pointer event → force in the loop → new state → frame drawn.

    .venv/bin/python benchmarks/bench_play.py [--seconds 12] [--controller cooperative] [--model MODEL]
                                              [--screenshot docs/figures/play.png]

Runs the real server (uvicorn, the loop thread paced at 125 Hz through the control tick)
and Debian's Chromium headless (Playwright, /usr/bin/chromium). A scripted mouse grabs
the tool and drags it along the plan, around the obstacle, with a small wiggle, moving
the mouse about every 16 ms. The page times every pointer event from its
``event.timeStamp`` to the end of the first animation frame that drew a state computed
with that pointer (the frame's echoed pointer sequence number): the whole chain, including
the browser's input queue, the websocket both ways, waiting for the next 8 ms tick, the
tick, the physics and waiting for the display frame.

Two runs in one process, the same script:

- ``per-tick``: the server pushes every control period's frame (coassist's design);
- ``naive 30 Hz``: the server pushes the newest frame on a fixed 30 Hz timer (a common
  "send the state at display rate" design).

Also measured: the transport floor (a ping answered by the server at once, round trip
seen by the page, nothing drawn), the page's frames/s, the loop's rate and its late ticks.
Prints median and p99 [ms] and the ratios. Target: p99 ≤ 50 ms.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from coassist.play.server import PlayServer  # noqa: E402
from coassist.play.session import PlayConfig, PlaySession  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def _stats(ms) -> tuple[float, float]:
    a = np.asarray(ms, dtype=float)
    return float(np.median(a)), float(np.percentile(a, 99))


def drive_page(
    pw, url: str, session: PlaySession, seconds: float, controller: str, screenshot: Path | None, profile: Path
) -> dict:
    """Drag for ``seconds``; the script reads the live state from the session (in this process), so the
    only browser call per step is the mouse move itself."""
    context = pw.chromium.launch_persistent_context(
        str(profile),
        executable_path=CHROMIUM,
        headless=True,
        args=CHROMIUM_ARGS,
        viewport={"width": 1360, "height": 820},
    )
    try:
        page = context.pages[0] if context.pages else context.new_page()
        page.goto(url)
        page.wait_for_function("window.coassist && window.coassist.ready", timeout=15000)
        page.select_option("#controller", controller)
        for _ in range(200):  # the transport floor: ping → pong, one at a time
            page.evaluate("window.coassist.ping()")
            time.sleep(0.005)
        page.click("#start")
        page.wait_for_function("window.coassist.frame !== null", timeout=10000)
        scene = page.evaluate("window.coassist.scene")
        # the page's metres → pixels map is affine: two points give it
        (ax, ay), (bx, by) = page.evaluate("[window.coassist.toPixels(0, 0), window.coassist.toPixels(1, 1)]")
        to_px = lambda p: (ax + (bx - ax) * p[0], ay + (by - ay) * p[1])  # noqa: E731
        obstacle = np.array(scene["obstacle"]["center"])
        page.mouse.move(*to_px(scene["start"]))
        page.mouse.down()
        page.evaluate("window.coassist.latencies.length = 0; window.coassist.stages.length = 0")
        draws0, t0, shot = page.evaluate("window.coassist.draws"), time.perf_counter(), False
        k0, k1, t1, f = session.frame["k"], None, t0, session.frame
        while time.perf_counter() - t0 < seconds and session.running:
            f = session.frame
            k1, t1 = f["k"], time.perf_counter()
            aim = np.array(f["ref"], dtype=float)
            d = float(np.linalg.norm(aim - obstacle))
            if d < 0.12:  # go around the box the way a person would: sideways, smoothly
                aim[1] += 0.09 * math.cos(0.5 * math.pi * d / 0.12) ** 2
            t = time.perf_counter() - t0
            aim += 0.006 * np.array([math.sin(9.0 * t), math.cos(7.0 * t)])  # keep the hand moving
            page.mouse.move(*to_px(aim))
            if screenshot is not None and not shot and abs(f["x"] - obstacle[0]) < 0.02:
                page.screenshot(path=str(screenshot))
                shot = True
            time.sleep(0.016)
        elapsed = time.perf_counter() - t0
        fps = (page.evaluate("window.coassist.draws") - draws0) / elapsed
        page.mouse.up()
        return {
            "latency": page.evaluate("window.coassist.latencies"),
            "stages": page.evaluate("window.coassist.stages"),
            "pong": page.evaluate("window.coassist.pongs"),
            "fps": fps,
            "loop_hz": (k1 - k0) / (t1 - t0) if t1 > t0 else math.nan,
            "misses": f["misses"],
        }
    finally:
        context.close()


def one_run(label: str, frame_rate: float | None, args, screenshot: Path | None) -> dict:
    from playwright.sync_api import sync_playwright

    tmp = Path(tempfile.mkdtemp(prefix="bench-play-"))
    try:
        config = PlayConfig(
            user="bench", out=tmp / "runs", controllers=(args.controller,), intent=args.model or "nominal"
        )
        session = PlaySession(config)
        with PlayServer(session, port=0, frame_rate=frame_rate) as server, sync_playwright() as pw:
            out = drive_page(pw, server.url, session, args.seconds, args.controller, screenshot, tmp / "profile")
        out["label"] = label
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds of dragging per run")
    ap.add_argument(
        "--repeats", type=int, default=2, help="runs of each design, alternating (the machine's load drifts)"
    )
    ap.add_argument("--controller", default="cooperative", choices=("cooperative", "impedance", "manual"))
    ap.add_argument("--model", default=None, help="an intent model folder (default: the nominal plan)")
    ap.add_argument("--screenshot", type=Path, default=None, help="write a screenshot of the page mid-trial (PNG)")
    args = ap.parse_args()
    if not Path(CHROMIUM).is_file():
        raise SystemExit(f"bench_play: no Chromium at {CHROMIUM} (apt-get install chromium)")
    if args.repeats < 1 or args.seconds <= 0:
        raise SystemExit("bench_play: --repeats must be >= 1 and --seconds > 0")
    if args.screenshot is not None:
        args.screenshot.parent.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()[0]
    designs = (("per-tick (coassist)", None), ("naive 30 Hz push", 30.0))
    runs: dict[str, list[dict]] = {label: [] for label, _ in designs}
    for i in range(args.repeats):
        for label, rate in designs:
            shot = args.screenshot if (i == 0 and rate is None) else None
            runs[label].append(one_run(label, rate, args, shot))
    print(
        f"pointer event → force → new state → frame drawn; {args.controller}, intent {args.model or 'nominal'}, "
        f"{args.repeats} × {args.seconds:.0f} s of dragging per design; load average {load0:.1f} → {os.getloadavg()[0]:.1f} "
        f"on {os.cpu_count()} CPUs"
    )
    print(
        f"{'run':24s} {'events':>6s} {'median ms':>10s} {'p99 ms':>8s} {'page fps':>9s} {'loop ticks/s':>13s} {'late ticks':>10s}"
    )
    pooled = {}
    for label, rs in runs.items():
        for r in rs:
            med, p99 = _stats(r["latency"])
            print(
                f"{label:24s} {len(r['latency']):6d} {med:10.1f} {p99:8.1f} {r['fps']:9.1f} {r['loop_hz']:13.1f} {r['misses']:10d}"
            )
        lat = np.concatenate([r["latency"] for r in rs])
        st = np.concatenate([np.asarray(r["stages"], dtype=float).reshape(-1, 2) for r in rs])
        pooled[label] = _stats(lat)
        (sm, sp), (rm, rp) = _stats(st[:, 0]), _stats(st[:, 1])
        print(
            f"  {label}, all runs: median {pooled[label][0]:.1f} / p99 {pooled[label][1]:.1f} ms over {len(lat)} events; "
            f"event → sent {sm:.1f} / {sp:.1f} ms, event → frame received {rm:.1f} / {rp:.1f} ms"
        )
    pong = np.concatenate([r["pong"] for r in runs[designs[0][0]]])
    floor_med, floor_p99 = _stats(pong)
    print(
        f"{'transport floor (ping)':24s} {len(pong):6d} {floor_med:10.1f} {floor_p99:8.1f}   (round trip, nothing drawn)"
    )
    (m0, p0), (m1, p1) = pooled[designs[0][0]], pooled[designs[1][0]]
    print(
        f"ratio naive / per-tick: median {m1 / m0:.2f}, p99 {p1 / p0:.2f}; per-tick p99 {p0:.1f} ms "
        f"{'≤' if p0 <= 50 else '>'} 50 ms target"
    )
    if args.screenshot is not None:
        print(f"wrote {args.screenshot}")


if __name__ == "__main__":
    main()
