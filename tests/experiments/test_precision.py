"""compare_intents: the validation comparison of docs/precision.md, on a one-trial plan."""

import numpy as np
import pytest

from coassist.analysis.paired import gain_share
from coassist.experiments.ablation_cells import ARBITRATED
from coassist.experiments.precision import compare_intents, comparison_table


def test_comparison_pairs_every_source_with_mg_and_the_oracle(tmp_path):
    # a label that ends like a training seed's name (`-s1`) is its own source (it once failed the table's
    # formatting after every simulation had run)
    result = compare_intents(
        {"cv-s1": "constant-velocity"},
        tmp_path,
        bases=(50000,),
        trials=1,
        users=(0,),
        calibrate=False,
        workers=1,
        progress=False,
    )
    for obj in ("board", "heavy"):
        mg, cv, oracle = (
            result.mg[("point-mass", obj)],
            result.metrics[("point-mass", obj, ARBITRATED, "cv-s1")],
            result.metrics[("point-mass", obj, ARBITRATED, "oracle")],
        )
        assert len(mg["f_rms_trials"]) == len(cv["f_rms_trials"]) == 1
        assert result.pairs[("point-mass", obj)] == [("user-0", 950000 + 1000 * ("board", "heavy").index(obj))]
        share = gain_share(mg["f_rms_trials"], cv["f_rms_trials"], oracle["f_rms_trials"])
        assert result.shares("point-mass", obj, ARBITRATED, "cv-s1")["f_rms"][0] == share[0]
        assert np.isfinite(cv["clearance_deficit"])
    table = comparison_table(result)
    assert table.count("| MG | manual |") == 2 and table.count("| cv-s1 | cooperative-arbitrated |") == 2


def test_bad_requests_name_what_is_wrong(tmp_path):
    with pytest.raises(ValueError, match="at least one source"):
        compare_intents({}, tmp_path)
    with pytest.raises(ValueError, match="bases"):
        compare_intents({"a": "present"}, tmp_path, bases=(1, 1))
    with pytest.raises(ValueError, match="taken by the baselines"):
        compare_intents({"oracle": "oracle"}, tmp_path)
    with pytest.raises(ValueError, match="taken by the baselines"):
        compare_intents({"oracle-cooperative": "present"}, tmp_path)
    with pytest.raises(ValueError, match="'cooperative-damped', 'cooperative', got"):
        compare_intents({"a": "present"}, tmp_path, controllers={"a": "manual"})
    for report_only in ("held-out", "unseen"):  # the populations that only report
        with pytest.raises(ValueError, match="kept out of everything tuned"):
            compare_intents({"a": "present"}, tmp_path, population=report_only)
    with pytest.raises(ValueError, match="population must be one of thesis, varied"):
        compare_intents({"a": "present"}, tmp_path, population="nobody")
    for bad in (0, 2.5):
        with pytest.raises(ValueError, match="probe_trials must be an integer >= 1"):
            compare_intents({"p": "person"}, tmp_path, probe_trials=bad)
    for bad in (-1, 9, 1.5):
        with pytest.raises(ValueError, match="person_calibration_asked must be an integer 0 to 8"):
            compare_intents({"p": "person"}, tmp_path, asked_trials=bad)
    assert not any(tmp_path.iterdir())  # refused before anything ran
    from typer.testing import CliRunner

    from coassist.cli import app

    res = CliRunner().invoke(
        app, ["compare-intents", "--source", "p=person", "--out", str(tmp_path / "x"), "--asked-trials", "9"]
    )
    assert res.exit_code == 2 and "--asked-trials must be 0 to 8, got 9" in res.output


def test_the_default_source_needs_less_force_and_overshoots_less_than_mg(tmp_path):
    # the default of every world without a calibration (coassist.scenario.assistance.DEFAULT_INTENT) was chosen
    # on the validation seeds of both bases (docs/precision.md): never more hand force or overshoot than MG.
    # One application trial per object here, with the arbitrated controller and the plain one (drive's default)
    from coassist.scenario.assistance import DEFAULT_INTENT

    result = compare_intents(
        {"default": DEFAULT_INTENT, "default-plain": DEFAULT_INTENT},
        tmp_path,
        bases=(60000,),
        controllers={"default-plain": "cooperative"},
        trials=1,
        users=(1,),
        calibrate=False,
        workers=1,
        progress=False,
    )
    assert result.models == {}  # no source needed the operators' calibration trials
    for obj in ("board", "heavy"):
        mg = result.mg[("point-mass", obj)]
        for controller, label in ((ARBITRATED, "default"), ("cooperative", "default-plain")):
            got = result.metrics[("point-mass", obj, controller, label)]
            assert got["f_rms"] < 0.9 * mg["f_rms"], (obj, label, got["f_rms"], mg["f_rms"])
            assert got["overshoot"] <= mg["overshoot"], (obj, label, got["overshoot"], mg["overshoot"])
        # the plain game's share is measured against its own oracle, run on the same trials
        plain, oracle = (result.metrics[("point-mass", obj, "cooperative", k)] for k in ("default-plain", "oracle"))
        share = gain_share(mg["f_rms_trials"], plain["f_rms_trials"], oracle["f_rms_trials"])
        assert result.shares("point-mass", obj, "cooperative", "default-plain")["f_rms"][0] == share[0]
    table = comparison_table(result)
    assert table.count("| oracle | cooperative |") == 2 and table.count("| default-plain | cooperative |") == 2
