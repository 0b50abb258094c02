"""A model-error floor where the sun is not identified: chosen on seen sets, judged on unseen ones.

Where more than half an object's frames have a sun that the data do not
identify (:func:`bayesgloss.joint_estimate.sun_flags`, the flag
``sun-not-identifiable``), its gamma rests on the sky's shape alone: on
sunless days nearly always, on some sun-lit ones. The facets then agree
on whatever the sky model makes them read, so their disagreement (the
model error's tau, :mod:`bayesgloss.model_error`) does not show a wrong
sky, and on the seen sets the intervals of such objects held the truth
less often than 90 % (stop 63, ``sun_flag_seen.py``). Stop 64's
candidate:

- a model-error floor of at least :data:`CANDIDATE_SUN_FLOOR` for an
  object flagged ``sun-not-identifiable`` (the default's floor,
  :func:`bayesgloss.model_error.model_error_floor`, where that is larger);
- the object's flag ``gloss-not-identifiable`` where its reported interval,
  model error included, is wider than ``estimate.NOT_IDENTIFIABLE_WIDTH``
  (0.6): an answer that wide does not tell gloss, whichever part of the
  model made it so (today the flag looks at the within-model interval only).

:func:`choose_sun_floor` picks the floor on the seen sets
(:data:`sun_flag_seen.SEEN_STOP63`) by a criterion fixed before any floor
was tried: the smallest floor of :data:`GRID` at which the flagged
objects' intervals (sun-lit and sunless, both renderers pooled) hold the
truth in at least 90 %. :func:`apply_rule` judges the candidate on sets
read after it was written, by the conditions of ``studies/README.md``
("Stop 64, a rule: a wider floor where the sun is not identified"):

(1)-(4) as :mod:`floor_rule`'s, over the sun-lit sequences (the default's
        floor unchanged where the object is not flagged);
(5) the flagged objects' intervals, sun-lit and sunless pooled over both
    renderers, hold the truth in 85-97 % or no farther from 90 % than the
    default's;
(6) the overcast rule passes on more sunless sequences than the default's.

Not met on holdout 26 and Mitsuba holdout 13 by (5) alone (10 of 10 flagged
objects held, the default 9); its second and last test (``--second``)
adds holdout 27's sunless days and asks (5), (6) and (7): the sunless
days' MAE at most :data:`SUNLESS_MAE_RISE` above the default's.

A floor changes no fit: each score keeps the object's posterior as 200
quantiles and each facet's posterior mean and sd (:func:`model_error_floor.widened`).

Usage::

    python studies/sun_floor_rule.py --choose [--json FILE]
    python studies/sun_floor_rule.py --set validation_holdout26 --set mitsuba_holdout13 \\
        [--set validation_holdout27 --second] [--json FILE]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from bayesgloss.estimate import NOT_IDENTIFIABLE_WIDTH
from bayesgloss.joint_estimate import SUN_UNIDENTIFIED_SHARE
from bayesgloss.model_error import model_error_floor

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from floor_rule import (  # noqa: E402
    NOMINAL,
    decide,
    figures,
    in_band,
    load_scores,
    measuring_facets,
    renderer,
    report,
)
from model_error_floor import widened  # noqa: E402
from sun_flag_seen import SEEN_STOP63, unidentified_share  # noqa: E402
from sun_flag_seen import figures as cell_figures  # noqa: E402
from validate_radiance import _holds as holds  # noqa: E402
from validate_radiance import reported_interval  # noqa: E402

#: Stop 64's candidate floor [gamma] where the sun is not identified, as
#: :func:`choose_sun_floor` gives it on the seen sets.
CANDIDATE_SUN_FLOOR = 0.20
#: The floors tried [gamma].
GRID = np.round(np.arange(0.06, 0.4001, 0.01), 2)
#: Coverage the flagged objects must reach on the seen sets.
COVERAGE = 0.90
#: The seed of the candidate's model-error draws.
SEED = 20261204


def sun_unidentified(entry: dict) -> bool:
    """Whether a score's object is flagged ``sun-not-identifiable``."""
    share = unidentified_share(entry)
    return share is not None and share > SUN_UNIDENTIFIED_SHARE


def with_flag_by_width(entry: dict) -> dict:
    """The entry with ``gloss-not-identifiable`` among its flags where its
    reported interval is wider than ``NOT_IDENTIFIABLE_WIDTH``."""
    flags = list(entry.get("flags", []))
    wide = np.ptp(reported_interval(entry)) > NOT_IDENTIFIABLE_WIDTH
    if wide and "gloss-not-identifiable" not in flags:
        flags.append("gloss-not-identifiable")
    return {**entry, "flags": flags}


def candidate(entry: dict, sun_floor: float, rng: np.random.Generator) -> dict:
    """The candidate's entry: widened again at ``sun_floor`` (or the
    default's floor where larger) if the object's sun is not identified,
    the default's otherwise; flagged by width (:func:`with_flag_by_width`)."""
    if sun_unidentified(entry):
        floor = max(sun_floor, model_error_floor(measuring_facets(entry)))
        q = widened(entry, floor, rng)
        entry = {**entry, **{k: q[k] for k in ("median", "q05", "q95", "hdi90")}}
    return with_flag_by_width(entry)


def _seen_scores(names=SEEN_STOP63) -> list[dict]:
    """The seen sets' scores that keep each frame's sun."""
    out = []
    for name in names:
        try:
            scores = load_scores(name, False)
        except (FileNotFoundError, KeyError):
            continue
        out += [s for s in scores if s["truth"] is not None and "sun_q05" in s["perez"]]
    return out


def choose_sun_floor(scores=None) -> dict:
    """The candidate floor on the seen sets: the smallest of :data:`GRID` at
    which the flagged objects' intervals hold the truth in at least
    :data:`COVERAGE`; with each floor's coverage."""
    scores = _seen_scores() if scores is None else scores
    flagged = [s for s in scores if sun_unidentified(s["perez"])]
    table = {}
    for floor in GRID:
        rng = np.random.default_rng(SEED)
        held = [bool(holds(candidate(s["perez"], float(floor), rng), s["truth"])) for s in flagged]
        table[float(floor)] = float(np.mean(held))
    good = [f for f, c in table.items() if c >= COVERAGE]
    return {"flagged": len(flagged), "table": table, "chosen": min(good) if good else None}


def apply_rule(sets: dict[str, list[dict]], sun_floor: float = CANDIDATE_SUN_FLOOR) -> dict:
    """The rule of the module docstring on ``sets`` (set name to scores)."""
    rng = np.random.default_rng(SEED)
    rows = {"default": {}, "candidate": {}}
    flagged = {"default": [], "candidate": []}
    for name, scores in sets.items():
        r = renderer(name)
        for s in scores:
            entry = s["perez"]
            pair = {"default": entry, "candidate": candidate(entry, sun_floor, rng)}
            for m, e in pair.items():
                row = (e, s["truth"], s["direct_sun"])
                rows[m].setdefault(r, []).append(row)
                if sun_unidentified(entry):
                    flagged[m].append(row)
    by_renderer = {
        r: {m: figures(rows[m][r]) for m in ("default", "candidate")} for r in rows["default"]
    }
    pooled = {m: figures([x for v in rows[m].values() for x in v]) for m in rows}
    cover = {m: cell_figures([(e, t) for e, t, _ in v]) for m, v in flagged.items()}
    decision = decide(pooled["default"], pooled["candidate"], by_renderer)
    met = decision.pop("met")
    cov = {m: c["held"] / c["n"] if c["n"] else None for m, c in cover.items()}
    five = cov["candidate"] is not None and (
        in_band(cov["candidate"])
        or abs(cov["candidate"] - NOMINAL) <= abs(cov["default"] - NOMINAL)
    )
    decision["(5) flagged objects' coverage in 85-97 % or no farther from 90 %"] = bool(five)
    six = pooled["candidate"]["overcast_ok"] > pooled["default"]["overcast_ok"]
    decision["(6) overcast rule on more sunless sequences"] = bool(six)
    decision["met"] = bool(met and five and six)
    sunless = {
        m: [abs(e["median"] - t) for v in rows[m].values() for e, t, d in v if not d] for m in rows
    }
    sunless_mae = {m: float(np.mean(v)) if v else None for m, v in sunless.items()}
    return {
        "sun_floor": sun_floor,
        "sets": {name: len(scores) for name, scores in sets.items()},
        "by_renderer": by_renderer,
        "pooled": pooled,
        "sun_not_identified": cover,
        "sunless_mae": sunless_mae,
        "decision": decision,
    }


#: Condition (7) of the second test: the sunless days' MAE may rise by at
#: most this much [gamma].
SUNLESS_MAE_RISE = 0.01


def second_test(out: dict) -> dict:
    """The second and last test (studies/README, "Holdout 27"): conditions
    (5) and (6) of :func:`apply_rule`'s ``out`` and (7) the sunless days'
    MAE at most :data:`SUNLESS_MAE_RISE` above the default's."""
    d = out["decision"]
    mae = out["sunless_mae"]
    seven = mae["candidate"] <= mae["default"] + SUNLESS_MAE_RISE
    keys = [k for k in d if k.startswith(("(5)", "(6)"))]
    res = {k: d[k] for k in keys}
    res["(7) sunless MAE at most 0.01 above the default's"] = bool(seven)
    res["met"] = bool(all(res.values()))
    return res


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--sun-floor", type=float, default=CANDIDATE_SUN_FLOOR)
    ap.add_argument("--choose", action="store_true", help="choose the floor on SEEN_STOP63")
    ap.add_argument("--second", action="store_true", help="the second test's conditions (5)-(7)")
    ap.add_argument("--json", help="write the result here")
    args = ap.parse_args(argv)
    if args.choose:
        out = choose_sun_floor()
    else:
        out = apply_rule({n: load_scores(n, False) for n in args.set}, args.sun_floor)
        if args.second:
            out["second_test"] = second_test(out)
    return report(out, args.json)


if __name__ == "__main__":
    main()
