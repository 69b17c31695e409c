"""The in-loop ablation's report (issues 18, 34, 40): its tables, first-screen rows and claims.

Rendering only: everything here reads an :class:`~coassist.experiments.ablation_cells.AblationResult`
(the cells' metrics, the shares of the oracle's benefit and the per-side paired differences it
computes) and writes text for :mod:`coassist.experiments.report`'s sections; the cells are run
in :mod:`coassist.experiments.ablation`, and what they are and their statistics are
:mod:`coassist.experiments.ablation_cells`'.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from coassist.analysis.paired import paired_difference
from coassist.experiments.ablation import HELD_OUT_PERSON, MUJOCO_PERSON
from coassist.experiments.ablation_cells import (
    ABLATION_CELLS,
    ARBITRATED,
    DAMPED,
    FORCE_SHARE_BAR,
    HELD_OUT,
    JERK_BAR,
    ORACLE_SHARE_BAR,
    OVERSHOOT_SHARE_BAR,
    SHARE_LOWER_BAR,
    SIDES,
    AblationResult,
    told_of,
)
from coassist.experiments.application import OBJECTS, paired_text
from coassist.experiments.pipeline import EVAL_HORIZONS
from coassist.experiments.report import Claim, Section
from coassist.experiments.source_training import APPLICATION_SOURCE
from coassist.robot.worlds import POINT_MASS
from coassist.scenario.assistance import DEFAULT_INTENT
from coassist.scenario.path_model import FEW_PATHS
from coassist.scenario.populations import UNSEEN


def shown(value: float, digits: int, bar: float | None = None, strict: bool = False, signed: bool = False) -> str:
    """``value`` with ``digits`` decimals, or more (at most three more) where that rounding would put it on the
    other side of a claim's ``bar`` than it is (``value`` > ``bar`` where ``strict``, else ≥; both in the units
    shown): 84.96 against a bar of 85 is "84.96", not "85". ``signed``: with its sign (a difference)."""
    sign = "+" if signed else ""
    text = f"{value:{sign}.{digits}f}"
    if bar is None or not np.isfinite(value):
        return text
    holds = value > bar if strict else value >= bar
    for more in range(1, 4):
        rounded = float(text)
        if (rounded > bar if strict else rounded >= bar) == holds:
            break
        text = f"{value:{sign}.{digits + more}f}"
    return text


def share_text(
    s: tuple[float, float, float], bar: float | None = None, lower_bar: float | None = None, lower_strict: bool = False
) -> str:
    """A (share, low, high) as the report writes it: percent with its interval, or n/a. A claim's ``bar`` on
    the share (share ≥ bar) and ``lower_bar`` on its low bound (≥, or > where ``lower_strict``), as fractions,
    keep the printed figures on their side of it (:func:`shown`)."""
    share, lo, hi = s
    if not np.isfinite(share):
        return "n/a"
    pct = None if bar is None else 100 * bar
    low = None if lower_bar is None else 100 * lower_bar
    # the bounds kept on the share's side of its bar too where the lower bound has none (84.86 % [85, 85] read as
    # an interval that misses its own share)
    lo_text = shown(100 * lo, 0, pct, False) if low is None else shown(100 * lo, 0, low, lower_strict)
    bracket = f" [{lo_text}, {shown(100 * hi, 0, pct)}]" if np.isfinite(lo) else ""
    return f"{shown(100 * share, 0, pct)} %{bracket}"


def seeds_text(result: AblationResult, world: str, obj: str, controller: str, source: str, metric: str) -> str:
    """The share over a source's trainings: the first one's with its interval, and each other seed's."""
    names = result.seeds_of(world, obj, controller, source)
    first = share_text(result.shares(world, obj, controller, names[0])[metric])
    if len(names) == 1:
        return first
    others = [result.shares(world, obj, controller, n)[metric][0] for n in names]
    return f"{first}; seeds {', '.join(f'{100 * v:.0f}' for v in others)} %"


def _side_text(v: tuple[float, float, float, float, int], judged: str = "") -> str:
    """One side's (mean, paired difference from MG, its 95 % low and high, trials) [m] in mm: "—" without a
    trial; the difference without an interval where one trial went that way. ``judged`` ("d" or "hi"): the
    figure a claim holds to ≤ 0, kept on its side of 0 (:func:`shown`)."""
    mean, d, lo, hi, n = v
    if not n:
        return "— (no trial)"
    # the claims hold a side to d ≤ 0 or hi ≤ 0: printed on the right side of "> 0"
    diff = shown(1e3 * d, 1, 0.0 if judged == "d" else None, strict=True, signed=True)
    if not np.isfinite(lo):
        return f"{1e3 * mean:.1f} ({diff}, one trial: no interval)"
    high = shown(1e3 * hi, 1, 0.0 if judged == "hi" else None, strict=True, signed=True)
    return f"{1e3 * mean:.1f} ({diff} [{1e3 * lo:+.1f}, {high}])"


def _thin_sides(sides: dict[int, tuple[float, float, float, float, int]], need: int) -> str:
    """Why a per-side claim cannot hold where a side had fewer than ``need`` trials ("" where none did)."""
    thin = [f"{SIDES[sd]} ({v[4]})" for sd, v in sides.items() if v[4] < need]
    if not thin:
        return ""
    least = "a trial" if need == 1 else f"{need} trials (an interval)"
    return (
        f"too few of the cell's trials went round the detour on the {' and '.join(thin)} to compare that side with "
        f"MG: it needs {least}; the trials' sides are the operators' own choices"
    )


#: The first screen's rows: (label, controller, source); the LSTM's and the ridge's as the previous
#: application source and its simplest rival, the application's, and the oracle.
HEADLINE = (
    ("nominal plan", ARBITRATED, "nominal"),
    ("LSTM+FC, intent label", ARBITRATED, "lstm-intent"),
    ("ridge, intent label", ARBITRATED, "ridge-intent"),
    ("present estimate", ARBITRATED, "present"),
    ("present estimate, held (every world's default without a calibration)", ARBITRATED, DEFAULT_INTENT),
    ("path hypotheses", ARBITRATED, "paths"),
    ("path hypotheses + deceleration damping", DAMPED, "paths"),
    ("person model (learnt from probe trials)", ARBITRATED, "person"),
    ("oracle (true intent)", ARBITRATED, "oracle"),
)


def cell_name(result: AblationResult, world: str) -> str:
    """A cell world's name in the report: the held-out cells' with their population where it is not the held-out one
    (reproduce.held_out_population)."""
    if world == HELD_OUT and result.held_out_population != HELD_OUT:
        return f"{world} ({result.held_out_population} population)"
    return world


def held_out_caption(population: str, people: int) -> str:
    """Who the held-out cells met, for their table's caption: the population (reproduce.held_out_population) and its
    people (reproduce.held_out_people), with what was chosen while seeing them."""
    if population == UNSEEN:
        return (
            f"the unseen population's people{f' of seed {people}' if people else ''}: operators of detour families "
            "made after every choice of the person model and its evaluation (a lean the other way first, a return "
            "that rings: docs/person-model.md), on trials of their own, point-mass world"
        )
    if people:
        return (
            f"the held-out population's people of seed {people}: operators of its detour families drawn anew, whom no "
            "choice of the person model has seen (their families were: docs/person-model.md), on trials of their "
            "own, point-mass world"
        )
    return (
        "the held-out population: operators of detour families and arms the tuning populations lack, on trials of "
        "their own (these operators were seen, on other trials, while the person model's lead check, its sign test "
        "and its lock guard were chosen: docs/person-model.md), point-mass world"
    )


def headline_rows(result: AblationResult, world: str = POINT_MASS) -> tuple[str, list[str], list[list[Any]]]:
    """The report's first-screen table (issue 34): per object, MG and each headline source with the
    arbitrated controller: f_RMS and its share of the oracle's saving, overshoot past the intent per side
    of the detour and its share, the clearance deficit per side, jerk and σ."""
    rows = []
    for obj in OBJECTS:
        if (world, obj) not in result.mg:
            continue
        m = result.mg[(world, obj)]
        side = np.asarray(m["side"])

        def sided(values, side: np.ndarray = side) -> str:
            v = np.asarray(values, float)
            return " / ".join(f"{1e3 * np.nanmean(v[side == s]):.1f}" if (side == s).any() else "—" for s in SIDES)

        rows.append(
            [
                obj,
                "MG",
                f"{m['f_rms']:.2f}",
                "",
                sided(m["overshoot_trials"]),
                "",
                sided(m["clearance_deficit_trials"]),
                f"{m['jerk_rms']:.2f}",
                f"{1e3 * m['sigma']:.2f}",
                "",
            ]
        )
        for label, controller, source in HEADLINE:
            if (world, obj, controller, source) not in result.metrics:
                continue
            r = result.metrics[(world, obj, controller, source)]
            default = " (the application's)" if source == APPLICATION_SOURCE and controller == ARBITRATED else ""
            rows.append(
                [
                    obj,
                    label + default,
                    f"{r['f_rms']:.2f}",
                    seeds_text(result, world, obj, controller, source, "f_rms"),
                    sided(r["overshoot_trials"]),
                    seeds_text(result, world, obj, controller, source, "overshoot"),
                    sided(r["clearance_deficit_trials"]),
                    f"{r['jerk_rms']:.2f} ({r['jerk_rms'] / m['jerk_rms']:.2f}× MG)",
                    f"{1e3 * r['sigma']:.2f}",
                    told_of(source, result.models.get(source)).text(),
                ]
            )
    n = len(result.pairs.get((world, OBJECTS[0]), ()))
    who = (
        held_out_caption(result.held_out_population, result.held_out_people)
        if world == HELD_OUT
        else "the MuJoCo UR5: each operator's first trials of the point-mass world, driven on the arm"
        if world == "mujoco"
        else f"{world} world"
    )
    caption = (
        f"Precision at the person's turns ({who}, arbitrated controller, {n} paired trials per object; "
        "shares of the oracle's benefit over MG with their 95 % bootstrap interval, and each training seed's for "
        "a learned source; left / right: the detour's side, right being the inside of the arc)"
    )
    header = [
        "object",
        "intent source",
        "f_RMS [N]",
        "force: share of oracle's saving",
        "overshoot left / right [mm]",
        "overshoot: share of oracle's reduction",
        "clearance deficit left / right [mm]",
        "jerk RMS [m/s³]",
        "σ [mm]",
        "told (besides what an arm measures)",
    ]
    return caption, header, rows


def ablation_section(result: AblationResult) -> Section:
    """The report's ablation section: every cell of both worlds, and the claims of issues 18 and 34."""
    s = Section("6. Which intent makes assistance better? The in-loop ablation (issues 18, 34)")
    # how many trainings of each LSTM ran (reproduce.source_seeds; "several" was said of one: a review, 2026-12-07)
    trainings = max(
        (
            len(result.seeds_of(w, o, c, src))
            for (w, o, c, src) in result.metrics
            if src in ("lstm-intent", "lstm-tool")
        ),
        default=1,
    )
    seeds = (
        f"each LSTM is trained with {trainings} seeds (the arbitrated controller runs every one)"
        if trainings > 1
        else "each LSTM is trained once"
    )
    s.paragraphs.append(
        "Each intent source drives the fixed-α and the arbitrated assistive controller (preset "
        f"'{result.preset}') on the application's trials, paired against MG on the same trials. The learned sources are "
        "trained from scratch on the same datasets by the same protocol; only what they learn to predict differs: the "
        f"tool's future pose (the thesis) or the simulated operator's true intent; {seeds}. 'present' estimates where "
        "the operator wants the tool now from the "
        "hand force; 'paths' adds path hypotheses round the obstacle the robot is told of, fitted to each operator's "
        "calibration trials. 'cooperative-damped' is the arbitrated controller with damping while the tool slows down. "
        "Share of the oracle's benefit = mean(MG − X) / mean(MG − oracle) over paired trials, with a 95 % bootstrap "
        "interval. Overshoot and clearance deficit (how much closer to the obstacle the tool passed than the operator "
        "meant) per side of the detour, as paired differences from MG with their 95 % intervals."
    )
    for world, why in result.skipped.items():
        s.paragraphs.append(f"The {world} world did not run: {why}.")
    drawn = sorted({(w, len({c[1] for c in labels})) for (w, _, _, _), labels in result.clusters.items()})
    if drawn:
        # the calibrations the cells' trials ran with (a run may fit more than its trials meet: the report had said
        # "calibrated that many times" of the ones met; a review, 2026-12-07)
        where = ", ".join(
            f"{cell_name(result, w)} (trials ran with {k} calibration{'s' if k != 1 else ''} of each operator)"
            for w, k in drawn
        )
        s.paragraphs.append(
            f"The person model's cells of {where}: each calibration on the operator's own probe trials, their trials "
            "going round the calibrations; the intervals of those cells resample the "
            "(operator, calibration) clusters whole, so they carry the calibration's own variance as well as the "
            "trials'. Their per-side differences from MG too: a t interval over those clusters (cluster-robust, "
            "G − 1 degrees of freedom), not over the trials."
        )
    asked = asked_in_calibrations(result.models, result.held_out_population)
    if asked:
        s.paragraphs.append(
            "Where an operator's probe trials showed a way round in fewer than "
            f"{FEW_PATHS} of them, their calibration asked them for a few more trials going that way "
            "(reproduce.person_calibration_asked; the paths join that way's, the ways' prior stays the operator's own "
            "choices): "
            + "; ".join(
                f"{where}, {n} of {fits} (operator, calibration) fits, {paths} trials asked"
                for where, (n, paths, fits) in asked.items()
            )
            + "."
        )
    if MUJOCO_PERSON in result.models:
        s.paragraphs.append(
            "On the MuJoCo UR5 the person model is calibrated on the arm it assists: each operator's probe trials "
            "(the point-mass cells' calibration trials, the same seeds) are driven there and fitted as in the "
            "point-mass world (reproduce.mujoco_person_calibration)."
        )
    for world in ABLATION_CELLS:
        rows = []
        for obj in OBJECTS:
            if (world, obj) not in result.mg:
                continue
            m = result.mg[(world, obj)]
            rows.append(
                [
                    obj,
                    "—",
                    "MG",
                    f"{m['f_rms']:.2f}",
                    f"{m['sigma'] * 1e3:.2f}",
                    f"{m['overshoot'] * 1e3:.1f}",
                    "",
                    "",
                    "",
                    "",
                    f"{m['jerk_rms']:.2f}",
                    f"{m['peak_effort_ratio']:.2f}",
                    "",
                    "",
                ]
            )
            for (w, ob, controller, source), r in result.metrics.items():
                if (w, ob) != (world, obj):
                    continue
                sh = result.shares(world, obj, controller, source)
                os_side = result.by_side(world, obj, controller, source, "overshoot")
                cd_side = result.by_side(world, obj, controller, source, "clearance_deficit")
                rows.append(
                    [
                        obj,
                        controller,
                        source,
                        f"{r['f_rms']:.2f}",
                        f"{r['sigma'] * 1e3:.2f}",
                        f"{r['overshoot'] * 1e3:.1f} ({paired_text(r['overshoot_trials'], m['overshoot_trials'], 1e3, 1)})",
                        _side_text(os_side[1]),
                        _side_text(os_side[-1]),
                        _side_text(cd_side[1]),
                        _side_text(cd_side[-1]),
                        f"{r['jerk_rms']:.2f}",
                        f"{r['peak_effort_ratio']:.2f}",
                        share_text(sh["f_rms"]),
                        share_text(sh["overshoot"]),
                    ]
                )
        if rows:
            n = len(result.pairs[(world, OBJECTS[0])])
            s.tables.append(
                (
                    f"{cell_name(result, world)} world, {n} paired trials per cell: f_RMS [N], σ [mm], overshoot past the intent [mm] (paired "
                    "difference from MG, 95 % interval), the same per side of the detour, the clearance deficit per side [mm], "
                    "jerk RMS [m/s³], peak robot/hand effort, share of the oracle's benefit",
                    [
                        "object",
                        "controller",
                        "intent source",
                        "f_RMS",
                        "σ",
                        "overshoot",
                        "overshoot, left",
                        "overshoot, right",
                        "clearance deficit, left",
                        "clearance deficit, right",
                        "jerk RMS",
                        "peak |u_r|/|u_h|",
                        "oracle share: force",
                        "oracle share: overshoot",
                    ],
                    rows,
                )
            )
    rows = []
    for (world, obj, controller, source), e in result.errors.items():
        if world == POINT_MASS and controller == ARBITRATED:
            rows.append(
                [source, obj]
                + [f"{1e3 * e[h]['tool']:.2f} / {1e3 * e[h]['intent']:.2f}" if h in e else "—" for h in EVAL_HORIZONS]
            )
    s.tables.append(
        (
            "What each source predicted in the loop (point-mass world, arbitrated controller): e_RMS [mm] against the tool's "
            "measured future pose / against the operator's true intent, per horizon",
            ["intent source", "object"] + [f"{h} samples" for h in EVAL_HORIZONS],
            rows,
        )
    )
    for obj in OBJECTS:
        for source in ("lstm-tool", "lstm-hand-alone", "lstm-intent"):
            key = (POINT_MASS, obj, ARBITRATED, source)
            if key not in result.metrics:
                continue
            sh = result.shares(*key)
            f, o = sh["f_rms"][0], sh["overshoot"][0]
            s.claims.append(
                Claim(
                    f"{obj}: the arbitrated controller with {source} in the loop gets ≥ {100 * ORACLE_SHARE_BAR:.0f} % of the "
                    "oracle's force saving and of its overshoot reduction over MG (issue 18's bar; point-mass world)",
                    bool(np.isfinite(f) and np.isfinite(o) and f >= ORACLE_SHARE_BAR and o >= ORACLE_SHARE_BAR),
                    f"force {share_text(sh['f_rms'], ORACLE_SHARE_BAR)}, overshoot "
                    f"{share_text(sh['overshoot'], ORACLE_SHARE_BAR)} of the oracle's benefit",
                    reason="a network on the hand force learns where the tool goes, not where the person wants it now: at a "
                    "turn it runs past it (docs/precision.md)",
                )
            )
    s.claims.extend(precision_claims(result))
    s.claims.extend(person_claims(result))
    s.claims.extend(default_claims(result))
    return s


#: The cells of the default's claims (:func:`default_claims`): (world, controller, the game in words). `drive`,
#: `ros2`, `play` and `collect` run the plain cooperative game by default; the study and the report's
#: application the arbitrated one.
DEFAULT_CELLS = (
    (POINT_MASS, "cooperative", "the plain cooperative game (drive's default)"),
    (POINT_MASS, ARBITRATED, "the arbitrated game"),
    (HELD_OUT, ARBITRATED, "the arbitrated game"),
    ("mujoco", ARBITRATED, "the arbitrated game"),
)


def _default_cell_world(world: str, result: AblationResult) -> str:
    """Where a cell of :data:`DEFAULT_CELLS` ran, in words: the held-out cells name the population they met
    (reproduce.held_out_population)."""
    if world == HELD_OUT:
        return f"{result.held_out_population} population"
    return {POINT_MASS: "point-mass world", "mujoco": "MuJoCo UR5"}[world]


def asked_in_calibrations(models: dict[str, str], population: str = HELD_OUT) -> dict[str, tuple[int, int, int]]:
    """Per person-model folder of ``models`` whose calibrations asked for a way (point-mass world, the held-out
    cells' ``population``, MuJoCo UR5):
    :func:`~coassist.scenario.calibration_draws.asked_paths`; a folder no longer there is left out."""
    from pathlib import Path

    from coassist.scenario.calibration_draws import DRAWS_FILE, asked_paths
    from coassist.scenario.person_model import PERSON_MODEL_FILE

    out = {}
    for label, where in (
        ("person", "point-mass world"),
        (HELD_OUT_PERSON, f"{population} population"),
        (MUJOCO_PERSON, "MuJoCo UR5"),
    ):
        folder = Path(models.get(label, ""))
        if label in models and ((folder / DRAWS_FILE).is_file() or (folder / PERSON_MODEL_FILE).is_file()):
            counts = asked_paths(folder)
            if counts[1]:
                out[where] = counts
    return out


def default_claims(result: AblationResult, source: str = DEFAULT_INTENT) -> list[Claim]:
    """Issue 40's goal for the intent source every world and command runs without a calibration
    (:data:`~coassist.scenario.assistance.DEFAULT_INTENT`): never more hand force nor more overshoot than MG in
    the application scenario. Per cell of :data:`DEFAULT_CELLS` where it ran, on both objects: the shares of the
    oracle's force saving and overshoot reduction above zero with their bootstrap lower bounds (less than MG,
    with an interval), and on each side of the detour a paired overshoot difference from MG ≤ 0."""
    claims = []
    for world, controller, game in DEFAULT_CELLS:
        where = f"{_default_cell_world(world, result)}, {game}"
        keys = [(world, obj, controller, source) for obj in OBJECTS]
        if not all(k in result.metrics for k in keys):
            continue
        ok, parts, thin = True, [], []
        for key in keys:
            sh = result.shares(*key)
            f_lo, o_lo = sh["f_rms"][1], sh["overshoot"][1]
            sides = result.by_side(*key, "overshoot")
            ok = ok and bool(np.isfinite(f_lo) and np.isfinite(o_lo) and f_lo > 0.0 and o_lo > 0.0)
            ok = ok and all(n >= 1 and np.isfinite(d) and d <= 0.0 for _, d, _, _, n in sides.values())
            if _thin_sides(sides, 1):
                thin.append(f"{key[1]}: {_thin_sides(sides, 1)}")
            parts.append(
                f"{key[1]}: force {share_text(sh['f_rms'], lower_bar=0.0, lower_strict=True)}, overshoot "
                f"{share_text(sh['overshoot'], lower_bar=0.0, lower_strict=True)} of the oracle's benefit; "
                + "; ".join(f"{SIDES[sd]} {_side_text(v, 'd')} mm vs MG" for sd, v in sides.items())
            )
        claims.append(
            Claim(
                f"{where}: without a calibration, every world's default ('{source}', the present estimate from the "
                "hand force, held) needs less hand force and overshoots less than MG on both objects (each share's "
                "bootstrap lower bound above 0) and no more than MG on either side of the detour (issue 40)",
                ok,
                "; ".join(parts),
                reason="; ".join(thin)
                or "it follows the hand rather than leading it, so what it saves varies from person to person "
                "and 24 trials leave a wide interval (docs/precision.md)",
            )
        )
    return claims


#: Issue 40's bars for the person model (arbitrated controller): (force share, overshoot share, its lower
#: bound, jerk against MG's) in the population it was developed on, and on the held-out population.
PERSON_BARS = {POINT_MASS: (0.85, 0.70, 0.40, 1.1), HELD_OUT: (0.80, 0.60, 0.30, None)}


def person_claims(result: AblationResult, source: str = "person") -> list[Claim]:
    """Issue 40's goals for the person model, per object, in the point-mass world and on the held-out
    population (where its cells ran): shares of the oracle's benefit, jerk, and per side no more
    overshoot than MG on the held-out population; then the MuJoCo UR5's direction (:func:`mujoco_person_claims`)."""
    claims = []
    for world, (force_bar, over_bar, lower_bar, jerk_bar) in PERSON_BARS.items():
        for obj in OBJECTS:
            key = (world, obj, ARBITRATED, source)
            if key not in result.metrics:
                continue
            sh = result.shares(*key)
            (f, _, _), (o, o_lo, _) = sh["f_rms"], sh["overshoot"]
            r, m = result.metrics[key], result.mg[(world, obj)]
            where = f"{result.held_out_population} population" if world == HELD_OUT else f"{world} world"
            ok = all(np.isfinite(v) for v in (f, o, o_lo)) and f >= force_bar and o >= over_bar and o_lo >= lower_bar
            jerk = r["jerk_rms"] / m["jerk_rms"]
            text = (
                f"force {share_text(sh['f_rms'], force_bar)}, overshoot {share_text(sh['overshoot'], over_bar, lower_bar)}; "
                f"jerk {shown(jerk, 2, jerk_bar, strict=True)}× MG"
            )
            reason = (
                "the way round is known only once the person has left the plan by more than the filter's dead zone, "
                "and the rows follow the person's own scatter of shapes (docs/precision.md)"
            )
            goal = (
                f"{obj}, {where}: the person model (learnt from each operator's probe trials, told no scene, family or "
                f"label) gets ≥ {100 * force_bar:.0f} % of the oracle's force saving and ≥ {100 * over_bar:.0f} % of its "
                f"overshoot reduction (lower bound ≥ {100 * lower_bar:.0f} %)"
            )
            if jerk_bar is not None:
                goal += f", jerk ≤ {jerk_bar:g} × MG's"
                ok = ok and jerk <= jerk_bar
            else:
                sides = result.by_side(*key, "overshoot")
                goal += ", and overshoots no more than MG on either side"
                ok = ok and all(n >= 1 and np.isfinite(d) and d <= 0.0 for _, d, _, _, n in sides.values())
                text += "; " + "; ".join(f"{SIDES[sd]} {_side_text(v, 'd')} mm vs MG" for sd, v in sides.items())
                # a side too thin to judge is one reason; where the shares miss their bars too, theirs is another
                # (the thin side alone was said of 69 % force and 6 % overshoot share: a review, 2026-12-07)
                thin = _thin_sides(sides, 1)
                met = (
                    all(np.isfinite(v) for v in (f, o, o_lo)) and f >= force_bar and o >= over_bar and o_lo >= lower_bar
                )
                reason = (thin if met else f"{thin}; and {reason}") if thin else reason
            claims.append(Claim(goal + " (issue 40)", bool(ok), text, reason=reason))
    return claims + mujoco_person_claims(result, source)


def mujoco_person_claims(result: AblationResult, source: str = "person") -> list[Claim]:
    """Issue 40's goal on the MuJoCo UR5, per object where its cells ran: the point-mass world's direction
    with an interval. The person model needs less hand force and overshoots less than MG on the same trials,
    each paired difference's 95 % upper bound below zero (:func:`~coassist.analysis.paired.paired_difference`);
    the evidence gives the shares of the oracle's benefit with their bootstrap intervals and the jerk."""
    claims = []
    for obj in OBJECTS:
        key = ("mujoco", obj, ARBITRATED, source)
        if key not in result.metrics:
            continue
        r, m = result.metrics[key], result.mg[("mujoco", obj)]
        sh = result.shares(*key)
        ok, parts = True, []
        for metric, unit, scale in (("f_rms", "N", 1.0), ("overshoot", "mm", 1e3)):
            d, lo, hi, n = paired_difference(r[f"{metric}_trials"], m[f"{metric}_trials"])
            ok = ok and bool(np.isfinite(hi) and hi < 0.0)
            what = "force" if metric == "f_rms" else "overshoot"
            # below two pairs there is no interval: the difference alone, and the claim does not hold
            interval = (
                f" [{scale * lo:+.2f}, {shown(scale * hi, 2, 0.0, signed=True)}]"
                if np.isfinite(lo)
                else ", no interval"
            )
            parts.append(
                f"{what} {share_text(sh[metric])} of the oracle's benefit, {scale * r[metric]:.2f} vs MG "
                f"{scale * m[metric]:.2f} {unit} ({scale * d:+.2f}{interval})"
            )
        parts.append(f"jerk {r['jerk_rms'] / m['jerk_rms']:.2f}× MG; {len(r['f_rms_trials'])} paired trials")
        claims.append(
            Claim(
                f"{obj}, MuJoCo UR5: the person model (calibrated from each operator's probe trials) needs less hand "
                "force and overshoots less than MG on the same trials, each paired difference's 95 % upper bound "
                "below zero (the point-mass world's direction, with an interval; issue 40)",
                ok,
                "; ".join(parts),
                reason="the arm's joint limits and the safety layer's filters delay the robot's effort, and fewer "
                "trials run on the arm than in the point-mass world",
            )
        )
    return claims


def precision_claims(result: AblationResult, source: str = APPLICATION_SOURCE) -> list[Claim]:
    """Issue 34's goals for ``source`` with the arbitrated controller in the point-mass world, per object
    (and the direction in the MuJoCo UR5's cells when they ran)."""
    claims = []
    for obj in OBJECTS:
        key = (POINT_MASS, obj, ARBITRATED, source)
        if key not in result.metrics:
            continue
        sh = result.shares(*key)
        (f, _, _), (o, o_lo, _) = sh["f_rms"], sh["overshoot"]
        claims.append(
            Claim(
                f"{obj}: with '{source}' the arbitrated controller gets ≥ {100 * FORCE_SHARE_BAR:.0f} % of the oracle's force "
                f"saving and ≥ {100 * OVERSHOOT_SHARE_BAR:.0f} % of its overshoot reduction over MG, the latter's bootstrap "
                f"lower bound ≥ {100 * SHARE_LOWER_BAR:.0f} % (issue 34)",
                bool(
                    np.isfinite(f)
                    and np.isfinite(o)
                    and np.isfinite(o_lo)
                    and f >= FORCE_SHARE_BAR
                    and o >= OVERSHOOT_SHARE_BAR
                    and o_lo >= SHARE_LOWER_BAR
                ),
                f"force {share_text(sh['f_rms'], FORCE_SHARE_BAR)}, overshoot "
                f"{share_text(sh['overshoot'], OVERSHOOT_SHARE_BAR, SHARE_LOWER_BAR)} of the oracle's benefit",
                reason="the side of the detour is known only some 0.1 s after it starts, and the person's shape varies from "
                "trial to trial: the robot follows the present estimate meanwhile",
            )
        )
        for metric, what in (
            ("overshoot", "overshoots the intent"),
            ("clearance_deficit", "passes closer to the obstacle"),
        ):
            sides = result.by_side(*key, metric)
            ok = all(n >= 2 and np.isfinite(hi) and hi <= 0.0 for _, _, _, hi, n in sides.values())
            claims.append(
                Claim(
                    f"{obj}: with '{source}' the arbitrated controller {what} no more than MG on either side of the detour "
                    "(paired difference's 95 % upper bound ≤ 0; issue 34)",
                    bool(ok),
                    "; ".join(f"{SIDES[sd]} {_side_text(v, 'hi')} mm vs MG" for sd, v in sides.items()),
                    reason=_thin_sides(sides, 2)
                    or (
                        "MG's heavy tool swings wide of the obstacle at the outside turn; a controller that follows the "
                        "intent closely passes nearer to it than MG does (the oracle too)"
                        if metric == "clearance_deficit"
                        else "where the side is decided late, the tool follows the old direction for a moment"
                    ),
                )
            )
        r, m = result.metrics[key], result.mg[(POINT_MASS, obj)]
        claims.append(
            Claim(
                f"{obj}: with '{source}' the arbitrated controller's jerk RMS is ≤ {JERK_BAR:g} × MG's (issue 34)",
                bool(r["jerk_rms"] <= JERK_BAR * m["jerk_rms"]),
                f"jerk RMS {r['jerk_rms']:.2f} vs MG {m['jerk_rms']:.2f} m/s³ ({shown(r['jerk_rms'] / m['jerk_rms'], 2, JERK_BAR, strict=True)}×)",
                reason="the rows change when the filter decides the side or the shape: the robot's effort changes with them",
            )
        )
    if all(("mujoco", obj, ARBITRATED, source) in result.metrics for obj in OBJECTS):
        parts, ok = [], True
        for obj in OBJECTS:
            r, m = result.metrics[("mujoco", obj, ARBITRATED, source)], result.mg[("mujoco", obj)]
            ok &= bool(r["f_rms"] < m["f_rms"] and r["overshoot"] <= m["overshoot"])
            parts.append(
                f"{obj}: f_RMS {r['f_rms']:.2f} vs MG {m['f_rms']:.2f} N, overshoot {1e3 * r['overshoot']:.1f} vs "
                f"MG {1e3 * m['overshoot']:.1f} mm"
            )
        claims.append(
            Claim(
                f"on the MuJoCo UR5, '{source}' with the arbitrated controller needs less force than MG and overshoots no more, "
                "on both objects (the point-mass result's direction; issue 34)",
                ok,
                "; ".join(parts),
                reason="the arm's joint limits and the safety layer's filters delay the robot's effort, and few trials run there",
            )
        )
    return claims
