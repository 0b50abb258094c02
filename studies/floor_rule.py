"""Apply the model-error floor's rule: a lower floor, judged on sets it was not chosen on.

:data:`bayesgloss.model_error.MODEL_ERROR_FLOOR` (0.06, stop 30) widens the
object's interval by a model error common to every facet. On the seen
holdouts 17-19 (Radiance) and Mitsuba holdouts 7-8 it held the truth in 57
of 57 Radiance sequences with direct sun (above issue 14's 85-97 %) and 35
of 39 Mitsuba ones. The candidate floor (``--floor``, 0.03 by the rule in
``studies/README.md``, "The model error's floor, and its rule (stop 56)")
was chosen on those sets; this script judges it on sets nobody had read
when the rule was written. A floor changes no fit: each score keeps the
object's posterior as 200 quantiles and each facet's posterior mean and sd,
so the candidate's interval is the default's posterior widened again
(:func:`model_error_floor.widened`, a fixed seed), and the default's is
the one it reported.

The rule's conditions, over each set's sequences with direct sun (the
sunless ones for (3)), sets of one renderer pooled:

(1) per renderer, the candidate's interval holds the truth in 85-97 % of
    the sequences, or no farther from 90 % than the default's does;
(2) pooled over every set, it holds the truth in at least 85 %;
(3) it passes the overcast rule on at least as many sunless sequences;
(4) its confident misses (the truth outside an interval narrower than 0.5)
    are at most 10 % of the sequences pooled (a right 90 % interval misses
    one time in ten, and almost every miss of a narrow interval is
    confident).

With ``--few-facets-floor F`` (stop 59's candidate, "Holdout 23 and
Mitsuba holdout 10: the floor by facet count" in ``studies/README.md``)
the candidate's floor is ``F`` where at most :data:`FEW_FACETS` facets
measured the object's gamma (the score's ``model_error.facets``: too few
for their disagreement to show the model's error) and ``--floor`` where
more did.

Stop 71's candidate (``--choose-more``, "Holdout 30 and Mitsuba holdout
16" in ``studies/README.md``): the floor 0.01 where more than
:data:`FEW_FACETS` facets measured gamma, 0.13 where fewer did, with a
condition (6) on the objects it acts on (``--more-facets-min 0.85``).

Usage::

    python studies/floor_rule.py --set mitsuba_holdout9 --set validation_holdout20 \\
        [--floor 0.03] [--few-facets-floor 0.06] [--cached] [--json FILE]

Scores come from the sets' committed results (:data:`validate_radiance.SETS`)
or, with ``--cached``, from their score caches (``studies/out/<set>/scores``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bayesgloss.model_error import FEW_FACETS

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from holdout_rule import load_set  # noqa: E402
from model_error_floor import widened  # noqa: E402
from validate_radiance import SETS, confident_miss, overcast_ok, reported_interval  # noqa: E402
from validate_radiance import _holds as holds  # noqa: E402

#: The candidate floor of the rule (studies/README.md, stop 56).
CANDIDATE_FLOOR = 0.03
#: Stop 59's candidate: objects whose gamma at most FEW_FACETS facets
#: measured (``bayesgloss.model_error``'s count) keep this floor
#: (``--few-facets-floor``); stop 62's took 0.13 and joined the default.
STOP59_FEW_FACETS_FLOOR = 0.06
#: The seed of the candidate's model-error draws.
SEED = 20261202
#: The band of issue 14 for a 90 % interval's coverage, and its centre.
BAND, NOMINAL = (0.85, 0.97), 0.90
#: Conditions (2) and (4).
POOLED_MIN, CONFIDENT_MISS_MAX = 0.85, 0.10
#: Stop 62's condition (5), where a few-facet floor is the candidate: the
#: sun-lit few-facet objects' pooled median width at most this [gamma].
FEW_WIDTH_MAX = 0.5
FIVE = "(5) few-facet objects' pooled median width at most 0.5"


def renderer(set_name: str) -> str:
    """``"mitsuba"`` for a Mitsuba set, else ``"radiance"``."""
    return "mitsuba" if "mitsuba" in set_name else "radiance"


def load_scores(set_name: str, cached: bool, method: str = "perez") -> list[dict]:
    """A set's scores holding ``method``, its entry as the default's (``perez``)
    (:func:`holdout_rule.load_set`)."""
    scores, _ = load_set(set_name, cached, (method, method))
    return [{**s, "perez": s[method]} for s in scores]


def measuring_facets(entry: dict) -> int:
    """How many facets measured the object's gamma in a score (its model
    error's ``facets``)."""
    return int(entry["model_error"]["facets"])


def with_floor(
    entry: dict, floor: float, rng: np.random.Generator, few_facets_floor: float | None = None
) -> dict:
    """The default's entry with its interval and median widened again at
    ``floor``, or at ``few_facets_floor`` (where given) if at most
    :data:`FEW_FACETS` facets measured it."""
    if few_facets_floor is not None and measuring_facets(entry) <= FEW_FACETS:
        floor = few_facets_floor
    q = widened(entry, floor, rng)
    return {**entry, **{k: q[k] for k in ("median", "q05", "q95", "hdi90")}}


def figures(rows: list[tuple[dict, float, bool]]) -> dict:
    """Coverage, confident misses, overcast rule, MAE and median width of
    (entry, truth, direct sun) rows."""
    sun = [(e, t) for e, t, d in rows if d]
    sunless = [(e, t) for e, t, d in rows if not d]
    held = int(sum(bool(holds(e, t)) for e, t in sun))
    return {
        "sun_lit": len(sun),
        "held": held,
        "coverage": held / len(sun) if sun else None,
        "confident_misses": int(sum(bool(confident_miss(e, t)) for e, t in sun)),
        "mae": float(np.mean([abs(e["median"] - t) for e, t in sun])) if sun else None,
        "median_width": float(np.median([np.ptp(reported_interval(e)) for e, _ in sun]))
        if sun
        else None,
        "sunless": len(sunless),
        "overcast_ok": int(sum(bool(overcast_ok(e, t)) for e, t in sunless)),
    }


def in_band(coverage: float) -> bool:
    return BAND[0] <= coverage <= BAND[1]


def decide(default: dict, candidate: dict, by_renderer: dict) -> dict:
    """Conditions (1)-(4) of the module docstring."""
    one = {
        r: bool(
            in_band(f["candidate"]["coverage"])
            or abs(f["candidate"]["coverage"] - NOMINAL) <= abs(f["default"]["coverage"] - NOMINAL)
        )
        for r, f in by_renderer.items()
    }
    out = {
        "(1) per renderer in 85-97 % or no farther from 90 %": one,
        "(2) pooled coverage at least 85 %": bool(candidate["coverage"] >= POOLED_MIN),
        "(3) overcast rule as often": bool(candidate["overcast_ok"] >= default["overcast_ok"]),
        "(4) confident misses at most 10 %": bool(
            candidate["confident_misses"] <= CONFIDENT_MISS_MAX * candidate["sun_lit"]
        ),
    }
    out["met"] = all(all(v.values()) if isinstance(v, dict) else v for v in out.values())
    return out


def _add_condition(decision: dict, name: str, ok: bool) -> None:
    """Add condition ``name`` to a :func:`decide` result, before its ``met``,
    and fold it into ``met``."""
    met = decision.pop("met")
    decision[name] = bool(ok)
    decision["met"] = met and decision[name]


def apply_rule(
    sets: dict[str, list[dict]],
    floor: float = CANDIDATE_FLOOR,
    few_facets_floor: float | None = None,
    more_facets_min: float | None = None,
) -> dict:
    """The rule on ``sets`` (set name to its scores); the candidate's floor
    :func:`with_floor`'s. ``more_facets_min``: stop 71's condition (6), the
    candidate's pooled coverage of the sun-lit objects whose gamma more than
    :data:`FEW_FACETS` facets measured at least this."""
    rng = np.random.default_rng(SEED)
    rows = {"default": {}, "candidate": {}}
    groups = {"default": {}, "candidate": {}}  # "<renderer>:<few|more>" and "<few|more>"
    for name, scores in sets.items():
        for s in scores:
            entry = s["perez"]
            if "object_quantiles" not in entry:
                raise ValueError(f"{name}: {s['bundle']} has no object quantiles to widen")
            row = (entry, s["truth"], s["direct_sun"])
            cand = (with_floor(entry, floor, rng, few_facets_floor), s["truth"], s["direct_sun"])
            group = "few" if measuring_facets(entry) <= FEW_FACETS else "more"
            for m, r in (("default", row), ("candidate", cand)):
                rows[m].setdefault(renderer(name), []).append(r)
                for key in (f"{renderer(name)}:{group}", group):
                    groups[m].setdefault(key, []).append(r)
    by_renderer = {
        r: {m: figures(rows[m][r]) for m in ("default", "candidate")} for r in rows["default"]
    }
    pooled = {m: figures([x for v in rows[m].values() for x in v]) for m in rows}
    by_group = {
        key: {m: figures(groups[m][key]) for m in groups} for key in sorted(groups["default"])
    }
    decision = decide(pooled["default"], pooled["candidate"], by_renderer)
    if few_facets_floor is not None:  # stop 62's rule adds (5)
        few = by_group.get("few", {}).get("candidate", {}).get("median_width")
        _add_condition(decision, FIVE, few is not None and few <= FEW_WIDTH_MAX)
    if more_facets_min is not None:  # stop 71's rule adds (6)
        more = by_group.get("more", {}).get("candidate", {}).get("coverage")
        six = f"(6) objects of more facets: pooled coverage at least {more_facets_min:.0%}"
        _add_condition(decision, six, more is not None and more >= more_facets_min)
    return {
        "floor": floor,
        "few_facets_floor": few_facets_floor,
        "few_facets": FEW_FACETS,
        "sets": {name: len(scores) for name, scores in sets.items()},
        "by_renderer": by_renderer,
        "pooled": pooled,
        "by_facet_group": by_group,
        "decision": decision,
    }


#: The seen sets the candidate floor was chosen on, each with the method
#: that was the default when it was read (stop 56).
SEEN = {
    "validation_holdout17": "perez",
    "validation_holdout18": "within-10",
    "validation_holdout19": "perez",
    "mitsuba_holdout7": "perez",
    "mitsuba_holdout8": "within-10",
}
#: The floors tried [gamma], the 0.005 grid of ``model_error_floor.py`` up to 0.08.
GRID = np.round(np.arange(0.0, 0.0801, 0.005), 3)


def choose_floor(sets: dict[str, list[dict]] | None = None) -> dict:
    """The candidate floor: the middle of the floors of :data:`GRID` at which,
    on the seen sets (:data:`SEEN`, sun-lit sequences), each renderer's
    coverage lies in 85-97 % and the pooled one is at least 90 %; with the
    coverage of every floor tried."""
    if sets is None:
        sets = seen_sun_lit(SEEN)
    table = {}
    for floor in GRID:
        out = apply_rule(sets, float(floor))["by_renderer"]
        cov = {r: f["candidate"]["coverage"] for r, f in out.items()}
        n = {r: f["candidate"]["sun_lit"] for r, f in out.items()}
        pooled = sum(cov[r] * n[r] for r in cov) / sum(n.values())
        table[float(floor)] = {**cov, "pooled": pooled}
    good = [f for f, c in table.items() if all(in_band(c[r]) for r in c if r != "pooled")]
    good = [f for f in good if table[f]["pooled"] >= NOMINAL]
    chosen = round(float(np.mean([min(good), max(good)])) / 0.005) * 0.005 if good else None
    return {"table": table, "qualifying": good, "chosen": chosen}


#: The seen sets stop 59's candidate was found on (sun-lit sequences), each
#: with the method that was the default when it was read.
SEEN_STOP59 = {
    **SEEN,
    "validation_holdout20": "perez",
    "validation_holdout22": "sun-side-overcast",
    "mitsuba_holdout9": "perez",
}
#: (floor where at most FEW_FACETS facets measured, floor where more did)
#: pairs tabulated by :func:`by_facet_count`.
FACET_FLOORS = ((0.06, 0.06), (0.0, 0.0), (0.03, 0.03), (0.06, 0.02), (0.06, 0.03), (0.06, 0.04))


def seen_sun_lit(seen: dict[str, str]) -> dict[str, list[dict]]:
    """The sun-lit scores of seen sets (set name to the method that was the
    default when it was read), that method's entry as the default's."""
    return {
        name: [r for r in load_scores(name, False, method) if r["direct_sun"]]
        for name, method in seen.items()
    }


def floored_cells(sets: dict[str, list[dict]], floor: float, few_facets_floor: float, keys) -> dict:
    """(entry, truth, direct sun) rows of the scores of ``sets``, each entry
    widened by :func:`with_floor` (one generator seeded :data:`SEED`, drawn in
    the sets' order), filed under every key of ``keys(set name, group)``
    (group ``"few"`` where at most :data:`FEW_FACETS` facets measured gamma,
    else ``"more"``); a score with no key is not widened."""
    rng = np.random.default_rng(SEED)
    cells = {}
    for name, scores in sets.items():
        for s in scores:
            group = "few" if measuring_facets(s["perez"]) <= FEW_FACETS else "more"
            filed = keys(name, group)
            if not filed:
                continue
            entry = with_floor(s["perez"], floor, rng, few_facets_floor)
            row = (entry, s["truth"], s["direct_sun"])
            for key in filed:
                cells.setdefault(key, []).append(row)
    return cells


def by_facet_count(sets: dict[str, list[dict]] | None = None) -> dict:
    """:func:`figures` of the sun-lit reported intervals, per
    renderer and per group (at most :data:`FEW_FACETS` measuring facets, or
    more), for each pair of floors of :data:`FACET_FLOORS`, on the seen
    sets of :data:`SEEN_STOP59` (stop 59's lead, ``--by-facets``)."""
    if sets is None:
        sets = seen_sun_lit(SEEN_STOP59)

    def keys(name, group):
        return (f"{renderer(name)}:{group}", renderer(name))

    table = {}
    for few_floor, floor in FACET_FLOORS:
        cells = floored_cells(sets, floor, few_floor, keys)
        table[f"{few_floor}/{floor}"] = {key: figures(rows) for key, rows in sorted(cells.items())}
    return {"sets": {k: len(v) for k, v in sets.items()}, "few_facets": FEW_FACETS, "table": table}


#: The seen sets of stop 62's candidate (few-facet floor): stop 59's, and
#: the holdouts read since, each with the method that was the default when
#: it was read (``lobes-every-sky`` for holdout 24 and Mitsuba holdout 11).
SEEN_STOP62 = {
    **SEEN_STOP59,
    "validation_holdout23": "perez",
    "mitsuba_holdout10": "perez",
    "validation_holdout24": "lobes-every-sky",
    "mitsuba_holdout11": "lobes-every-sky",
}
#: The few-facet floors tried [gamma] (the floor elsewhere stays the default's).
FEW_GRID = np.round(np.arange(0.06, 0.2001, 0.01), 2)
#: Stop 62's criterion: the pooled few-facet coverage the floor must reach.
FEW_COVERAGE = 0.90


def choose_few_facets_floor(sets: dict[str, list[dict]] | None = None) -> dict:
    """Stop 62's candidate: the smallest floor of :data:`FEW_GRID` at which
    the sun-lit objects whose gamma at most :data:`FEW_FACETS` facets
    measured, pooled over both renderers' seen sets (:data:`SEEN_STOP62`),
    hold the truth in at least :data:`FEW_COVERAGE`; with each floor's
    :func:`figures` per renderer and pooled (``--choose-few``)."""
    if sets is None:
        sets = seen_sun_lit(SEEN_STOP62)
    table = {}
    for few_floor in FEW_GRID:  # only objects of few facets are filed, each at few_floor
        cells = floored_cells(
            sets,
            few_floor,
            few_floor,
            lambda name, group: (renderer(name), "pooled") if group == "few" else (),
        )
        table[float(few_floor)] = {key: figures(rows) for key, rows in sorted(cells.items())}
    good = [f for f, c in table.items() if c["pooled"]["coverage"] >= FEW_COVERAGE]
    return {
        "sets": {k: len(v) for k, v in sets.items()},
        "table": table,
        "chosen": min(good) if good else None,
    }


#: Stop 71's seen pools for the floor where more than FEW_FACETS facets
#: measured gamma: every mixed set scored since stop 55 with its default of
#: the day (the broad pool), and those scored with today's default but for
#: stop 70's sunless change (the current pool; holdout 27 and Mitsuba
#: holdout 15 are sunless, so none of their objects is filed).
SEEN_STOP71_BROAD = {
    name: "perez"
    for name in (
        "validation_holdout19", "validation_holdout20", "validation_holdout23",
        "validation_holdout25", "validation_holdout26", "validation_holdout28",
        "mitsuba_holdout9", "mitsuba_holdout10", "mitsuba_holdout12",
        "mitsuba_holdout13", "mitsuba_holdout14",
    )
}  # fmt: skip
SEEN_STOP71_CURRENT = {
    name: "perez"
    for name in (
        "validation_holdout26", "validation_holdout28", "mitsuba_holdout13", "mitsuba_holdout14"
    )
}  # fmt: skip
#: Stop 71's criterion: the coverage the many-facet objects must reach in both pools.
MORE_COVERAGE = 0.90


def choose_more_facets_floor(pools: dict[str, dict] | None = None) -> dict:
    """Stop 71's candidate: the smallest floor of :data:`GRID` at which the
    sun-lit objects whose gamma more than :data:`FEW_FACETS` facets measured
    hold the truth in at least :data:`MORE_COVERAGE` pooled over both
    renderers, in the broad seen pool and in the current one alike
    (:data:`SEEN_STOP71_BROAD`, :data:`SEEN_STOP71_CURRENT`); with each
    floor's :func:`figures` per renderer and pooled (``--choose-more``)."""
    if pools is None:
        pools = {
            "broad": seen_sun_lit(SEEN_STOP71_BROAD),
            "current": seen_sun_lit(SEEN_STOP71_CURRENT),
        }

    def keys(name, group):
        return (renderer(name), "pooled") if group == "more" else ()

    table = {}
    for floor in GRID:
        table[float(floor)] = {
            pool: {
                key: figures(rows)
                for key, rows in sorted(floored_cells(sets, floor, None, keys).items())
            }
            for pool, sets in pools.items()
        }
    good = [
        f
        for f, c in table.items()
        if all(c[pool]["pooled"]["coverage"] >= MORE_COVERAGE for pool in pools)
    ]
    return {
        "pools": {pool: {k: len(v) for k, v in sets.items()} for pool, sets in pools.items()},
        "table": table,
        "chosen": min(good) if good else None,
    }


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", action="append", default=[], choices=sorted(SETS))
    ap.add_argument("--floor", type=float, default=CANDIDATE_FLOOR)
    ap.add_argument(
        "--few-facets-floor",
        type=float,
        help=f"the candidate's floor where at most {FEW_FACETS} facets measured gamma",
    )
    ap.add_argument("--cached", action="store_true", help="scores from studies/out/<set>/scores")
    ap.add_argument("--json", help="write the result here")
    ap.add_argument(
        "--choose", action="store_true", help="print how the candidate floor was chosen (SEEN)"
    )
    ap.add_argument(
        "--by-facets",
        action="store_true",
        help="tabulate the floors by facet count on the seen sets (SEEN_STOP59)",
    )
    ap.add_argument(
        "--choose-few",
        action="store_true",
        help="print how stop 62's few-facet floor was chosen (SEEN_STOP62)",
    )
    ap.add_argument(
        "--choose-more",
        action="store_true",
        help="print how stop 71's floor for more facets was chosen (SEEN_STOP71_*)",
    )
    ap.add_argument(
        "--more-facets-min",
        type=float,
        help="stop 71's condition (6): the pooled coverage objects of more facets must reach",
    )
    args = ap.parse_args(argv)
    if args.choose_more:
        out = choose_more_facets_floor()
    elif args.choose_few:
        out = choose_few_facets_floor()
    elif args.by_facets:
        out = by_facet_count()
    elif args.choose:
        out = choose_floor()
    else:
        sets = {name: load_scores(name, args.cached) for name in args.set}
        out = apply_rule(sets, args.floor, args.few_facets_floor, args.more_facets_min)
    return report(out, args.json)


def report(out: dict, path: str | None) -> dict:
    """Print a rule's result as JSON, and write it to ``path`` where given."""
    print(json.dumps(out, indent=1))
    if path:
        Path(path).write_text(json.dumps(out, indent=1) + "\n")
    return out


if __name__ == "__main__":
    main()
