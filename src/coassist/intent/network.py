"""The RNN+FC intent network (thesis §4.1, Fig. 4.2, §5.2.2).

An LSTM reads the window (B, steps, features); its last hidden state goes through
fully connected layers to the H·d outputs (the predicted trajectory in the chosen
target parameterisation, scaled to [−1, 1]). The thesis network is
LSTM 3 × 250 → FC 250 → 200 → 2·50 with SiLU between FC layers, Xavier init.

With ``lstm_layers = 0`` the network is its linear skip alone, y = W x + b on the
flattened window: the ridge predictor in the same model format (training fits it in
closed form, ``training.train_model``).

With ``hypotheses = K > 1`` the last FC layer gives K trajectories y_k (each plus the
skip) and a chooser (one linear layer on the last FC layer's input, which its loss does
not train) their logits ℓ_k. Where the person may go round an obstacle either way, one
trajectory fitted by MSE is the mean of the two ways, near the plan; K hypotheses are
meant to keep the ways apart (multiple-choice learning: the loss is the best hypothesis'
MSE, ``training.choice_loss``). On the project's simulated data they did not: the two
split the futures' spread, not the way round, and in the loop did no better than one
(docs/intent-hypotheses.md). The network's output is

    y = Σ_k softmax(ℓ / T)_k y_k,    T = ``choice_temperature``,

the likeliest hypothesis as T → 0, the mixture's mean at T = 1; continuous in the inputs
for every T > 0, so the rows do not jump when the likeliest way changes.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import nn

from coassist._checks import check_int, is_real_number

__all__ = ["ACTIVATIONS", "MAX_PARAMETERS", "IntentNet", "NetworkConfig"]

ACTIVATIONS = {"silu": nn.SiLU, "relu": nn.ReLU, "tanh": nn.Tanh}
#: The most parameters a network may have (400 MB of float32 weights, three times that to train with Adam): a size
#: typed by mistake (--hidden 100000000, --layers 100000) is refused in one line, not allocated or built for hours.
MAX_PARAMETERS = 100_000_000


@dataclass(frozen=True)
class NetworkConfig:
    """Sizes of the network.

    n_features : inputs per step (4·d).  n_outputs : H·d.
    lstm_layers, hidden : the LSTM; 0 layers: no LSTM and no FC layers, only the linear skip.  fc : widths of the hidden FC layers after the LSTM
    (thesis: (200,), i.e. two FC layers 250 → 200 → 100).  activation : between FC layers.
    skip_inputs : 0 (the thesis) or steps·n_features: adds a linear map from the flattened
    window straight to the outputs, so the LSTM+FC learns a correction on top of a linear
    predictor (initialised with the ridge solution; see ``training.build_model``).
    hypotheses : K trajectories and a chooser (module docstring); 1 (the thesis): one.
    choice_temperature : T of the module docstring (K > 1 only), > 0.
    """

    n_features: int
    n_outputs: int
    lstm_layers: int = 3
    hidden: int = 250
    fc: tuple[int, ...] = (200,)
    activation: str = "silu"
    skip_inputs: int = 0
    hypotheses: int = 1
    choice_temperature: float = 0.25

    def __post_init__(self) -> None:
        object.__setattr__(self, "n_features", check_int(self.n_features, "network.n_features", 1))
        object.__setattr__(self, "n_outputs", check_int(self.n_outputs, "network.n_outputs", 1))
        object.__setattr__(self, "lstm_layers", check_int(self.lstm_layers, "network.lstm_layers", 0))
        object.__setattr__(self, "hidden", check_int(self.hidden, "network.hidden", 1))
        fc = tuple(self.fc) if isinstance(self.fc, (list, tuple)) else self.fc
        if not isinstance(fc, tuple):
            raise ValueError(f"network.fc must be a list of layer widths, got {self.fc!r}")
        fc = tuple(check_int(w, f"network.fc[{i}]", 1) for i, w in enumerate(fc))
        object.__setattr__(self, "fc", fc)
        object.__setattr__(self, "skip_inputs", check_int(self.skip_inputs, "network.skip_inputs", 0))
        if self.skip_inputs and self.skip_inputs % self.n_features:
            raise ValueError(f"network.skip_inputs must be steps·n_features, got {self.skip_inputs}")
        if self.lstm_layers == 0 and not self.skip_inputs:
            raise ValueError(
                "network.lstm_layers = 0 (a linear predictor) needs the linear skip (network.skip_inputs > 0)"
            )
        object.__setattr__(self, "hypotheses", check_int(self.hypotheses, "network.hypotheses", 1))
        if self.hypotheses > 1 and not self.lstm_layers:
            raise ValueError("network.hypotheses > 1 needs the LSTM (network.lstm_layers >= 1)")
        t = self.choice_temperature
        if not is_real_number(t) or not math.isfinite(t) or t <= 0:
            raise ValueError(f"network.choice_temperature must be a number > 0, got {t!r}")
        object.__setattr__(self, "choice_temperature", float(t))
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"network.activation must be one of {sorted(ACTIVATIONS)}, got {self.activation!r}")
        if self.n_parameters > MAX_PARAMETERS:  # counted from the sizes: refused before anything is allocated
            raise ValueError(
                f"network: {self.n_parameters:,} parameters (lstm_layers {self.lstm_layers}, hidden {self.hidden}, "
                f"fc {list(self.fc)}, hypotheses {self.hypotheses}) is more than the {MAX_PARAMETERS:,} a model may "
                "have (the thesis' network has 1.3 million)"
            )

    @property
    def n_parameters(self) -> int:
        """Parameters of ``IntentNet(self)``, from its sizes alone (nothing allocated).

        LSTM layer l: 4h (in_l + h) weights + 8h biases (in_0 = n_features, else h); each
        linear layer a → b: a b + b (the last one's b is hypotheses · n_outputs, and with hypotheses the
        chooser is one more, from the last one's input to hypotheses); the skip: skip_inputs · n_outputs + n_outputs.
        """
        n, h = 0, self.hidden
        if self.lstm_layers:
            for layer in range(self.lstm_layers):
                n += 4 * h * ((self.n_features if layer == 0 else h) + h) + 8 * h
            widths = (h, *self.fc, self.hypotheses * self.n_outputs)
            n += sum(a * b + b for a, b in zip(widths[:-1], widths[1:]))
            if self.hypotheses > 1:  # the chooser
                n += widths[-2] * self.hypotheses + self.hypotheses
        if self.skip_inputs:
            n += self.skip_inputs * self.n_outputs + self.n_outputs
        return n

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["fc"] = list(self.fc)
        return out


class IntentNet(nn.Module):
    """LSTM then FC: (B, steps, n_features) -> (B, n_outputs).

    ``generator`` draws the initial weights (:meth:`reset_parameters`); ``None`` uses
    torch's global generator (fine when the weights are loaded afterwards).
    """

    def __init__(self, config: NetworkConfig, generator: torch.Generator | None = None) -> None:
        super().__init__()
        self.config = config
        self.lstm: nn.LSTM | None = None
        self.head: nn.Sequential | None = None
        self.chooser: nn.Linear | None = None
        # The layers' own default initialisation draws from torch's global generator and is
        # overwritten below: restore that generator so building a network leaves it alone.
        with torch.random.fork_rng(devices=[]):
            if config.lstm_layers:
                self.lstm = nn.LSTM(config.n_features, config.hidden, config.lstm_layers, batch_first=True)
                widths = (config.hidden, *config.fc, config.hypotheses * config.n_outputs)
                layers: list[nn.Module] = []
                for i, (a, b) in enumerate(zip(widths[:-1], widths[1:])):
                    if i:
                        layers.append(ACTIVATIONS[config.activation]())
                    layers.append(nn.Linear(a, b))
                self.head = nn.Sequential(*layers)
                if config.hypotheses > 1:
                    self.chooser = nn.Linear(widths[-2], config.hypotheses)
            self.skip = nn.Linear(config.skip_inputs, config.n_outputs) if config.skip_inputs else None
        self.reset_parameters(generator)

    def reset_parameters(self, generator: torch.Generator | None = None) -> None:
        """Xavier/Glorot-uniform weights drawn from ``generator``, zero biases (thesis ref. [25])."""
        for p in self.parameters():
            if p.dim() >= 2:
                nn.init.xavier_uniform_(p, generator=generator)
            else:
                nn.init.zeros_(p)

    @property
    def is_linear(self) -> bool:
        """No LSTM: the network is its linear skip."""
        return self.lstm is None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.lstm is None:
            return self.skip(x.flatten(1))
        return self.forward_head(self.lstm_features(x), x.flatten(1))

    def lstm_features(self, x: torch.Tensor) -> torch.Tensor:
        """Last hidden state of the top LSTM layer, (B, hidden); (B, 0) for a linear network."""
        if self.lstm is None:
            return x.new_zeros((x.shape[0], 0))
        out, _ = self.lstm(x)
        return out[:, -1]

    def forward_head(self, h: torch.Tensor, x_flat: torch.Tensor | None) -> torch.Tensor:
        """FC layers on the LSTM features (B, hidden), plus the skip on the flat window (B, steps·features);
        with hypotheses, their mixture at ``choice_temperature`` (module docstring)."""
        if self.head is None:
            return self.skip(x_flat)
        if self.chooser is not None:
            ys, logits = self.forward_hypotheses(h, x_flat)
            weights = torch.softmax(logits / self.config.choice_temperature, dim=1)
            return torch.einsum("bk,bko->bo", weights, ys)
        y = self.head(h)
        if self.skip is not None:
            y = y + self.skip(x_flat)
        return y

    def forward_hypotheses(self, h: torch.Tensor, x_flat: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """The K hypotheses (B, K, n_outputs), each plus the skip, and the chooser's logits (B, K).

        The chooser reads the last FC layer's input detached: its cross-entropy trains it alone,
        and the hypotheses' shared layers learn only from their regression."""
        if self.head is None or self.chooser is None:
            raise ValueError("forward_hypotheses needs network.hypotheses > 1")
        z = self.head[:-1](h)
        ys = self.head[-1](z).unflatten(1, (self.config.hypotheses, self.config.n_outputs))
        if self.skip is not None:
            ys = ys + self.skip(x_flat).unsqueeze(1)
        return ys, self.chooser(z.detach())

    def lstm_parameters(self) -> list[nn.Parameter]:
        return [] if self.lstm is None else list(self.lstm.parameters())

    @torch.no_grad()
    def init_skip(self, weight: torch.Tensor, bias: torch.Tensor) -> None:
        """Set the linear skip to a given map (e.g. the ridge solution) and zero the last FC
        layer, so the network starts as that linear predictor.

        With hypotheses the last layer keeps its initial weights (its biases zeroed): K equal
        hypotheses would stay equal, the best of them taking every gradient."""
        if self.skip is None:
            raise ValueError("network has no linear skip (network.skip_inputs = 0)")
        self.skip.weight.copy_(weight)
        self.skip.bias.copy_(bias)
        if self.head is not None:
            last = self.head[-1]
            if self.chooser is None:
                last.weight.zero_()
            last.bias.zero_()
