"""The main job on several seeds (issue 35): which verdicts hold whatever the seed.

Every verdict of one run comes from one seed: 18–24 paired trials per cell, one training of
each model. :func:`run_seeds` runs the whole pipeline once per seed, in ``out/seed-<k>/``, all
on one pool of simulation processes (run seed k owns the trial seeds k·10⁶ … (k+1)·10⁶ − 1 and
its own training seeds, :func:`~coassist.experiments.seed_plan.trial_seed_base`, so the runs share
no trial), then writes one report and one summary: per claim, on how many seeds it holds, with
each seed's verdict and evidence (:func:`claims_across_seeds`). A claim is

- **robust** when it holds on every seed,
- **seed-dependent** when it holds on some,
- **not holding** when it holds on none.

The first screen says which claims are robust; each seed's own report is in its folder.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from coassist._checks import is_ascii_integer
from coassist._io import atomic_write_text
from coassist.experiments.report import Section, write_report
from coassist.experiments.reproduce_config import ReproduceConfig

__all__ = ["SeedClaim", "claims_across_seeds", "parse_seeds", "run_seeds", "seeds_section"]


@dataclass(frozen=True)
class SeedClaim:
    """One claim over the seeds: its text, and per seed (holds, evidence); None where a seed's run has no
    such claim (a run that did not check it, e.g. without the real recordings)."""

    text: str
    per_seed: dict[int, tuple[bool, str] | None]

    @property
    def checked(self) -> int:
        """Seeds whose run checked the claim."""
        return sum(v is not None for v in self.per_seed.values())

    @property
    def held(self) -> int:
        """Seeds on which it holds."""
        return sum(1 for v in self.per_seed.values() if v is not None and v[0])

    @property
    def status(self) -> str:
        """ "robust" (holds on every seed that checked it), "seed-dependent" (on some) or "not holding"."""
        if self.checked and self.held == self.checked:
            return "robust"
        return "seed-dependent" if self.held else "not holding"

    def to_dict(self) -> dict[str, Any]:
        return {
            "claim": self.text,
            "status": self.status,
            "holds_on": self.held,
            "checked_on": self.checked,
            "seeds": {
                str(k): None if v is None else {"holds": v[0], "evidence": v[1]} for k, v in self.per_seed.items()
            },
        }


def parse_seeds(text: str) -> tuple[int, ...]:
    """``--seeds``: a count N (the seeds 0 … N−1) or a comma-separated list of distinct seeds ≥ 0."""
    parts = [p.strip() for p in str(text).split(",") if p.strip()]
    if not all(is_ascii_integer(p) for p in parts):
        raise ValueError(f"--seeds must be a count or a comma-separated list of integers, got {text!r}")
    values = [int(p) for p in parts]
    if not values:
        raise ValueError("--seeds must name at least one seed")
    if len(values) == 1 and "," not in str(text):
        if values[0] < 1:
            raise ValueError(f"--seeds N must be a count >= 1, got {values[0]}")
        return tuple(range(values[0]))
    if any(v < 0 for v in values) or len(set(values)) != len(values):
        raise ValueError(f"--seeds must be distinct integers >= 0, got {text!r}")
    return tuple(values)


def claims_across_seeds(summaries: Mapping[int, Mapping[str, Any]]) -> list[SeedClaim]:
    """Every claim of the runs' summaries (seed → summary.json's dict), in the order they first appear,
    with each seed's verdict and evidence; claims are matched by their text."""
    order: list[str] = []
    per: dict[str, dict[int, tuple[bool, str]]] = {}
    for seed, summary in summaries.items():
        for c in summary["claims"]:
            if c["claim"] not in per:
                per[c["claim"]] = {}
                order.append(c["claim"])
            if seed in per[c["claim"]]:
                raise ValueError(f"seed {seed}'s summary states the claim twice: {c['claim']!r}")
            per[c["claim"]][seed] = (bool(c["holds"]), str(c["evidence"]))
    return [SeedClaim(text, {seed: per[text].get(seed) for seed in summaries}) for text in order]


def seeds_section(claims: Sequence[SeedClaim], seeds: Sequence[int]) -> Section:
    """The report's section: every claim with its count and each seed's verdict and evidence."""
    s = Section(f"Every claim on seeds {', '.join(str(k) for k in seeds)}")
    s.paragraphs.append(
        "Each seed is a whole run of the pipeline on its own trials and trainings (its report is in seed-<k>/). A claim "
        "is robust when it holds on every seed, seed-dependent when it holds on some: its verdict with one seed says "
        "as much about that seed's trials as about the claim."
    )
    rows = []
    for c in claims:
        row: list[Any] = [c.text, f"{c.held} of {c.checked}", c.status]
        for k in seeds:
            v = c.per_seed.get(k)
            row.append("—" if v is None else ("holds: " if v[0] else "does not hold: ") + v[1])
        rows.append(row)
    s.tables.append(
        (
            "Claims across seeds: on how many seeds each holds, and each seed's evidence",
            ["claim", "holds on", "status"] + [f"seed {k}" for k in seeds],
            rows,
        )
    )
    return s


def _verdict_text(verdict: tuple[bool, str] | None) -> str:
    """One seed's verdict in a table cell: holds, does not hold, or — where the seed did not check it."""
    if verdict is None:
        return "—"
    return "holds" if verdict[0] else "does not hold"


def _headline(claims: Sequence[SeedClaim], seeds: Sequence[int]) -> Section:
    s = Section(f"Which claims hold whatever the seed ({len(seeds)} seeds)")
    by = {status: [c for c in claims if c.status == status] for status in ("robust", "seed-dependent", "not holding")}
    s.tables.append(
        (f"Robust: {len(by['robust'])} claims hold on every seed", ["claim"], [[c.text] for c in by["robust"]])
    )
    s.tables.append(
        (
            f"Seed-dependent: {len(by['seed-dependent'])} claims hold on some seeds only",
            ["claim", "holds on"] + [f"seed {k}" for k in seeds],
            [
                [c.text, f"{c.held} of {c.checked}"] + [_verdict_text(c.per_seed.get(k)) for k in seeds]
                for c in by["seed-dependent"]
            ],
        )
    )
    s.tables.append(
        (
            f"Not holding: {len(by['not holding'])} claims hold on no seed",
            ["claim"],
            [[c.text] for c in by["not holding"]],
        )
    )
    return s


def run_seeds(
    config: ReproduceConfig,
    seeds: Sequence[int],
    out: str | Path,
    *,
    progress: bool = True,
    say: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run the pipeline on each seed (``out/seed-<k>``, one pool for all) and write ``out/report.html`` and
    ``out/summary.json`` (module docstring); returns the summary."""
    from coassist.experiments.reproduce import run_reproduce, simulation_pool

    seeds = tuple(int(k) for k in seeds)
    if not seeds or len(set(seeds)) != len(seeds) or any(k < 0 for k in seeds):
        raise ValueError(f"seeds must be distinct integers >= 0, got {seeds!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    say = say or (lambda line: None)
    t0 = time.perf_counter()
    summaries: dict[int, dict[str, Any]] = {}
    with simulation_pool(config) as pool:
        for k in seeds:
            say(f"[bold]seed {k}[/] ({len(summaries) + 1} of {len(seeds)})")
            summaries[k] = run_reproduce(
                replace(config, seed=k), out / f"seed-{k}", progress=progress, say=say, pool=pool
            )
    claims = claims_across_seeds(summaries)
    total = time.perf_counter() - t0
    cpu = {k: s.get("cpu_seconds", {}) for k, s in summaries.items()}
    summary = {
        "preset": config.name,
        "seeds": list(seeds),
        "total_seconds": total,
        "seconds": {str(k): s["total_seconds"] for k, s in summaries.items()},
        "cpu_seconds": {str(k): v for k, v in cpu.items()},
        "claims": [c.to_dict() for c in claims],
        "robust": sum(c.status == "robust" for c in claims),
        "n_claims": len(claims),
    }
    intro = (
        f"coassist reproduction of the thesis' experiments on seeds {', '.join(str(k) for k in seeds)}, preset "
        f"'{config.name}'; total time {total:.0f} s ({', '.join(f'seed {k}: {s:.0f} s' for k, s in zip(seeds, (summaries[k]['total_seconds'] for k in seeds)))}). "
        f"{summary['robust']} of {len(claims)} claims hold on every seed."
    )
    write_report(
        out / "report.html",
        "coassist — the thesis' experiments on several seeds",
        intro,
        [seeds_section(claims, seeds)],
        _headline(claims, seeds),
    )
    import json

    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1, allow_nan=False))
    return summary
