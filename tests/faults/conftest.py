"""Shared by the file-fault tests: one small trained model, copied by each test before it edits."""

from __future__ import annotations

from pathlib import Path

import pytest

from ..intent.conftest import TINY, labeled


@pytest.fixture(scope="session")
def model_dir(tmp_path_factory) -> Path:
    """A tiny model folder (never edited in place: tests copy it first)."""
    from dataclasses import replace

    from coassist.intent.training import train_model, write_model

    out = tmp_path_factory.mktemp("model") / "m"
    write_model(train_model(labeled(3), TINY, replace(TINY.train, epochs=1)), out)
    return out
