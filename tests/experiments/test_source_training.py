"""The learned intent sources (coassist.experiments.source_training): each trains on one torch
thread in a worker process, so how many train at a time does not change a single weight."""

from __future__ import annotations

from dataclasses import replace

import pytest
from safetensors.numpy import load_file

from coassist.experiments.pipeline import ITERATION_TASKS, Workspace
from coassist.experiments.reproduce_config import REPRODUCE_PRESETS
from coassist.experiments.source_training import seed_names, train_sources


@pytest.fixture(scope="module")
def datasets(tmp_path_factory):
    cfg = REPRODUCE_PRESETS["tiny"]
    out = tmp_path_factory.mktemp("sources")
    # collected in this process (workers=1): the same trials bit for bit as on the preset's pool of two
    # (tests/sim/test_trial_runner.py), without starting the pool's two processes (1.6 CPU-s against 4.5)
    ws = Workspace(replace(cfg, workers=1), out, progress=False)
    folder, _ = ws.collect("D0", tasks=ITERATION_TASKS, trials=cfg.trials_per_task, seed=1)
    return cfg, out, [folder]


def test_sources_train_alike_one_or_two_at_a_time(datasets, tmp_path):
    cfg, out, folders = datasets
    weights = {}
    for processes in (1, 2):
        run = tmp_path / f"p{processes}"
        (run / "datasets").mkdir(parents=True)
        (run / "datasets" / "D0").symlink_to(folders[0])
        ws = Workspace(replace(cfg, workers=2), run, progress=False)
        models = train_sources(ws, [run / "datasets" / "D0"], processes=processes)
        expected = sorted(n for s in cfg.learned_sources for n in seed_names(s, cfg.source_seeds))
        assert list(models) == expected
        weights[processes] = {s: load_file(f"{m}/weights.safetensors") for s, m in models.items()}
    for source in models:
        one, two = weights[1][source], weights[2][source]
        assert one.keys() == two.keys()
        for name in one:
            assert (one[name] == two[name]).all(), (source, name)  # bit for bit: one thread each either way


def test_on_an_accelerator_each_source_trains_here_with_the_arguments_a_worker_gets(tmp_path, monkeypatch):
    """Off the CPU the sources train one after the other in this process (Workspace.train), each with the
    arguments a CPU run hands train_in_worker, and each written model is told as it comes."""
    from coassist.experiments import pipeline

    calls, told = [], []

    def train(self, name, datasets, **options):
        calls.append((name, tuple(datasets), options))
        return tmp_path / "models" / name

    monkeypatch.setattr(pipeline.Workspace, "train", train)
    cfg = replace(REPRODUCE_PRESETS["tiny"], device="cuda", source_seeds=2)
    ws = Workspace(cfg, tmp_path, progress=False)
    models = train_sources(ws, [tmp_path / "D0"], on_models=lambda m: told.append(dict(m)))
    names = [n for source in cfg.learned_sources for n in seed_names(source, cfg.source_seeds)]
    assert [name for name, _, _ in calls] == names and sorted(models) == sorted(names)
    assert told[0] == {} and told[-1] == models and len(told) == len(names) + 1
    for _, datasets, options in calls:
        assert datasets == (tmp_path / "D0",)
        assert options["init"] == "scratch" and options["stride"] == cfg.source_stride
        assert options["fit_stride"] == cfg.source_fit_stride and options["seed"] // 1000 == cfg.seed
    assert len({o["seed"] for _, _, o in calls}) == cfg.source_seeds  # seed·1000 + k, k per training seed
