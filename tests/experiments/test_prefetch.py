"""Simulations started ahead of time (issue 19): ``Workspace.prefetch`` and the ablation's
``AblationAhead`` put a later step's trials on the run's pool early; what they give must be
exactly what the later step would have run itself, and nothing may be left unused."""

from concurrent.futures import Future
from contextlib import nullcontext
from dataclasses import replace

import numpy as np
import pytest

from coassist.experiments import pipeline, reproduce_config
from coassist.experiments.ablation import MG_JOB, OBJECTS, AblationAhead, _mujoco_jobs, mujoco_task
from coassist.experiments.ablation_cells import CALIBRATED, ablation_cells, base_source, mujoco_sources, run_sources
from coassist.experiments.application import handed_to_ablation
from coassist.experiments.source_training import LEARNED, seed_names
from coassist.sim.pool import worker_pool

ARRAYS = ("time", "pose", "velocity", "wrench", "reference", "prediction", "intent", "effort_h", "effort_r", "fault")


class _RecordingPool:
    """An executor that runs nothing: it records what was submitted."""

    def __init__(self):
        self.calls = []

    def submit(self, fn, *args):
        self.calls.append((fn.__name__, args))
        future = Future()
        future.set_result([])
        return future


def _same_trials(a, b):
    assert len(a.trials) == len(b.trials)
    for ta, tb in zip(a.trials, b.trials):
        assert ta.meta.seed == tb.meta.seed
        for name in ARRAYS:
            x, y = getattr(ta, name), getattr(tb, name)
            assert (x is None) == (y is None), name
            if x is not None:
                np.testing.assert_array_equal(x, y, err_msg=name)  # bit for bit: the same jobs


def _named_cells(cfg):
    """The ablation's cells whose source needs no model or calibration, per object."""
    return [(c, s) for c, s in ablation_cells(cfg) if base_source(s) not in LEARNED and s not in CALIBRATED]


def _probes(cfg, suffix=""):
    """The person model's probe datasets: one per calibration draw (draw 0 under the plain name)."""
    return {f"dataset:calibration-probe{suffix}"} | {
        f"dataset:calibration-probe{suffix}-draw{k}" for k in range(1, cfg.calibration_draws)
    }


def _held_out(cfg):
    """What the ablation's first call starts for the held-out population: its operators' calibration trials
    (the person model's, one set per calibration draw) and MG's cells (the calibrated sources' cells wait for
    their fit)."""
    if not cfg.held_out_trials:
        return set()
    return {"dataset:calibration-held-out", *_probes(cfg, "-held-out")} | {
        f"dataset:held-out-{o}-manual" for o in OBJECTS
    }


@pytest.fixture(scope="module")
def shared_pool():
    """Two simulation processes for this module's tests: a pool costs ~8 CPU-s to start (each process
    imports numpy, scipy and torch). A job carries all its inputs, so the same processes again give the same
    trials (tests/sim/test_trial_runner.py); each test still compares against its own reference."""
    with worker_pool(2) as pool:
        yield pool


@pytest.fixture(scope="module")
def loop_model(tmp_path_factory):
    """The tiny preset's network (``Workspace.train``, one epoch from scratch on two curved trials, in this process):
    the model in the loop of this module's collections and the M_prev of its transfer run. Which model it is
    matters to none of them (each compares two paths with the same model); trained once here instead of once in
    each of three tests, each with its own collection (issue 44)."""
    pytest.importorskip("torch")
    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], workers=1, threads=1)
    ws = pipeline.Workspace(cfg, tmp_path_factory.mktemp("loop-model"), progress=False)
    folder, _ = ws.collect("D0", tasks=("curved",), trials=2, seed=1)
    return ws.train("m", [folder], init="scratch", epochs=1)


def test_ahead_starts_exactly_the_cells_the_ablation_collects(tmp_path):
    """Named sources at the first call, each learned one (and each of its trainings) once written;
    never a cell the application hands over; never twice; the MuJoCo jobs are those ``_run_mujoco``
    takes."""
    cfg = replace(
        reproduce_config.REPRODUCE_PRESETS["tiny"], ablation_mujoco_trials=1, source_seeds=2, mujoco_sources=()
    )
    pool = _RecordingPool()
    ws = pipeline.Workspace(cfg, tmp_path, progress=False, pool=pool)
    ahead = AblationAhead(ws, handed_to_ablation())
    models = {n: f"/models/{n}" for s in cfg.learned_sources for n in seed_names(s, cfg.source_seeds)}
    models["paths"] = "/models/paths"
    models["person"] = "/models/person"

    ahead({})
    named = [s for s in run_sources(cfg) if s not in LEARNED and s not in CALIBRATED]
    expect = {f"dataset:ablation-{o}-{c}-{s}" for o in OBJECTS for c, s in _named_cells(cfg)} | _held_out(cfg)
    if ahead.mujoco:
        expect |= {f"job:mujoco:{s}" for s in (MG_JOB, *named)}
    assert set(ws._pending) == expect  # MG's point-mass cells come from the application: not started

    ahead({"lstm-tool": models["lstm-tool"]})
    ahead({"lstm-tool": models["lstm-tool"]})  # again: nothing new
    expect |= {
        f"dataset:ablation-{o}-{c}-lstm-tool" for o in OBJECTS for c, s in ablation_cells(cfg) if s == "lstm-tool"
    }
    if ahead.mujoco:
        expect.add("job:mujoco:lstm-tool")
    assert set(ws._pending) == expect
    ahead({"lstm-tool-s1": models["lstm-tool-s1"]})  # a second training: its arbitrated cell alone
    expect |= {f"dataset:ablation-{o}-cooperative-arbitrated-lstm-tool-s1" for o in OBJECTS}
    assert set(ws._pending) == expect

    ahead(models)
    expect |= {
        f"dataset:ablation-{o}-{c}-{s}"
        for o in OBJECTS
        for c, s in ablation_cells(cfg)
        if (o, c, s) not in handed_to_ablation()
    }
    if ahead.mujoco:
        expect |= {f"job:mujoco:{s}" for s in run_sources(cfg)}
    assert set(ws._pending) == expect
    assert "dataset:ablation-board-cooperative-damped-paths" in expect  # the damped controller's: not the application's
    # each prefetched cell carries its source's model
    (options, groups), _ = ws._pending["dataset:ablation-board-cooperative-arbitrated-ridge"]
    assert options["intent"] == models["ridge"] and options["controller"] == "cooperative-arbitrated"
    assert "dataset:ablation-board-cooperative-ridge" not in ws._pending  # the default leaves fixed-α learned cells out
    assert groups == 1  # a cell is one lockstep group: the pool holds many at once
    if ahead.mujoco:
        intents = {s: models.get(s, s) for s in run_sources(cfg)}
        jobs = _mujoco_jobs(ws, intents)
        drives = [(name, args) for name, args in pool.calls if name in ("_drive_batch", "calibrate_then_drive")]
        order = (MG_JOB, *named, "lstm-tool", *[s for s in run_sources(cfg) if s not in (*named, "lstm-tool")])
        # the cells' configs: _drive_batch's one argument, calibrate_then_drive's third (probes, folder, configs, asked)
        cells = [args[0] if name == "_drive_batch" else args[2] for name, args in drives]
        assert cells == [[c for _, configs in jobs[s] for c in configs] for s in order]
        # the person model's job calibrates on the arm first (its own folder); every other job drives its cells
        assert drives == [(fn.__name__, args) for fn, args in (mujoco_task(ws, s, intents) for s in order)]
        assert [name for name, _ in drives].count("calibrate_then_drive") == 1


@pytest.mark.parametrize("with_model", [False, True])
def test_prefetched_collection_is_the_collection(tmp_path, with_model, shared_pool, request):
    """prefetch + collect writes the same trials, bit for bit, as collect alone (named intent,
    and a model in the loop in lockstep groups); a prefetch under the same name with other
    options is dropped and the collection asked for runs."""
    pytest.importorskip("torch")
    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], workers=2, threads=1)
    intent = str(request.getfixturevalue("loop_model")) if with_model else "nominal"
    # 2 tasks x 2 users x 1 trial: four trials, two to a lockstep group on each of the 2 workers
    options = {"tasks": ("curved", "linear"), "users": (0, 1), "trials": 1, "seed": 7, "intent": intent}
    with nullcontext(shared_pool) as pool:
        _, reference = pipeline.Workspace(cfg, tmp_path / "ref", progress=False, pool=pool).collect("x", **options)
        ws = pipeline.Workspace(cfg, tmp_path / "ahead", progress=False, pool=pool)
        ws.prefetch("x", **options)
        ws.prefetch("y", **{**options, "seed": 99})
        _, ahead = ws.collect("x", **options)
        _, other = ws.collect("y", **options)  # not the prefetched seeds: those are dropped
        assert ws._pending == {}
    _same_trials(reference, ahead)
    _same_trials(reference, other)
    assert [t.meta.seed for t in ahead.trials] == list(range(7, 7 + 4))


def test_prefetch_without_a_pool_does_nothing(tmp_path):
    """Nothing is simulated or submitted: the collection is only deferred (below)."""
    ws = pipeline.Workspace(reproduce_config.REPRODUCE_PRESETS["tiny"], tmp_path, progress=False)
    ws.prefetch("x", tasks=("curved",), trials=1, seed=1)
    assert ws._pending == {} and ws.submit("k", int, "1") is None and ws.take("k") is None
    assert not (tmp_path / "datasets").exists() and list(ws._deferred) == ["x"]


def test_run_deferred_runs_only_the_collections_named(tmp_path, monkeypatch):
    """A stage that times its own collections (the transfer's) runs only those; what other stages deferred stays
    deferred for their own collect; a name not deferred is left to its collect."""
    from coassist.sim import trial_runner

    groups = []
    run = trial_runner.run_spec_lockstep
    monkeypatch.setattr(
        trial_runner, "run_spec_lockstep", lambda specs, *a, **k: groups.append(len(specs)) or run(specs, *a, **k)
    )
    ws = pipeline.Workspace(reproduce_config.REPRODUCE_PRESETS["tiny"], tmp_path, progress=False)
    options = {"tasks": ("curved",), "trials": 1, "controller": "manual"}
    for name, seed in (("x", 1), ("y", 2), ("z", 3)):
        ws.prefetch(name, seed=seed, **options)
    ws.run_deferred(["z", "x", "not-deferred"])
    assert groups == [2] and list(ws._deferred) == ["y"]
    assert sorted(p.name for p in (tmp_path / "datasets").iterdir()) == ["x", "z"]
    assert ws.collect("x", seed=1, **options)[1].trials[0].meta.seed == 1 and groups == [2]  # already written
    assert ws.collect("y", seed=2, **options)[1].trials[0].meta.seed == 2 and groups == [2, 1] and not ws._deferred


def test_collections_deferred_without_a_pool_run_together_and_are_the_collections(tmp_path, monkeypatch, loop_model):
    """Without a pool, the first collect of a prefetched collection runs every deferred one in lockstep groups
    in this process (the same trials, bit for bit, as each collected alone: named intents, MG, a model on
    ONNX Runtime); a group holds at most NAMED_GROUP trials; a model that would run on torch is not deferred
    (its rounding depends on the batch)."""
    pytest.importorskip("torch")
    import coassist.intent.onnx_network as onnx_network
    from coassist.sim import trial_runner

    if not onnx_network.onnx_runtime_available():
        pytest.skip("needs ONNX Runtime (the onnx extra)")
    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], workers=1, threads=1)
    plain = pipeline.Workspace(cfg, tmp_path / "ref", progress=False)
    model = str(loop_model)
    base = {"tasks": ("curved",), "users": (0, 1), "trials": 1, "obstacle": "large"}
    options = {
        "a": {**base, "seed": 7, "controller": "cooperative-arbitrated", "intent": "constant-velocity"},
        "b": {**base, "seed": 7, "controller": "manual"},
        "c": {**base, "seed": 7, "controller": "cooperative-arbitrated", "intent": model},
        "d": {**base, "seed": 30, "users": (0,), "intent": "oracle"},
    }
    reference = {name: plain.collect(name, **o)[1] for name, o in options.items()}
    groups = []
    run = trial_runner.run_spec_lockstep
    monkeypatch.setattr(
        trial_runner, "run_spec_lockstep", lambda specs, *a, **k: groups.append(len(specs)) or run(specs, *a, **k)
    )
    monkeypatch.setattr(trial_runner, "NAMED_GROUP", 6)
    ws = pipeline.Workspace(cfg, tmp_path / "ahead", progress=False)
    for name, o in options.items():
        ws.prefetch(name, **o)
    assert list(ws._deferred) == ["a", "b", "c", "d"] and groups == []
    assert not (tmp_path / "ahead" / "datasets").exists()
    got = {"b": ws.collect("b", **options["b"])[1]}  # runs every deferred one: 2 + 2 + 2 trials, then 1
    assert groups == [6, 1] and ws._deferred == {}
    assert sorted(p.name for p in (tmp_path / "ahead" / "datasets").iterdir()) == ["a", "b", "c", "d"]
    got |= {name: ws.collect(name, **options[name])[1] for name in ("a", "c", "d")}
    assert ws._pending == {} and groups == [6, 1]
    for name in options:
        _same_trials(reference[name], got[name])
    # deferred under a name, then asked for with other options: the one asked for runs, alone
    ws.prefetch("e", **options["a"])
    assert ws.collect("e", **options["d"])[1].trials[0].meta.seed == 30 and ws._deferred == {}
    # where the model would run on torch, its collection is not deferred; the named ones still are
    monkeypatch.setattr(onnx_network, "onnx_runtime_available", lambda: False)
    for name, o in options.items():
        ws.prefetch(name, **o)
    assert list(ws._deferred) == ["a", "b", "d"]


def test_a_deferred_collection_that_fails_raises_in_its_own_collect(tmp_path, monkeypatch):
    """Without a pool, a broken model in one deferred collection does not take the others with it: the one
    asked for is collected (alone), and the broken one raises when it is asked for, as it would alone."""
    import coassist.intent.onnx_network as onnx_network

    monkeypatch.setattr(onnx_network, "onnx_runtime_available", lambda: True)  # deferred, whatever is installed
    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], workers=1, threads=1)
    ws = pipeline.Workspace(cfg, tmp_path, progress=False)
    broken = tmp_path / "broken-model"
    broken.mkdir()
    (broken / "model.json").write_text("{not json")
    options = {"tasks": ("curved",), "trials": 1, "seed": 1}
    ws.prefetch("y", **options, intent=str(broken))
    ws.prefetch("x", **options)
    assert list(ws._deferred) == ["y", "x"]
    _, x = ws.collect("x", **options)
    assert [t.meta.seed for t in x.trials] == [1] and ws._deferred == {}
    with pytest.raises(Exception, match="model.json|JSON|json"):
        ws.collect("y", **options, intent=str(broken))


def test_result_of_waits_for_the_job_or_runs_it_here(tmp_path):
    """``result_of`` gives the submitted job's result without running ``fn`` again; without a
    pool (nothing submitted) it runs ``fn`` in this process."""
    calls = []

    def fn(x):
        calls.append(x)
        return x + 1

    alone = pipeline.Workspace(reproduce_config.REPRODUCE_PRESETS["tiny"], tmp_path, progress=False)
    alone.submit("k", fn, 1)
    assert alone.result_of("k", fn, 1) == 2 and calls == [1]
    pool = _RecordingPool()  # its futures hold []
    ws = pipeline.Workspace(reproduce_config.REPRODUCE_PRESETS["tiny"], tmp_path, progress=False, pool=pool)
    ws.submit("k", fn, 1)
    assert ws.result_of("k", fn, 1) == [] and calls == [1] and ws._pending == {}


@pytest.mark.parametrize("iterations", [4, 2, 1])
def test_beside_training_starts_each_later_share_once_and_all_by_the_last_training(tmp_path, iterations):
    """The iterative stage's ``ahead(k)`` (reproduce._beside_training): the real recordings
    beside M_0, then one share per training; every share exactly once, all of them by the last
    training however few there are; and only cells the application and the ablation collect."""
    from coassist.experiments.application import CONTROLLERS as APP_CONTROLLERS
    from coassist.experiments.reproduce import _beside_training

    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], iterations=iterations, ablation_mujoco_trials=1)
    pool = _RecordingPool()
    ws = pipeline.Workspace(cfg, tmp_path, progress=False, pool=pool)
    ablation_ahead = AblationAhead(ws, handed_to_ablation())
    ahead = _beside_training(ws, "/real", ablation_ahead)
    seen = []
    for k in range(iterations):
        before = set(ws._pending)
        ahead(k)
        seen.append(set(ws._pending) - before)
    assert seen[0] >= {"job:real recordings"}
    if iterations == 4:
        assert seen[0] == {"job:real recordings"}
        assert seen[1] == {
            f"dataset:app-{o}-{c}" for o in OBJECTS for c in APP_CONTROLLERS if not c.startswith("cooperative")
        } | {"dataset:calibration", *_probes(cfg)}
        assert all(seen[k] for k in range(4))
    named = [s for s in run_sources(cfg) if s not in LEARNED and s not in CALIBRATED]
    expect = {"job:real recordings", "dataset:calibration", *_probes(cfg)} | _held_out(cfg)
    expect |= {f"dataset:app-{o}-{c}" for o in OBJECTS for c in APP_CONTROLLERS if not c.startswith("cooperative")}
    expect |= {f"dataset:ablation-{o}-{c}-{s}" for o in OBJECTS for c, s in _named_cells(cfg)}
    if ablation_ahead.mujoco:  # the default's MuJoCo sources: of the named ones, the oracle
        expect |= {f"job:mujoco:{s}" for s in (MG_JOB, *named) if s == MG_JOB or s in mujoco_sources(cfg)}
        assert "job:mujoco:nominal" not in expect and "job:mujoco:oracle" in expect
    assert set().union(*seen) == set(ws._pending) == expect
    n = len(pool.calls)
    ablation_ahead({})  # the application stage's first call: nothing named left to start
    assert len(pool.calls) == n


def test_transfer_on_the_pool_equals_transfer_in_process(tmp_path, monkeypatch, shared_pool, loop_model):
    """run_transfer's jobs on the run's pool (one torch thread each, the longest first, each
    model scored in its worker) give the models and scores of the one-after-the-other path in
    this process on one thread, exactly; the train times are the jobs' own. The datasets are
    collected once, in this process, and the pool's run is handed the same folders (what this
    test compares is the trainings and scorings; prefetched and pooled collections equal
    in-process ones in the tests above and in tests/sim/test_trial_runner.py)."""
    pytest.importorskip("torch")
    import torch

    from coassist.data import read_dataset
    from coassist.experiments.transfer import run_transfer

    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], workers=2, threads=1)
    alone = replace(cfg, workers=1)  # collections in this process: no worker processes to start
    prev = loop_model
    from coassist.experiments.transfer import transfer_targets
    from coassist.sim import trial_runner

    groups = []
    run = trial_runner.run_spec_lockstep
    monkeypatch.setattr(
        trial_runner, "run_spec_lockstep", lambda specs, *a, **k: groups.append(len(specs)) or run(specs, *a, **k)
    )
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        here = run_transfer(pipeline.Workspace(alone, tmp_path / "here", progress=False), prev, 1.0)
    finally:
        torch.set_num_threads(threads)
    # without a pool the targets' six collections ran together, in one lockstep group (the tiny preset's
    # trials are fewer than NAMED_GROUP), and each is the dataset collected alone (tests above)
    targets = transfer_targets(alone)
    n_trials = sum(len(t.users) * len(t.objects) * len(t.tasks) * (t.trials + t.test_trials) for t in targets.values())
    assert groups == [n_trials] and n_trials <= trial_runner.NAMED_GROUP
    monkeypatch.setattr(trial_runner, "run_spec_lockstep", run)

    def collected_here(self, name, **options):
        return tmp_path / "here" / "datasets" / name, read_dataset(tmp_path / "here" / "datasets" / name)

    monkeypatch.setattr(pipeline.Workspace, "collect", collected_here)
    monkeypatch.setattr(pipeline.Workspace, "prefetch", lambda self, name, **options: None)  # nothing to start
    with nullcontext(shared_pool) as pool:
        ws = pipeline.Workspace(cfg, tmp_path / "pool", progress=False, pool=pool)
        on_pool = run_transfer(ws, prev, 1.0)
    assert list(on_pool.targets) == list(here.targets)
    for name, target in on_pool.targets.items():
        assert target.e_rms == here.targets[name].e_rms  # every model and baseline, every horizon, exactly
        assert target.trials == here.targets[name].trials
        assert set(target.train_s) == set(cfg.transfer_starts) and all(s > 0 for s in target.train_s.values())
        for start, path in target.models.items():
            assert path.parent.parent == tmp_path / "pool"
            a = (path / "weights.safetensors").read_bytes()
            b = (here.targets[name].models[start] / "weights.safetensors").read_bytes()
            assert a == b, (name, start)


def test_prefetch_errors_reach_collect(tmp_path, shared_pool):
    """A prefetched collection that fails raises in the collect that asks for it (not lost in
    its thread); the same name prefetched again is a no-op with the same options, refused with others."""
    cfg = replace(reproduce_config.REPRODUCE_PRESETS["tiny"], workers=2)
    with nullcontext(shared_pool) as pool:
        ws = pipeline.Workspace(cfg, tmp_path, progress=False, pool=pool)
        options = {"tasks": ("curved",), "trials": 1, "seed": 1}
        ws.prefetch("x", **options)
        pending = ws._pending["dataset:x"]
        ws.prefetch("x", **options)  # the same trials already on their way: nothing more started
        assert ws._pending["dataset:x"] is pending
        with pytest.raises(ValueError, match="already being prefetched with other options"):
            ws.prefetch("x", **{**options, "seed": 2})
        ws.collect("x", **options)
        broken = tmp_path / "broken-model"
        broken.mkdir()
        (broken / "model.json").write_text("{not json")  # fails in the worker, when the trials load it
        ws.prefetch("y", **options, intent=str(broken))
        with pytest.raises(Exception, match="model.json|JSON|json"):
            ws.collect("y", **options, intent=str(broken))
        assert ws._pending == {}


def test_transfer_collection_shares_are_each_targets_training_ticks_over_all_ticks():
    """Table 5.2's "collect" column: the targets' collections run together, so each target gets the share of
    their time its training trials' ticks are of every tick collected (training and test trials of all)."""
    from types import SimpleNamespace

    from coassist.experiments.transfer import collection_shares

    def dataset(*ticks):
        return SimpleNamespace(trials=[SimpleNamespace(n_samples=n) for n in ticks])

    shares = collection_shares(
        [(dataset(100, 300), dataset(100)), (dataset(200), dataset(50, 50)), (dataset(), dataset(200))]
    )
    assert shares == pytest.approx([400 / 1000, 200 / 1000, 0.0], rel=1e-15)
    assert collection_shares([(dataset(), dataset())]) == [0.0]


@pytest.mark.parametrize(("population", "people"), [("held-out", 0), ("held-out", 5), ("unseen", 0)])
def test_the_held_out_people_are_the_configs_and_only_the_held_out_populations(tmp_path, population, people):
    """``reproduce.held_out_people`` is the held-out population's population seed: every collection of that
    population the ablation starts (its calibrations, every draw's probe trials, MG's cells) draws its operators of
    that seed, and no other population's does; 0 leaves the options as they were (no key: the collections' keys and
    trials unchanged). ``reproduce.held_out_population`` is whose families those collections draw (the cells keep
    their name and seeds), and only a population no setting is chosen on may be named."""
    from coassist.experiments.source_training import calibration_options
    from coassist.scenario.populations import HELD_OUT, population_profile
    from coassist.sim.collect import dataset_specs

    cfg = replace(
        reproduce_config.REPRODUCE_PRESETS["tiny"],
        ablation_mujoco_trials=0,
        mujoco_sources=(),
        held_out_people=people,
        held_out_population=population,
    )
    ws = pipeline.Workspace(cfg, tmp_path, progress=False, pool=_RecordingPool())
    AblationAhead(ws, handed_to_ablation())({})
    held_out = {k for k in ws._pending if "held-out" in k}
    assert held_out == _held_out(cfg)
    for key, ((options, _), _) in ws._pending.items():
        if key in held_out:
            assert options.get("population_seed") == (people or None)
            assert {s.population_seed for s in dataset_specs(**options)} == {people}
            assert options["population"] == population
            assert {s.population for s in dataset_specs(**options)} == {population}
        else:
            assert "population_seed" not in options, key
            assert options.get("population", "thesis") in ("thesis", "varied"), key
    assert "population_seed" not in calibration_options(ws, "manual")  # the thesis population's
    if people:  # other operators than the report's usual three
        first = [population_profile(HELD_OUT, u, 0) for u in cfg.application_users]
        drawn = [population_profile(HELD_OUT, u, people) for u in cfg.application_users]
        assert all(a.stiffness_min != b.stiffness_min for a, b in zip(first, drawn))
    with pytest.raises(ValueError, match=r"reproduce\.held_out_people must be an integer >= 0, got -1"):
        replace(cfg, held_out_people=-1)
    for tuned in ("varied", "thesis", "unseen2"):
        with pytest.raises(ValueError, match=rf"reproduce\.held_out_population must be one of .* got '{tuned}'"):
            replace(cfg, held_out_population=tuned)
