"""A simulated participant on the study's page: the hand follows the simulated operator's intended path.

Used by the websocket test (no browser) and the Chromium test: both need, for the step the page
shows, the path the simulated operator's hand takes (from the study folder's recorded steps,
the researcher's side: the page itself is told no seed and no condition).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from coassist.config import CONTROL_PRESETS
from coassist.scenario.operator import asked_to_go
from coassist.scenario.tasks import task_for_seed
from coassist.study.participants import hand_path, simulated_answers, simulated_profile
from coassist.study.plan import plan_from_text
from coassist.study.questionnaires import form_for

#: Every string the page must never receive in a comparison of these conditions.
SECRETS = ("cooperative", "impedance", "manual", "assistive", "arbitrated")


class OperatorPath:
    """Where participant ``pid``'s simulated operator wants its hand at time t of step k."""

    def __init__(self, study: Path, pid: str) -> None:
        self.study = Path(study)
        self.plan = plan_from_text((self.study / "plan.toml").read_text(), self.study)
        self.pid = pid
        self._paths: dict[int, np.ndarray] = {}

    def _order(self) -> dict:
        return json.loads((self.study / "participants" / self.pid / "order.json").read_text())

    def at(self, k: int, t: float) -> tuple[float, float]:
        if k not in self._paths:
            order = self._order()
            step = order["steps"][k]
            tp = self.plan.trials
            dt = float(CONTROL_PRESETS.lookup(tp.preset).impedance.dt)
            task = task_for_seed(step["task"], step["seed"], obstacle=tp.obstacle, motion_time=tp.motion_time)
            self.dt = dt
            # a calibration trial that asks for a way round: the page says which; the simulated participant takes it
            profile = asked_to_go(simulated_profile(order["number"], self.plan.seed), int(step.get("way", 0)))
            self._paths[k] = hand_path(task, step["seed"], profile, dt, 20000)
        path = self._paths[k]
        i = min(len(path) - 1, max(0, int(round(t / self.dt))))
        return float(path[i, 0]), float(path[i, 1])

    def answers(self, k: int, form_items: list[dict]) -> list[int]:
        """Answers of the questionnaire of step k (the simulated participant's, from the condition's trials)."""
        from coassist.data import read_dataset
        from coassist.metrics import f_rms

        order = self._order()
        block = order["steps"][k]["block"]
        trials = read_dataset(self.study / "participants" / self.pid / block).trials
        form = form_for(self.plan.questionnaire)
        assert [i.key for i in form.items] == [i["key"] for i in form_items]
        f = float(np.mean([f_rms(t.wrench[:, :2]) for t in trials]))
        return simulated_answers(
            form, f, None, simulated_profile(order["number"], self.plan.seed), np.random.default_rng([k, 1])
        )
