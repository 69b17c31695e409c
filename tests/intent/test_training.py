"""Training: determinism, freezing for transfer, resume, gradients, configuration."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coassist.intent import IntentNet, NetworkConfig, TrainConfig, save_model, train_model
from coassist.intent.features import Scaler

from .conftest import labeled


def _state(model):
    return {k: v.clone() for k, v in model.net.state_dict().items()}


def test_same_seed_gives_bit_identical_weights(trials, tiny):
    a = train_model(trials, tiny, tiny.train)
    b = train_model(trials, tiny, tiny.train)
    sa, sb = _state(a), _state(b)
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert a.info["training_history"] == [
        {**r, "seconds": s["seconds"]} for r, s in zip(b.info["training_history"], a.info["training_history"])
    ]
    c = train_model(trials, tiny, TrainConfig(**{**tiny.train.__dict__, "seed": 1}))
    assert not torch.equal(_state(c)["lstm.weight_ih_l0"], sa["lstm.weight_ih_l0"])


def test_training_reduces_the_loss(trials, tiny):
    cfg = TrainConfig(**{**tiny.train.__dict__, "epochs": 4})
    m = train_model(trials, tiny, cfg)
    h = m.info["training_history"]
    assert h[-1]["train_loss"] < h[0]["train_loss"]
    assert abs(h[-1]["lr"] - cfg.lr * cfg.lr_final_ratio) < 1e-12  # geometric decay to the final ratio


def test_transfer_freezes_the_lstm_bit_for_bit(tmp_path, trials, tiny):
    base = train_model(trials, tiny, tiny.train)
    save_model(base, tmp_path / "base")
    new_user = labeled(3, prefix="U", first_seed=100)
    tl = train_model(new_user, tiny, TrainConfig(**{**tiny.train.__dict__, "init": f"transfer:{tmp_path / 'base'}"}))
    sb, st = _state(base), _state(tl)
    lstm = [k for k in sb if k.startswith("lstm.")]
    head = [k for k in sb if not k.startswith("lstm.")]
    assert lstm and all(torch.equal(sb[k], st[k]) for k in lstm)
    assert any(not torch.equal(sb[k], st[k]) for k in head)
    assert tl.info["frozen"] == ["lstm"] and tl.info["parent"]["dataset_ids"] == ["T"]
    # Its scaling is the base model's, not refitted on the new data.
    assert np.array_equal(tl.input_scaler.lo, base.input_scaler.lo)
    # Fine-tuning everything does move the LSTM.
    ft = train_model(new_user, tiny, TrainConfig(**{**tiny.train.__dict__, "init": f"finetune:{tmp_path / 'base'}"}))
    assert not torch.equal(_state(ft)["lstm.weight_hh_l0"], sb["lstm.weight_hh_l0"])


def test_transfer_refits_a_frozen_skip_to_the_new_datas_ridge(tmp_path, trials, tiny):
    """freeze_skip: the residual is over the ridge of the data trained on. In transfer the skip
    is the ridge fitted on the new trials in the source's scalers (recomputed here), not the
    source's ridge, which extrapolates on a new user."""
    from dataclasses import replace

    from coassist.intent import RidgeBaseline
    from coassist.intent.features import WindowSet, split_trials

    preset = replace(tiny, skip=True, train=replace(tiny.train, freeze_skip=True, skip_alpha=0.5))
    base = train_model(trials, preset, preset.train)
    save_model(base, tmp_path / "base")
    new_user = labeled(4, prefix="U", first_seed=100)
    cfg = replace(preset.train, init=f"transfer:{tmp_path / 'base'}")
    tl = train_model(new_user, preset, cfg)
    train_idx, _ = split_trials([t.id for t in new_user], cfg.test_fraction, cfg.seed)
    ws = WindowSet([new_user[i].trial for i in train_idx], base.window, base.dt)
    ridge = RidgeBaseline.fit(ws, base.input_scaler, base.target_scaler, 0.5)
    np.testing.assert_allclose(tl.net.skip.weight.detach().numpy(), ridge.W.T, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(tl.net.skip.bias.detach().numpy(), ridge.b, rtol=1e-5, atol=1e-6)
    assert not torch.equal(tl.net.skip.weight, base.net.skip.weight)


def test_resume_continues_the_history(tmp_path, trials, tiny):
    base = train_model(trials, tiny, tiny.train)
    save_model(base, tmp_path / "m0")
    m1 = train_model(trials, tiny, TrainConfig(**{**tiny.train.__dict__, "init": f"resume:{tmp_path / 'm0'}"}))
    assert [r["epoch"] for r in m1.info["training_history"]] == [1, 2, 3, 4]


def test_loss_gradient_matches_finite_differences():
    torch.manual_seed(0)
    net = IntentNet(NetworkConfig(n_features=4, n_outputs=6, lstm_layers=2, hidden=5, fc=(7,), skip_inputs=12)).double()
    x, y = torch.randn(3, 3, 4, dtype=torch.float64), torch.randn(3, 6, dtype=torch.float64)
    params = list(net.parameters())

    def loss_of(*flat):
        with torch.no_grad():
            for p, v in zip(params, flat):
                p.copy_(v)
        return torch.nn.functional.mse_loss(net(x), y)

    loss = torch.nn.functional.mse_loss(net(x), y)
    grads = torch.autograd.grad(loss, params)
    rng = np.random.default_rng(0)
    eps = 1e-6
    for p, g in zip(params, grads):
        for _ in range(3):
            idx = tuple(int(rng.integers(0, s)) for s in p.shape)
            with torch.no_grad():
                orig = p[idx].item()
                p[idx] = orig + eps
                up = torch.nn.functional.mse_loss(net(x), y).item()
                p[idx] = orig - eps
                down = torch.nn.functional.mse_loss(net(x), y).item()
                p[idx] = orig
            assert (up - down) / (2 * eps) == pytest.approx(g[idx].item(), rel=1e-5, abs=1e-8)


def test_xavier_init_and_zero_biases():
    torch.manual_seed(0)
    net = IntentNet(NetworkConfig(n_features=8, n_outputs=100, lstm_layers=3, hidden=250, fc=(200,)))
    w = net.lstm.weight_hh_l0.detach()
    bound = np.sqrt(6.0 / (w.shape[0] + w.shape[1]))
    assert float(w.abs().max()) <= bound and float(w.abs().max()) > 0.9 * bound
    assert all(float(p.detach().abs().max()) == 0.0 for n, p in net.named_parameters() if "bias" in n)


def test_initial_weights_come_from_the_given_generator_only():
    cfg = NetworkConfig(n_features=4, n_outputs=6, lstm_layers=2, hidden=5, fc=(7,), skip_inputs=12)
    global_state = torch.get_rng_state()
    a, b, c = (IntentNet(cfg, generator=torch.Generator().manual_seed(s)) for s in (3, 3, 4))
    assert torch.equal(torch.get_rng_state(), global_state)  # building a network draws nothing from it
    sa, sb, sc = a.state_dict(), b.state_dict(), c.state_dict()
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert not torch.equal(sa["lstm.weight_ih_l0"], sc["lstm.weight_ih_l0"])


def test_training_leaves_torch_global_state_alone(trials, tiny):
    threads = torch.get_num_threads()
    cfg = TrainConfig(**{**tiny.train.__dict__, "threads": threads + 1})
    torch.manual_seed(123)
    global_state = torch.get_rng_state()
    train_model(trials, tiny, cfg)
    assert torch.get_num_threads() == threads  # the thread count is the CLI's to set
    assert torch.equal(torch.get_rng_state(), global_state)


def test_thesis_preset_is_the_thesis_network():
    from coassist.intent import MODEL_PRESETS

    p = MODEL_PRESETS["thesis"]
    net = IntentNet(p.network(2))
    assert (net.lstm.num_layers, net.lstm.hidden_size) == (3, 250)
    linears = [m for m in net.head if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(250, 200), (200, 100)]
    assert isinstance(net.head[1], torch.nn.SiLU) and net.skip is None
    assert (p.window.history, p.window.decimation, p.window.horizon) == (125, 1, 50)
    t = p.train
    assert (t.epochs, t.batch_size, t.lr, t.lr_final_ratio, t.optimizer) == (25, 64, 1e-3, 0.05, "adam")


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"epochs": 0}, "train.epochs"),
        ({"lr": -1.0}, "train.lr"),
        ({"optimizer": "lbfgs"}, "train.optimizer"),
        ({"init": "transfer:"}, "train.init"),
        ({"init": "warm:x"}, "train.init"),
        ({"test_fraction": 1.0}, "train.test_fraction"),
    ],
)
def test_train_config_errors_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        TrainConfig(**kwargs)


def test_missing_start_model_is_a_clear_error(trials, tiny, tmp_path):
    from coassist.intent import ModelFileError

    with pytest.raises(ModelFileError, match="model.json"):
        train_model(trials, tiny, TrainConfig(**{**tiny.train.__dict__, "init": f"resume:{tmp_path / 'nope'}"}))


def test_preset_with_skip_starts_as_the_ridge_predictor(trials, tiny):
    from dataclasses import replace

    from coassist.intent.training import build_model

    p = replace(tiny, skip=True)
    m = build_model(p, trials, p.train)
    assert float(m.net.head[-1].weight.detach().abs().max()) == 0.0
    ridge_train = train_model(trials, p, TrainConfig(**{**p.train.__dict__, "epochs": 1}))  # fits the ridge baseline
    t = trials[0].trial
    a, b = m.predict_trial(t), ridge_train.ridge.predict_trial(t)
    ok = np.isfinite(a[:, 0, 0])
    assert ok.sum() > 100 and np.allclose(
        a[ok], b[ok], atol=1e-4
    )  # float32 network vs float64 ridge (positions ~0.1 m)


def test_linear_preset_starts_as_the_ridge_predictor(trials, tiny):
    """build_model fits a linear preset's skip too (train_model alone defers it to its closed form)."""
    from dataclasses import replace

    from coassist.intent import RidgeBaseline, WindowSet, split_trials
    from coassist.intent.training import build_model

    p = replace(tiny, lstm_layers=0, hidden=1, fc=(), skip=True, train=replace(tiny.train, ridge_alpha=1.0))
    m = build_model(p, trials, p.train)
    assert m.net.is_linear
    train_idx, _ = split_trials([lt.id for lt in trials], p.train.test_fraction, p.train.seed)
    ws = WindowSet([trials[i].trial for i in train_idx], p.window, m.dt)
    ridge = RidgeBaseline.fit(ws, m.input_scaler, m.target_scaler, 1.0)
    np.testing.assert_allclose(m.net.skip.weight.detach().numpy(), ridge.W.T, rtol=1e-5, atol=1e-6)


def test_skip_alpha_shrinks_the_skip_and_leaves_the_baseline_alone(trials, tiny):
    """skip_alpha sets the ridge the skip starts from; ridge_alpha alone sets the baseline."""
    from dataclasses import replace

    from coassist.intent import RidgeBaseline, WindowSet, split_trials
    from coassist.intent.training import build_model

    p = replace(tiny, skip=True, train=replace(tiny.train, skip_alpha=100.0, ridge_alpha=1.0, epochs=1))
    m = build_model(p, trials, p.train)
    train_idx, _ = split_trials([lt.id for lt in trials], p.train.test_fraction, p.train.seed)
    ws = WindowSet([trials[i].trial for i in train_idx], p.window, m.dt)
    strong = RidgeBaseline.fit(ws, m.input_scaler, m.target_scaler, 100.0)
    weak = RidgeBaseline.fit(ws, m.input_scaler, m.target_scaler, 1.0)
    skip = m.net.skip.weight.detach().numpy().T
    np.testing.assert_allclose(skip, strong.W, rtol=1e-5, atol=1e-6)
    assert np.abs(skip - weak.W).max() > 1e-3
    trained = train_model(trials, p, p.train)  # its baseline is fitted on the strided training windows
    ws_strided = WindowSet([trials[i].trial for i in train_idx], p.window, m.dt, stride=p.train.train_stride)
    baseline = RidgeBaseline.fit(ws_strided, m.input_scaler, m.target_scaler, 1.0)
    np.testing.assert_allclose(trained.ridge.W, baseline.W, rtol=1e-10, atol=1e-12)


def test_fit_stride_fits_the_scalers_and_the_skip_on_every_nth_window(tmp_path, trials, tiny):
    """fit_stride = 3: the scalers are the ranges of every 3rd training window and the skip is the ridge on
    them (recomputed here), in a fresh model and in a transfer's refitted skip; 1 is every window."""
    from dataclasses import replace

    from coassist.intent import RidgeBaseline, WindowSet, split_trials
    from coassist.intent.training import build_model

    p = replace(tiny, skip=True, train=replace(tiny.train, skip_alpha=0.5, freeze_skip=True))
    train_idx, _ = split_trials([lt.id for lt in trials], p.train.test_fraction, p.train.seed)
    every = build_model(p, trials, p.train)
    third = build_model(p, trials, replace(p.train, fit_stride=3))
    ws = WindowSet([trials[i].trial for i in train_idx], p.window, every.dt, stride=3)
    lo_hi = ws.fit_scalers()
    for got, want in zip((third.input_scaler, third.target_scaler), lo_hi):
        assert np.array_equal(got.lo, want.lo) and np.array_equal(got.hi, want.hi)
    ridge = RidgeBaseline.fit(ws, *lo_hi, 0.5)
    np.testing.assert_allclose(third.net.skip.weight.detach().numpy(), ridge.W.T, rtol=1e-5, atol=1e-6)
    assert np.abs(third.net.skip.weight.detach().numpy() - every.net.skip.weight.detach().numpy()).max() > 1e-4
    # a transfer's skip is refitted on the new trials' every 3rd window, in the source's scalers
    save_model(every, tmp_path / "base")
    new_user = labeled(4, prefix="U", first_seed=100)
    cfg = replace(p.train, init=f"transfer:{tmp_path / 'base'}", fit_stride=3, epochs=1)
    tl = train_model(new_user, p, cfg)
    idx, _ = split_trials([t.id for t in new_user], cfg.test_fraction, cfg.seed)
    ws = WindowSet([new_user[i].trial for i in idx], every.window, every.dt, stride=3)
    ridge = RidgeBaseline.fit(ws, every.input_scaler, every.target_scaler, 0.5)
    np.testing.assert_allclose(tl.net.skip.weight.detach().numpy(), ridge.W.T, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="train.fit_stride must be an integer >= 1"):
        TrainConfig(fit_stride=0)


def test_the_ridge_alpha_search_runs_once_per_training(monkeypatch, trials, tiny):
    """The skip's α and the baselines' α come from the same search on the same trials: it runs
    once, and both use its answer."""
    from dataclasses import replace

    from coassist.intent import baselines, training

    calls = []
    real = baselines.tune_ridge_alpha

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(training, "tune_ridge_alpha", counting)
    monkeypatch.setattr(baselines, "tune_ridge_alpha", counting)
    preset = replace(tiny, skip=True, train=replace(tiny.train, freeze_skip=True))
    m = train_model(trials, preset, preset.train)
    assert len(calls) == 1
    ridge = m.info["baselines"]["ridge"]
    assert ridge["tuned"] and ridge["alpha"] == ridge["alphas"][int(np.argmin(ridge["validation_mse"]))]


def test_a_bigger_batch_scales_the_learning_rate_by_the_square_root_rule():
    from coassist.intent.presets import with_batch_size

    base = TrainConfig(batch_size=64, lr=3e-3)
    big = with_batch_size(base, 256)
    assert big.batch_size == 256 and big.lr == pytest.approx(6e-3, rel=1e-15)  # 3e-3 · √4
    assert with_batch_size(base, 16).lr == pytest.approx(1.5e-3, rel=1e-15)
    assert {k: v for k, v in big.__dict__.items() if k not in ("batch_size", "lr")} == {
        k: v for k, v in base.__dict__.items() if k not in ("batch_size", "lr")
    }
    with pytest.raises(ValueError, match="train.batch_size"):
        with_batch_size(base, 0)


def test_a_model_whose_window_cannot_be_mirrored_transfers_and_says_how_to_finetune(tmp_path, trials, tiny):
    """A source with an absolute window (the thesis'), started from with a mirroring configuration (the CLI's
    default preset): transfer never mirrors, so it trains; once it was refused for train.mirror, which the CLI
    has no option for. Finetune would mirror: refused, saying what to pass."""
    from dataclasses import replace

    absolute = replace(tiny, window=replace(tiny.window, input_frame="absolute", target="absolute"))
    save_model(train_model(trials, absolute, replace(tiny.train, epochs=1)), tmp_path / "src")
    mirroring = replace(tiny.train, epochs=1, mirror=True)
    tl = train_model(
        labeled(3, prefix="U", first_seed=100), tiny, replace(mirroring, init=f"transfer:{tmp_path / 'src'}")
    )
    assert tl.info["frozen"] == ["lstm"] and tl.info["mirrored"] is False
    assert tl.window.input_frame == "absolute"
    with pytest.raises(ValueError) as err:
        train_model(
            labeled(3, prefix="U", first_seed=100), tiny, replace(mirroring, init=f"finetune:{tmp_path / 'src'}")
        )
    assert str(err.value) == (
        f"{tmp_path / 'src'}: its window (input_frame 'absolute', target 'absolute') cannot be mirrored, which "
        "train.mirror (on in this configuration) asks; finetune: it with train.mirror off (--preset thesis does "
        "not mirror)"
    )
    ft = train_model(
        labeled(3, prefix="U", first_seed=100),
        tiny,
        replace(mirroring, mirror=False, init=f"finetune:{tmp_path / 'src'}"),
    )
    assert ft.info["mirrored"] is False and ft.info["frozen"] == []
    with pytest.raises(ValueError, match=r"^train.mirror needs window.input_frame='relative'"):  # from scratch
        train_model(trials, absolute, mirroring)


def test_a_diverged_training_stops_naming_the_epoch_and_writes_nothing(tmp_path, trials, tiny):
    """lr 1e30: once "Out of range float values are not JSON compliant: inf" from writing the checkpoint."""
    from dataclasses import replace

    from coassist._io import partial_folder

    cfg = replace(tiny.train, epochs=3, lr=1e30, optimizer="sgd")
    with pytest.raises(ValueError) as err:
        train_model(trials, tiny, cfg, checkpoint_to=tmp_path / "m")
    msg = str(err.value)
    assert msg.startswith("training diverged at epoch 1 (") and msg.endswith("); lower train.lr"), msg
    assert msg.split("(")[1].split(")")[0] in {f"{k} loss {v}" for k in ("train", "test") for v in ("inf", "nan")}
    assert not (tmp_path / "m").exists() and not partial_folder(tmp_path / "m").exists()


def test_a_test_split_too_short_to_window_is_named(trials, tiny):
    """Once "no trial is long enough …" although the training trials were: the held-out one is the short one."""
    from dataclasses import replace

    from coassist.intent import LabeledTrial
    from coassist.intent.features import split_trials

    from .conftest import make_trial

    _, (short,) = split_trials([t.id for t in trials], tiny.train.test_fraction, tiny.train.seed)
    trials[short] = LabeledTrial(trials[short].id, trials[short].dataset, make_trial(short, n=25))
    with pytest.raises(ValueError) as err:
        train_model(trials, tiny, replace(tiny.train, epochs=1))
    assert str(err.value).startswith(
        f"the test split (1 trial: {trials[short].id}): no trial is long enough for history 20 + horizon 10 samples"
    )


def test_window_errors_name_the_trials(tiny):
    """A validation split or an evaluation of one short trial, and a trial of other DOFs among the rest, said "no
    trial is long enough …" and "all trials must have the same number of DOFs" naming none (review, 2026-12-06)."""
    from coassist.intent.features import WindowSet

    from .conftest import make_trial

    short = make_trial(3, n=25)
    with pytest.raises(ValueError) as err:
        WindowSet([short], tiny.window, 0.008)
    assert str(err.value).endswith(f"(1 given: user-t's seed {short.meta.seed} (25 samples))"), str(err.value)
    with pytest.raises(ValueError) as err:
        WindowSet([make_trial(1), make_trial(2, d=3)], tiny.window, 0.008)
    assert "all trials must have the same number of DOFs: user-t's seed" in str(err.value)
    assert "(260 samples) has 3, user-t's" in str(err.value) and str(err.value).endswith(" 2")


def test_trials_a_starting_model_trained_on_stay_on_the_training_side(tmp_path, trials, tiny):
    """finetune:/resume: with another seed or more data: the new split would hold out trials the parent trained
    on. They go to the training side; with none of them among the trials, the split is split_trials' own."""
    from dataclasses import replace

    from coassist.intent.features import split_trials

    cfg = replace(tiny.train, epochs=1)
    parent = train_model(trials, tiny, cfg)
    save_model(parent, tmp_path / "p")
    ids = [t.id for t in trials]
    plain_train, plain_test = split_trials(ids, cfg.test_fraction, 3)
    assert [ids[i] for i in plain_test] == ["T/trial_04"]  # seed 3 would hold out a trial the parent trained on
    assert parent.info["test_trials"] == ["T/trial_02"] and "T/trial_04" in parent.info["train_trials"]
    ft = train_model(trials, tiny, replace(cfg, seed=3, init=f"finetune:{tmp_path / 'p'}"))
    assert ft.info["test_trials"] == [] and ft.info["train_trials"] == ids and ft.info["n_test_windows"] == 0
    more = trials + labeled(5, prefix="U", first_seed=100)  # other trials
    stage = train_model(more, tiny, replace(cfg, init=f"resume:{tmp_path / 'p'}"))
    _, test = split_trials([t.id for t in more], cfg.test_fraction, 0)
    assert [more[i].id for i in test] == ["T/trial_04", "U/trial_01"]  # T/trial_04: the parent's training trial
    assert stage.info["test_trials"] == ["U/trial_01"]
    assert set(parent.info["train_trials"]) <= set(stage.info["train_trials"])
    # a starting model that never saw these trials: the split as split_trials makes it
    tl = train_model(labeled(5, prefix="V", first_seed=200), tiny, replace(cfg, init=f"transfer:{tmp_path / 'p'}"))
    _, test = split_trials([f"V/trial_{i:02d}" for i in range(5)], cfg.test_fraction, 0)
    assert tl.info["test_trials"] == [f"V/trial_{i:02d}" for i in test]


def test_a_grandparents_training_trials_stay_on_the_training_side(tmp_path, trials, tiny):
    """A model records its starting model's training trials, but the record stopped there: from the third generation
    on, the first model's training trials were held out and scored as new (review, 2026-12-06)."""
    from dataclasses import replace

    from coassist.intent.model import lineage_train_trials

    cfg = replace(tiny.train, epochs=1)
    first = train_model(trials, tiny, cfg)
    save_model(first, tmp_path / "a")
    second = train_model(labeled(5, prefix="U", first_seed=100), tiny, replace(cfg, init=f"resume:{tmp_path / 'a'}"))
    save_model(second, tmp_path / "b")
    third = train_model(labeled(5, prefix="V", first_seed=200), tiny, replace(cfg, init=f"resume:{tmp_path / 'b'}"))
    # what evaluate leaves out of the third model's score, and what a fourth generation keeps on the training side
    assert set(first.info["train_trials"]) <= lineage_train_trials(third.info)
    save_model(third, tmp_path / "c")
    fourth = train_model(trials, tiny, replace(cfg, seed=3, init=f"resume:{tmp_path / 'c'}"))
    assert not set(first.info["train_trials"]) & set(fourth.info["test_trials"])  # seed 3 would hold out T/trial_04


def test_a_copy_of_a_training_trial_among_the_trials_is_not_held_out(trials, tiny):
    """A dataset appended to twice holds each trial twice under two names: a test trial's copy trained, so the test
    loss was a training loss (review, 2026-12-06). Copies go to the training side with their original; trials with
    no copy are split as before."""
    from dataclasses import replace

    from coassist.intent.features import split_trials

    cfg = replace(tiny.train, epochs=1)
    doubled = trials + labeled(5, prefix="C")  # the same five trials again, other names
    ids = [t.id for t in doubled]
    train, test = split_trials(ids, cfg.test_fraction, 0)
    held = [ids[i] for i in test]
    twins = {f"T/{name.split('/')[1]}" if name.startswith("C/") else f"C/{name.split('/')[1]}" for name in held}
    assert twins & {ids[i] for i in train}, "the plain split must put some test trial's copy in training"
    model = train_model(doubled, tiny, cfg)
    kept = model.info["test_trials"]
    assert set(kept) <= set(held)
    for name in kept:  # no held-out trial has a copy among the training trials
        twin = ("C/" if name.startswith("T/") else "T/") + name.split("/")[1]
        assert twin not in model.info["train_trials"]
    plain = train_model(trials, tiny, cfg)  # no copies: the split as split_trials makes it
    assert plain.info["test_trials"] == [
        trials[i].id for i in split_trials([t.id for t in trials], cfg.test_fraction, 0)[1]
    ]


def test_the_ridge_tuning_says_its_split_had_no_window():
    """With one trial long enough of two, the α tuning's part without it raised "no trial is long enough", read as of
    every trial given (a review, 2026-12-07): it says it is the tuning's split."""
    from coassist.intent.baselines import tune_ridge_alpha

    from .conftest import TINY

    trials = labeled(1, n=260) + labeled(1, n=25, prefix="S", first_seed=9)
    big = np.full(64, 10.0)
    scaler = Scaler(-big, big)
    with pytest.raises(ValueError, match=r"^the ridge's α is tuned on a split of the 2 training trials \(1 to fit, 1 "):
        tune_ridge_alpha([t.trial for t in trials], [t.id for t in trials], TINY.window, 0.008, scaler, scaler, seed=0)
