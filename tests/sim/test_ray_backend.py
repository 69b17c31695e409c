"""The Ray backend of :func:`coassist.sim.trial_runner.run_trials` on a local, in-process Ray instance.

Ray 2.60 has no ``local_mode``: ``ray_address="local"`` makes ``run_trials`` start a
local instance (a raylet and worker processes on this machine), which is what a cluster
run does minus the network. The trials must be identical, bit for bit, to the process
pool's: same specs, same seeds, same numpy/BLAS build and BLAS thread count (Ray's
workers inherit the driver's environment, so the thread variables are pinned before
either runner starts).
"""

from __future__ import annotations

import pytest

from coassist.sim.trial_runner import TrialSpec, run_trials

ray = pytest.importorskip("ray", reason="Ray is the optional 'cluster' extra: pip install -e '.[cluster]'")

# Two short trials that differ in everything a spec carries (task, user, seed, object,
# controller): most of the test's time is starting processes, not simulating.
SPECS = [
    TrialSpec(task="curved", seed=2, user=1, controller="impedance"),
    TrialSpec(task="z", seed=3, user=2, object="board"),
]


@pytest.fixture
def blas_one_thread(monkeypatch):
    # Both runners' worker processes inherit these (the game's gains are bit-identical
    # only for the same BLAS thread count; Ray would otherwise set OMP_NUM_THREADS=1 alone).
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.setenv(name, "1")


@pytest.fixture
def no_ray_running():
    if ray.is_initialized():
        pytest.skip("a Ray instance is already running in this process")
    yield
    ray.shutdown()


def test_ray_runner_gives_the_process_pools_trials(blas_one_thread, no_ray_running):
    pool = run_trials(SPECS, workers=2, progress=False)
    on_ray = run_trials(SPECS, ray_address="local", progress=False)  # starts the local instance itself
    assert ray.is_initialized()
    assert len(on_ray) == len(SPECS)
    for spec, a, b in zip(SPECS, pool, on_ray):
        assert b.meta.seed == spec.seed and b.meta.task == spec.task and b.meta.controller == spec.controller
        assert b.meta.object == spec.object
        assert a.equals(b), f"{spec}: the Ray trial differs from the process pool's"

    # Streaming (collect writes each trial as it lands): every index once, nothing kept.
    delivered = {}
    kept = run_trials(
        SPECS, ray_address="local", progress=False, on_result=lambda i, trial: delivered.setdefault(i, trial)
    )
    assert kept == []
    assert sorted(delivered) == list(range(len(SPECS)))
    for i, trial in delivered.items():
        assert trial.equals(pool[i])
