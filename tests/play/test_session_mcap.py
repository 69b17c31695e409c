"""`coassist play --mcap`: each saved trial also lands as an MCAP file beside its Parquet file."""

from __future__ import annotations

import numpy as np
import pytest

from coassist.data import Trial, TrialMeta, read_dataset
from coassist.play.session import PlayConfig, PlaySession

pytest.importorskip("rosbags", reason="the bags extra (rosbags) is not installed")


def test_saved_trials_are_written_as_mcap_too(tmp_path):
    from coassist.data.bags import load_bag_trial

    session = PlaySession(PlayConfig(user="bob", out=tmp_path, controllers=("cooperative",), mcap=True))
    n = 30
    t = np.arange(n) * 0.008
    pose = np.column_stack([0.1 * t, -0.05 * t])
    meta = TrialMeta(
        user="bob",
        task="linear",
        object="none",
        controller="cooperative",
        model_id=None,
        seed=0,
        origin="sim",
        dt=0.008,
        extra={"target": [0.5, 0.0], "arrive_radius": 0.025, "ended": "target"},
    )
    trial = Trial(
        meta=meta,
        time=t,
        pose=pose,
        velocity=np.tile([0.1, -0.05], (n, 1)),
        wrench=np.ones((n, 2)),
        reference=pose + 0.01,
    )
    session._save(trial)
    session._save(trial)
    folder = tmp_path / "bob"
    parquet = sorted(folder.glob("*.parquet"))
    mcaps = sorted(folder.glob("*.mcap"))
    assert [p.stem for p in mcaps] == [p.stem for p in parquet] and len(mcaps) == 2
    assert load_bag_trial(mcaps[1]).pose.tobytes() == trial.pose.tobytes()
    assert len(read_dataset(folder).trials) == 2  # the dataset is untouched by the MCAP files beside it
