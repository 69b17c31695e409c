"""Where ``coassist train`` writes its model (``--out``): checked before any work, in one line naming the option."""

from __future__ import annotations

import os
from pathlib import Path

from coassist.cli._common import err_console, fail

__all__ = ["MODEL_FILES", "check_model_out", "continues"]

#: What a model folder holds: the sidecar, weights and ridge (coassist.intent.model's SIDECAR, WEIGHTS, RIDGE), the
#: training's history and loss figure (coassist.intent.training.write_model) and evaluate's default record.
MODEL_FILES = frozenset(
    {"model.json", "weights.safetensors", "ridge.safetensors", "history.json", "loss.png", "evaluation.json"}
)


def _epochs_done(checkpoint: Path) -> str:
    """ ", E of N epochs done" from an interrupted run's checkpoint.json, or "" where it cannot be read."""
    import json

    try:
        ckpt = json.loads(checkpoint.read_text())
        done, total = ckpt["epoch"], ckpt["train_config"]["epochs"]
    except (OSError, ValueError, KeyError, TypeError):
        return ""
    return f", {done} of {total} epochs done" if isinstance(done, int) and isinstance(total, int) else ""


def continues(out: Path, init: str) -> bool:
    """Whether the run continues an interrupted one in place (``resume:`` of --out, its checkpoint beside it)."""
    from coassist._io import partial_folder

    return (
        init.startswith("resume:")
        and Path(init.partition(":")[2]).absolute() == out.absolute()
        and (partial_folder(out) / "checkpoint.json").is_file()  # intent.checkpoint.CHECKPOINT_JSON
    )


def check_model_out(out: Path, overwrite: bool, init: str) -> None:
    """Refuse before any work an --out that is a file, the current folder (or one holding it), a folder of other files
    than a model, or an existing model without --overwrite."""
    from coassist._io import partial_folder

    bad_parent = next((p for p in reversed(out.parents) if p.exists() and not p.is_dir()), None)
    if bad_parent is not None:
        fail(f"--out {out}: {bad_parent} is a file, not a folder", 2)
    if out.exists() and not out.is_dir():
        fail(f"--out {out}: is a file; give a folder for the model", 2)
    here = Path(os.getcwd()).resolve()
    if out.resolve() in (here, *here.parents):  # the model folder is swapped in whole: not the one we stand in
        fail(f"--out {out}: is the current folder or holds it; give a folder for the model beside or below it", 2)
    # a folder of other files is not a model to replace (--overwrite swapped it out whole: a thesis.tex, notes/, gone)
    if out.is_dir() and any(out.iterdir()) and not (out / "model.json").is_file():  # intent.model.SIDECAR
        fail(
            f"--out {out}: holds files but no model (no model.json), which --overwrite would delete with it; give "
            "an empty or new folder for the model",
            2,
        )
    if overwrite and (out / "model.json").is_file():
        # the model is swapped out whole: files it did not write (notes, another evaluation) would go with it
        others = sorted(p.name + ("/" if p.is_dir() else "") for p in out.iterdir() if p.name not in MODEL_FILES)
        if others:
            fail(
                f"--out {out}: holds files a model does not ({', '.join(others[:5])}"
                f"{f', … {len(others)} in all' if len(others) > 5 else ''}), which --overwrite would delete with the "
                "old model; move them out first, or give another folder for the model",
                2,
            )
    # Only an interrupted run (its checkpoint in the partial folder beside --out) is continued in place;
    # a new stage from the finished model in --out replaces it, as any other run would.
    continuing = continues(out, init)
    checkpoint = partial_folder(out) / "checkpoint.json"
    if not continuing and checkpoint.is_file():
        # an interrupted run's epochs are kept until this run's first epoch replaces them: said, so that a rerun
        # of the command that was stopped is not taken for its continuation
        err_console.print(
            f"note: {checkpoint.parent} holds the checkpoint of an interrupted training{_epochs_done(checkpoint)}; "
            f"this run starts again and replaces it (to continue it instead: --init resume:{out})",
            markup=False,
            soft_wrap=True,
        )
    if out.is_dir() and any(out.iterdir()) and not (overwrite or continuing):
        fail(
            f"--out {out}: already holds files; pass --overwrite to replace it (the old model stays until the new "
            "one is complete)",
            2,
        )
