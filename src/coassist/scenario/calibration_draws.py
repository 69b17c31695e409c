"""Several calibrations of the same people, each trial meeting one: the calibration's own variance (issue 40).

A person model is fitted to a few calibration trials of the person (:mod:`coassist.scenario.person_model`);
another few trials of the same person give another model, and the assistance measured with it moves
(docs/person-model.md: over three draws of the probe trials the board's overshoot share was 91, 60 and 64 %).
An evaluation that fits one calibration per person measures one draw, and an interval over its trials leaves
that variance out.

A **calibration-draws folder** holds K person-model folders of the same people, each fitted to its own
calibration trials (``draw-0`` … ``draw-{K−1}``, listed in ``calibration-draws.json``). The trial of seed s
meets draw s mod K (a trial without a seed, draw 0): a person's consecutive trials go round the draws. An
interval that resamples the (person, draw) clusters whole (:func:`coassist.analysis.paired.gain_share`'s
``clusters``, :func:`draw_clusters`) then carries the calibration's variance as well as the trials'.

It is an evaluation device: a lab calibrates once and runs that model (a person-model folder). Each draw is
told what a person model is told, no more; which draw runs is a function of the trial's seed alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from coassist._checks import check_int
from coassist._io import read_hashed_json, write_hashed_json
from coassist.interfaces import TrialContext
from coassist.scenario.person_intent import PersonPathsIntent
from coassist.scenario.person_model import read_person_model

__all__ = [
    "DRAWS_FILE",
    "MAX_DRAWS",
    "CalibrationDraws",
    "asked_paths",
    "draw_clusters",
    "draw_count",
    "draw_of",
    "read_draws",
    "write_draws",
]

DRAWS_FILE = "calibration-draws.json"
#: The most draws a folder may hold (each is a calibration: a few trials per person; the run's calibration seeds
#: leave room for eight blocks, experiments.source_training.DRAW_SEED_STEP).
MAX_DRAWS = 8
_FORMAT = "coassist-calibration-draws-1"


def draw_of(seed: int | None, draws: int) -> int:
    """The draw the trial of ``seed`` meets among ``draws``: seed mod draws (0 for a trial without a seed)."""
    draws = check_int(draws, "draws", 1, MAX_DRAWS)
    return 0 if seed is None else int(seed) % draws


def draw_count(intent: str | Path) -> int:
    """The draws a calibration-draws folder holds, read from its file; 1 for anything else (one calibration,
    or none)."""
    path = Path(intent) / DRAWS_FILE
    if not path.is_file():
        return 1
    names = read_hashed_json(path, format=_FORMAT).get("draws")
    if not isinstance(names, list) or not 1 <= len(names) <= MAX_DRAWS:
        raise ValueError(f"{path}: draws must be a list of 1 to {MAX_DRAWS} folder names, got {names!r}")
    return len(names)


def draw_clusters(pairs: Sequence[tuple[str, int]], draws: int) -> list[tuple[str, int]]:
    """The (person, draw) cluster of each (person, seed) pair (:func:`~coassist.experiments.application.pair_key`):
    the trials that shared one calibration."""
    return [(str(user), draw_of(None if seed < 0 else seed, draws)) for user, seed in pairs]


class CalibrationDraws:
    """The intent source of a calibration-draws folder (module docstring): at each trial's reset, the draw
    :func:`draw_of` its seed names runs the trial.

    Parameters
    ----------
    draws : the person models, one per calibration draw (the same people), in draw order.
    model_id : what trials record as the source.
    """

    def __init__(self, draws: Sequence[PersonPathsIntent], model_id: str = "person-draws") -> None:
        self.draws = tuple(draws)
        if not 1 <= len(self.draws) <= MAX_DRAWS:
            raise ValueError(f"CalibrationDraws needs 1 to {MAX_DRAWS} person models, got {len(self.draws)}")
        horizons = {d.horizon for d in self.draws}
        if len(horizons) != 1:
            raise ValueError(f"CalibrationDraws: the draws' horizons differ ({sorted(horizons)})")
        self.horizon = self.draws[0].horizon
        self.history = max(d.history for d in self.draws)
        self.model_id = model_id
        self._active: PersonPathsIntent | None = None

    @property
    def active(self) -> int | None:
        """The index of the draw running the present trial (None before the first reset)."""
        return None if self._active is None else self.draws.index(self._active)

    @property
    def side(self) -> int:
        """The way round the running draw's rows follow (:attr:`PersonPathsIntent.side`)."""
        return 0 if self._active is None else self._active.side

    def reset(self, context: TrialContext) -> None:
        self._active = self.draws[draw_of(context.seed, len(self.draws))]
        self._active.reset(context)

    def predict(self, history: np.ndarray) -> np.ndarray:
        if self._active is None:
            raise RuntimeError("CalibrationDraws.predict called before reset")
        return self._active.predict(history)


def write_draws(folder: str | Path, names: Sequence[str]) -> Path:
    """Write ``calibration-draws.json`` into ``folder`` (atomically), listing its draws' person-model folders
    ``names`` (each a folder directly inside ``folder``, in draw order); returns the folder."""
    folder = Path(folder)
    names = [str(n) for n in names]
    if not 1 <= len(names) <= MAX_DRAWS:
        raise ValueError(f"a calibration-draws folder holds 1 to {MAX_DRAWS} draws, got {len(names)}")
    for name in names:
        if not name or name in (".", "..") or "/" in name or "\\" in name:
            raise ValueError(f"draw {name!r}: a draw is a folder directly inside {folder}")
        if not (folder / name).is_dir():
            raise ValueError(f"draw {name!r}: no folder {folder / name}")
    if len(set(names)) != len(names):
        raise ValueError(f"draws {names}: a draw is named twice")
    write_hashed_json(folder / DRAWS_FILE, {"draws": names}, format=_FORMAT)
    return folder


def asked_paths(intent: str | Path) -> tuple[int, int, int]:
    """Of a person-model or calibration-draws folder's fits (person × draw): (how many hold paths the lab asked for,
    how many paths were asked for in all, how many fits) (:attr:`~coassist.scenario.path_model.PathModel.asked`)."""
    folder = Path(intent)
    sources = read_draws(folder).draws if (folder / DRAWS_FILE).is_file() else (read_person_model(folder),)
    counts = [int(np.sum(np.asarray(m.asked, dtype=bool))) for source in sources for m in source.paths.values()]
    return sum(n > 0 for n in counts), sum(counts), len(counts)


def read_draws(folder: str | Path, horizon: int = 50) -> CalibrationDraws:
    """The intent source a calibration-draws folder holds (errors name the file and the draw)."""
    folder = Path(folder)
    path = folder / DRAWS_FILE
    doc = read_hashed_json(path, format=_FORMAT)
    names = doc.get("draws")
    if not isinstance(names, list) or not 1 <= len(names) <= MAX_DRAWS or not all(isinstance(n, str) for n in names):
        raise ValueError(f"{path}: draws must be a list of 1 to {MAX_DRAWS} folder names, got {names!r}")
    sources = []
    for name in names:
        if not name or name in (".", "..") or "/" in name or "\\" in name:
            raise ValueError(f"{path}: draw {name!r} is not a folder directly inside {folder}")
        sources.append(read_person_model(folder / name, horizon))
    return CalibrationDraws(sources, model_id=f"person-draws:{folder.name}")
