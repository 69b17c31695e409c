"""What every benchmark prints about the machine it ran on (imported by the bench_*.py scripts)."""

from __future__ import annotations

import os
import platform
import time

import numpy as np


def machine_line() -> str:
    """One line: processor, CPU count, Python version."""
    return f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, python {platform.python_version()}"


def network_forward_flops(
    n_features: int, n_outputs: int, lstm_layers: int, hidden: int, fc, steps: int, skip_inputs: int = 0
) -> tuple[float, float]:
    """Multiply-add FLOPs of one window's forward pass through an ``IntentNet`` in its matrix
    products, (LSTM, head): the LSTM's gates, 4·h·(in + h)·2 per layer and step, over
    ``steps``; the FC head from the last hidden state, and the linear skip (with no LSTM
    the network is the skip alone, ``IntentNet``'s rule). Elementwise work is left out."""
    lstm = (
        sum(4 * hidden * ((n_features if layer == 0 else hidden) + hidden) * 2 for layer in range(lstm_layers)) * steps
    )
    widths = [hidden, *fc, n_outputs] if lstm_layers else []
    head = sum(2 * a * b for a, b in zip(widths, widths[1:])) + 2 * skip_inputs * n_outputs
    return float(lstm), float(head)


class RecordsWindows:
    """Mixed into an intent source (``class R(RecordsWindows, Source)``): it keeps the context and the windows
    it was given in the loop, for :func:`replay` to time them again on fresh sources."""

    def reset(self, context):
        super().reset(context)  # type: ignore[misc]
        self.context, self.windows = context, []

    def predict(self, history):
        self.windows.append(np.array(history))
        return super().predict(history)  # type: ignore[misc]


def replay(source, context, windows, clock=time.perf_counter_ns) -> np.ndarray:
    """Reset ``source`` to ``context`` and time its ``predict`` on each of ``windows`` with ``clock`` (ns); µs per call."""
    source.reset(context)
    times = np.empty(len(windows))
    for k, window in enumerate(windows):
        t0 = clock()
        source.predict(window)
        times[k] = clock() - t0
    return times / 1e3


def curved_trial(profile, seed: int, controller: str, source=None, obstacle: str = "large"):
    """One simulated trial of the curved task with ``profile``'s operator at the handle, under ``controller`` of the
    ``thesis-application-damped`` preset with the intent ``source`` (None: the controller's own), the task's obstacle
    drawn from ``seed`` (the person-model scripts' trials: calibration_paths.py, person_real.py --simulated)."""
    from coassist.control.presets import get_preset, make_controller
    from coassist.scenario.objects import get_object
    from coassist.scenario.tasks import task_for_seed
    from coassist.sim.trial_runner import run_trial

    task = task_for_seed("curved", seed, obstacle=obstacle)
    preset = get_preset("thesis-application-damped")
    return run_trial(task, profile, get_object("handle"), make_controller(controller, preset), source, seed)
