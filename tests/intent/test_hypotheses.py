"""The network's hypotheses (network.hypotheses > 1): multiple-choice learning of a bimodal future."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from coassist.intent import IntentNet, NetworkConfig, TrainConfig, load_model, save_model, train_model
from coassist.intent.model import IntentModel
from coassist.intent.training import CHOICE_RELAX, choice_loss

#: One window's future either way round: y = ±MODE (the two ways' mirror images).
MODE = torch.tensor([1.0, 0.5, -0.3, 0.8, 0.2, -0.6])


def _windows(n: int, generator: torch.Generator, told: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """n windows (n, 5 steps, 4 features) and their futures: the side is the sign of the last step's first
    feature (``told``) or a fair coin the window does not show."""
    x = torch.randn(n, 5, 4, generator=generator)
    coin = torch.rand(n, generator=generator) > 0.5
    side = torch.where(x[:, -1, 0] > 0 if told else coin, 1.0, -1.0)
    return x, side[:, None] * MODE[None]


def _fit(k: int, told: bool, steps: int = 600) -> IntentNet:
    net = IntentNet(NetworkConfig(4, 6, 1, 16, (16,), hypotheses=k), generator=torch.Generator().manual_seed(1))
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    g = torch.Generator().manual_seed(2)
    net.train()
    for _ in range(steps):
        x, y = _windows(256, g, told)
        h = net.lstm_features(x)
        loss = (
            choice_loss(*net.forward_hypotheses(h, x.flatten(1)), y)
            if k > 1
            else torch.nn.functional.mse_loss(net(x), y)
        )
        opt.zero_grad()
        loss.backward()
        opt.step()
    return net.eval()


def test_two_hypotheses_recover_both_ways_where_one_regresses_to_their_mean():
    """A future that is +MODE or −MODE by a coin the window does not show: one trajectory fitted by MSE
    is their mean (0); two hypotheses are the two ways, each chosen half the time."""
    x, _ = _windows(4000, torch.Generator().manual_seed(3), told=False)
    one_net, two = _fit(1, told=False), _fit(2, told=False)
    with torch.no_grad():
        one = one_net(x)
        ys, logits = two.forward_hypotheses(two.lstm_features(x), x.flatten(1))
    assert one.abs().max() < 0.1  # the mean of the ways, for every window
    means = ys.mean(dim=0)  # (2, 6)
    first = int(torch.argmax(means[:, 0]))
    # The relaxed winner-takes-all pulls each way towards the other by its share of the loser's gradient:
    # the stationary point of the loss is (1 − ε)·MODE + ε·(−MODE) = (1 − 2ε)·MODE; allow 0.1 for the fit.
    expected = (1 - 2 * CHOICE_RELAX) * MODE
    assert torch.allclose(means[first], expected, atol=0.1) and torch.allclose(means[1 - first], -expected, atol=0.1)
    p = torch.softmax(logits, dim=1).mean(dim=0)
    assert torch.allclose(p, torch.full((2,), 0.5), atol=0.05)  # a coin: neither way likelier


def test_the_chooser_follows_the_way_the_window_shows():
    """The side is in the window: the network's output is the way it shows, and its choice is confident."""
    x, y = _windows(4000, torch.Generator().manual_seed(4), told=True)
    net = _fit(2, told=True)
    with torch.no_grad():
        out = net(x)
        _, logits = net.forward_hypotheses(net.lstm_features(x), x.flatten(1))
    err = float(((out - y) ** 2).mean())
    assert err < 0.05 * float((y**2).mean())  # against 1.0 for the mean of the ways (0)
    assert float(torch.softmax(logits, dim=1).max(dim=1).values.median()) > 0.9


def test_the_output_is_the_mixture_at_the_choice_temperature():
    """y = Σ_k softmax(ℓ / T)_k y_k (network docstring), against the formula evaluated by hand."""
    torch.manual_seed(0)
    cfg = NetworkConfig(4, 6, 1, 8, (8,), skip_inputs=20, hypotheses=3, choice_temperature=0.5)
    net = IntentNet(cfg, generator=torch.Generator().manual_seed(5))
    with torch.no_grad():
        net.chooser.weight.normal_(0.0, 1.0)  # logits that differ between windows
    x = torch.randn(7, 5, 4)
    with torch.no_grad():
        out = net(x)
        h = net.lstm_features(x)
        z = net.head[:-1](h)
        ys = net.head[-1](z).reshape(7, 3, 6) + net.skip(x.flatten(1))[:, None, :]
        logits = z @ net.chooser.weight.T + net.chooser.bias
    w = np.exp(logits.numpy() / 0.5)
    w /= w.sum(axis=1, keepdims=True)
    expected = np.einsum("bk,bko->bo", w, ys.numpy())
    # float32 both ways, in other orders: the weights' rounding (a few ε of |ℓ/T| ≲ 10, ε = 1.2e-7) times three
    # hypotheses of O(1) is ~1e-5 at worst; the products' rounding is smaller
    np.testing.assert_allclose(out.numpy(), expected, rtol=0, atol=1e-5)


def test_the_choice_loss_is_the_best_hypothesis_mse_and_the_choosers_cross_entropy():
    ys = torch.tensor([[[0.0, 0.0], [1.0, 1.0]], [[2.0, 0.0], [0.0, 0.0]]])  # (B=2, K=2, O=2)
    y = torch.tensor([[1.0, 1.0], [0.0, 0.0]])  # window 0: hypothesis 1 exact; window 1: hypothesis 1 exact
    logits = torch.tensor([[0.0, 0.0], [1.0, 0.0]])
    eps = CHOICE_RELAX
    # window 0: errors (1, 0), window 1: (2, 0); the best (1) takes 1 − ε, the other ε
    mse = ((eps * 1.0) + (eps * 2.0)) / 2
    ce = (np.log(2.0) + (np.log(np.exp(1.0) + 1.0) - 0.0)) / 2
    assert float(choice_loss(ys, logits, y)) == pytest.approx(mse + ce, rel=1e-6)


def test_the_chooser_reads_detached_features():
    """The chooser's cross-entropy moves the chooser alone: the hypotheses' layers learn from their regression."""
    net = IntentNet(NetworkConfig(4, 6, 1, 8, (8,), hypotheses=2), generator=torch.Generator().manual_seed(6))
    x = torch.randn(9, 5, 4)
    _, logits = net.forward_hypotheses(net.lstm_features(x), x.flatten(1))
    torch.nn.functional.cross_entropy(logits, torch.zeros(9, dtype=torch.long)).backward()
    grads = {n: p.grad for n, p in net.named_parameters()}
    assert grads["chooser.weight"] is not None and float(grads["chooser.weight"].abs().sum()) > 0
    assert all(g is None for n, g in grads.items() if not n.startswith("chooser."))


def test_a_model_with_hypotheses_trains_saves_and_loads_the_same(tmp_path, trials, tiny):
    preset = replace(tiny, hypotheses=2, skip=True)
    a = train_model(trials, preset, preset.train)
    b = train_model(trials, preset, preset.train)
    assert all(torch.equal(v, b.net.state_dict()[k]) for k, v in a.net.state_dict().items())  # same seed, same model
    assert a.net.config.hypotheses == 2 and a.net.chooser is not None
    hist = a.info["training_history"]
    assert all(np.isfinite(r["train_loss"]) and np.isfinite(r["test_loss"]) for r in hist)
    save_model(a, tmp_path / "m")
    loaded = load_model(tmp_path / "m")
    assert loaded.net.config == a.net.config
    x = torch.randn(3, a.window.steps, a.net.config.n_features)
    with torch.no_grad():
        assert torch.equal(loaded.net(x), a.net(x))


def test_a_model_without_the_field_reads_as_one_hypothesis(tmp_path, trials, tiny):
    """Model files from before the field existed: network.hypotheses defaults to 1, the same network."""
    m = train_model(trials, tiny, replace(tiny.train, epochs=1))
    assert m.net.config.hypotheses == 1 and m.net.chooser is None
    assert (
        NetworkConfig(
            **{k: v for k, v in m.net.config.to_dict().items() if k not in ("hypotheses", "choice_temperature")}
        )
        == m.net.config
    )


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"hypotheses": 0}, "network.hypotheses"),
        ({"hypotheses": 2, "lstm_layers": 0, "skip_inputs": 20}, "network.hypotheses"),
        ({"hypotheses": 2, "choice_temperature": 0.0}, "network.choice_temperature"),
        ({"hypotheses": 2, "choice_temperature": float("nan")}, "network.choice_temperature"),
    ],
)
def test_bad_hypotheses_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        NetworkConfig(4, 6, **kwargs)


def test_transfer_of_a_model_with_hypotheses_trains_the_head_and_chooser(tmp_path, trials, tiny):
    preset = replace(tiny, hypotheses=2)
    base = train_model(trials, preset, preset.train)
    save_model(base, tmp_path / "base")
    tl = train_model(trials, preset, TrainConfig(**{**tiny.train.__dict__, "init": f"transfer:{tmp_path / 'base'}"}))
    sb, st = base.net.state_dict(), tl.net.state_dict()
    assert all(torch.equal(sb[k], st[k]) for k in sb if k.startswith("lstm."))
    assert not torch.equal(sb["chooser.weight"], st["chooser.weight"])
    assert not torch.equal(sb["head.2.weight"], st["head.2.weight"])


def test_an_intent_model_with_hypotheses_predicts_positions(trials, tiny):
    """The model around the network (scaling, decoding) is unchanged: predict gives (H, d) positions."""
    preset = replace(tiny, hypotheses=2)
    m: IntentModel = train_model(trials, preset, replace(tiny.train, epochs=1))
    out = m.predict_trial(trials[0].trial)
    assert out.shape[1:] == (m.horizon, 2) and np.isfinite(out[m.history :]).all()
