"""Apply a holdout's rule: does a candidate method beat the default on sets it never saw?

Every change to the default since stop 40 was judged by a rule written in
``studies/README.md`` before its sets were drawn. The rule's conditions
are always the same five, over the sets' sun-lit sequences pooled (the
sunless ones for (d), all for (e)):

(a) the candidate's object MAE is lower than the default's, and on no set
    more than ``--set-tolerance`` (0.01) higher;
(b) its reported 90 % interval holds the truth at least as often;
(c) it makes no more confident misses (the truth outside a reported
    interval narrower than 0.5);
(d) it passes the overcast rule (within 0.05 of the truth, or flagged
    ``gloss-not-identifiable`` with an interval wider than 0.5) on at
    least as many sunless sequences;
(e) its median seconds a sequence over all sequences are at most
    ``--speed-limit`` (1.25) times the default's.

A rule about sunless days alone (holdout 21's, ``--sunless``) has its own
five, over the sets' sunless sequences pooled (:func:`sunless_rule`): (a)
the overcast rule passes on at least as many; (b) the reported 90 %
interval holds the truth on at least as many; (c) no more confident
misses; (d) the MAE at most ``--mae-tolerance`` (0.02) above the
default's; (e) median seconds at most ``--speed-limit`` times the
default's (2 in that rule).

A rule's own condition (f), a named test passing on the candidate, is run
by hand. Reported beside the rule, as every rule asks: per set, per
material class, per sky type, per facet count (1-3, more) and
``not-converged``; the median width of the reported intervals; and the
sequences the candidate fitted (not copied from the default) on their
own, per set and class, with each lobe family's weight and MAE there.

A sequence counts only where both methods scored it, and the script says
how many each set has of how many bundles, so a rule is never read on a
set scored part way without saying so.

Usage::

    python studies/holdout_rule.py --set validation_holdout16 \\
        --default perez --candidate ground-shadow [--cached] [--json FILE]

Scores come from the set's committed results (``studies/results/<set>.json``,
:data:`validate_radiance.SETS`) or, with ``--cached``, from its score cache
(``studies/out/<set>/scores/``, where ``validate_radiance.py --merge`` put
the candidate's). ``--set`` may be repeated: the rule pools the sets.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

# the same tests of a score as validate_radiance's tables
from validate_radiance import SETS, confident_miss, overcast_ok, reported_interval  # noqa: E402
from validate_radiance import _holds as holds  # noqa: E402


def facet_count(score: dict) -> str:
    """The facet-count group a score is reported in."""
    return "1-3 facets" if score["facets"] <= 3 else "more than 3"


def answer_figures(rows: list[dict], method: str) -> dict:
    """A method's answers on ``rows`` against their truths: MAE, median width
    of the reported interval, held, and confident misses (the bundles' first
    four characters); None for the MAE and width of no rows."""
    err = [abs(s[method]["median"] - s["truth"]) for s in rows]
    widths = [np.ptp(reported_interval(s[method])) for s in rows]
    return {
        "mae": float(np.mean(err)) if err else None,
        "median_width": float(np.median(widths)) if widths else None,
        "held": sum(holds(s[method], s["truth"]) for s in rows),
        "confident_misses": [
            s["bundle"][:4] for s in rows if confident_miss(s[method], s["truth"])
        ],
    }


def method_figures(scores: list[dict], method: str) -> dict:
    """A method's figures on ``scores``: :func:`answer_figures` of the sun-lit
    sequences, the overcast rule on the sunless, median seconds and
    ``not-converged``."""
    sun = [s for s in scores if s["direct_sun"]]
    sunless = [s for s in scores if not s["direct_sun"]]
    return {
        "sun_lit": len(sun),
        **answer_figures(sun, method),
        "sunless": len(sunless),
        "overcast_ok": sum(overcast_ok(s[method], s["truth"]) for s in sunless),
        "median_seconds": float(np.median([s[method]["seconds"] for s in scores]))
        if scores
        else None,
        "not_converged": sum("not-converged" in s[method].get("flags", []) for s in scores),
    }


def candidate_fit(score: dict, candidate: str) -> str:
    """Whether the candidate fitted this sequence or copied the default's
    answer (``validate_radiance.py --candidate`` marks a copy
    ``same_fit_as``): only the fitted ones can move."""
    return "copied" if score[candidate].get("same_fit_as") else "fitted"


def rule(
    sets: dict[str, list[dict]],
    default: str,
    candidate: str,
    *,
    set_tolerance: float = 0.01,
    speed_limit: float = 1.25,
) -> dict:
    """Conditions (a)-(e) of the module docstring, pooled over ``sets`` (name:
    scores holding both methods), with each set's figures beside them."""
    pooled, d, c, ratio = _pooled(sets, (default, candidate), method_figures)
    fitted = fitted_by_set_and_class(sets, candidate)
    per_set = {
        name: {m: method_figures(scores, m) for m in (default, candidate)}
        for name, scores in sets.items()
    }
    worse = [
        name
        for name, fig in per_set.items()
        if fig[default]["mae"] is not None
        and fig[candidate]["mae"] > fig[default]["mae"] + set_tolerance
    ]
    conditions = {
        "a": d["mae"] is not None and c["mae"] < d["mae"] and not worse,
        "b": c["held"] >= d["held"],
        "c": len(c["confident_misses"]) <= len(d["confident_misses"]),
        "d": c["overcast_ok"] >= d["overcast_ok"],
        "e": ratio is not None and ratio <= speed_limit,
    }
    return {
        "default": default,
        "candidate": candidate,
        "pooled": {default: d, candidate: c},
        "speed_ratio": ratio,
        "sets_more_than_tolerance_worse": worse,
        "conditions": conditions,
        "met": all(conditions.values()),
        "per_set": per_set,
        "beside": {
            key: {
                group: {m: method_figures(rows, m) for m in (default, candidate)}
                for group, rows in groups.items()
            }
            for key, groups in (
                ("class", _groups(pooled, lambda s: s.get("class") or "none")),
                ("sky type", _groups(pooled, lambda s: s["category"])),
                ("facet count", _groups(pooled, facet_count)),
                ("candidate's fit", _groups(pooled, lambda s: candidate_fit(s, candidate))),
                ("fitted, per set and class", fitted),
            )
        },
        "lobe_families": lobe_family_figures(fitted, (default, candidate)),
    }


def _pooled(sets: dict[str, list[dict]], methods: tuple[str, str], figures) -> tuple:
    """The sets' scores pooled, ``figures`` of the default and the candidate
    on them, and the ratio of their median seconds."""
    pooled = [s for scores in sets.values() for s in scores]
    d, c = (figures(pooled, m) for m in methods)
    ratio = c["median_seconds"] / d["median_seconds"] if d["median_seconds"] else None
    return pooled, d, c, ratio


def sunless_figures(scores: list[dict], method: str) -> dict:
    """A method's figures on the sunless sequences of ``scores``: the overcast
    rule, :func:`answer_figures` and median seconds."""
    days = [s for s in scores if not s["direct_sun"]]
    return {
        "sunless": len(days),
        "overcast_ok": sum(overcast_ok(s[method], s["truth"]) for s in days),
        **answer_figures(days, method),
        "median_seconds": float(np.median([s[method]["seconds"] for s in days])) if days else None,
    }


def sunless_rule(
    sets: dict[str, list[dict]],
    default: str,
    candidate: str,
    *,
    mae_tolerance: float = 0.02,
    speed_limit: float = 2.0,
) -> dict:
    """The sunless rule's conditions (a)-(e) (module docstring), pooled over
    the sunless sequences of ``sets``, with each sequence's answers beside."""
    pooled, d, c, ratio = _pooled(sets, (default, candidate), sunless_figures)
    conditions = {
        "a": c["overcast_ok"] >= d["overcast_ok"],
        "b": c["held"] >= d["held"],
        "c": len(c["confident_misses"]) <= len(d["confident_misses"]),
        "d": d["mae"] is not None and c["mae"] <= d["mae"] + mae_tolerance,
        "e": ratio is not None and ratio <= speed_limit,
    }
    days = [
        {
            "bundle": s["bundle"],
            "sky": s.get("sky"),
            "class": s.get("class"),
            "facets": s.get("facets"),
            "truth": s["truth"],
            **{
                m: {
                    "median": s[m]["median"],
                    "interval": [float(x) for x in reported_interval(s[m])],
                    "overcast_ok": bool(overcast_ok(s[m], s["truth"])),
                    "most_weight": (s[m].get("sky_families") or {}).get("most_weight"),
                }
                for m in (default, candidate)
            },
        }
        for s in pooled
        if not s["direct_sun"]
    ]
    return {
        "default": default,
        "candidate": candidate,
        "pooled": {default: d, candidate: c},
        "speed_ratio": ratio,
        "conditions": conditions,
        "met": all(conditions.values()),
        "days": days,
    }


def fitted_by_set_and_class(sets: dict[str, list[dict]], candidate: str) -> dict:
    """The sequences the candidate fitted (:func:`candidate_fit`), grouped
    as ``"<set>, <class>"``, in order."""
    out: dict[str, list[dict]] = {}
    for name, scores in sets.items():
        for s in scores:
            if candidate_fit(s, candidate) == "fitted":
                out.setdefault(f"{name}, {s.get('class') or 'none'}", []).append(s)
    return dict(sorted(out.items()))


def lobe_family_figures(fitted: dict[str, list[dict]], methods: tuple[str, str]) -> dict:
    """Per group of :func:`fitted_by_set_and_class`, over its sun-lit
    sequences where both ``methods`` stacked lobe families: each family's
    median weight, and the MAE of its own fit's object gamma, for each
    method (what a rule about one lobe family reports beside it)."""
    out: dict[str, dict] = {}
    for group, scores in fitted.items():
        rows = [
            s for s in scores if s["direct_sun"] and all(s[m].get("lobe_families") for m in methods)
        ]
        if not rows:
            continue
        out[group] = {"n": len(rows)}
        for m in methods:
            families = dict.fromkeys(f for s in rows for f in s[m]["lobe_families"])
            out[group][m] = {}
            for family in families:
                fits = [
                    (s[m]["lobe_families"][family], s["truth"])
                    for s in rows
                    if family in s[m]["lobe_families"]
                ]
                out[group][m][family] = {
                    "median_weight": float(np.median([fit["weight"] for fit, _ in fits])),
                    "mae": float(np.mean([abs(fit["gamma"]["median"] - t) for fit, t in fits])),
                }
    return out


def _groups(scores, by) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for s in scores:
        out.setdefault(by(s), []).append(s)
    return dict(sorted(out.items()))


def load_set(name: str, cached: bool, methods: tuple[str, str]) -> tuple[list[dict], int]:
    """A set's scores holding both ``methods``, and how many bundles the set has."""
    if cached:
        files = sorted((HERE / "out" / name / "scores").glob("*.json"))
        scores = [json.loads(f.read_text()) for f in files]
        bundles = HERE / "out" / name / "bundles"
        n = (
            sum((p / "sequence.json").exists() for p in bundles.iterdir())
            if bundles.is_dir()
            else len(scores)
        )
    else:
        path = HERE / "results" / f"{SETS[name]}.json"
        if not path.exists():
            raise SystemExit(f"holdout_rule: {path}: no committed results for set {name!r}")
        scores = json.loads(path.read_text())["sequences"]
        n = len(scores)
    both = [s for s in scores if all(m in s for m in methods) and s.get("truth") is not None]
    return both, n


def with_blend_truth(scores: list[dict], sampled: dict) -> list[dict]:
    """``scores`` with each smooth metal's truth replaced by the gloss its
    frames hold (``sampled``: sequence prefix -> ``{"sampled": ...}``, from
    ``blend_truth.py --json``); the others unchanged."""
    out = []
    for s in scores:
        hit = sampled.get(s["bundle"].split("-")[0])
        out.append(dict(s, truth=hit["sampled"]) if hit else s)
    return out


def _line(name: str, fig: dict) -> str:
    mae = "-" if fig["mae"] is None else f"{fig['mae']:.3f}"
    width = "-" if fig["median_width"] is None else f"{fig['median_width']:.2f}"
    return (
        f"  {name:<16} MAE {mae}  held {fig['held']}/{fig['sun_lit']}  width {width}"
        f"  confident misses {len(fig['confident_misses'])} {fig['confident_misses']}"
        f"  overcast {fig['overcast_ok']}/{fig['sunless']}"
        f"  median s {fig['median_seconds']:.0f}  not-converged {fig['not_converged']}"
    )


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", action="append", required=True, choices=tuple(SETS), dest="sets")
    ap.add_argument("--default", default="perez", help="the default's method name in the scores")
    ap.add_argument("--candidate", required=True, help="the candidate's method name")
    ap.add_argument("--cached", action="store_true", help="read the sets' score caches")
    ap.add_argument("--set-tolerance", type=float, default=0.01)
    ap.add_argument("--speed-limit", type=float, default=None, help="1.25; 2 with --sunless")
    ap.add_argument("--sunless", action="store_true", help="the sunless days' rule (sunless_rule)")
    ap.add_argument("--mae-tolerance", type=float, default=0.02, help="with --sunless")
    ap.add_argument("--json", help="also write the figures to this file")
    ap.add_argument(
        "--blend-truth",
        action="store_true",
        help="also report the figures with Mitsuba's blended smooth metals scored against "
        "the gloss their frames hold (results/blend_truth_<set>.json; not the rule's)",
    )
    args = ap.parse_args(argv)
    methods = (args.default, args.candidate)
    sets, sizes = {}, {}
    for name in args.sets:
        sets[name], sizes[name] = load_set(name, args.cached, methods)
    if args.speed_limit is None:  # the rules' own limits (module docstring)
        args.speed_limit = 2.0 if args.sunless else 1.25
    if args.sunless:
        return _sunless_main(args, sets, sizes, methods)
    out = rule(
        sets,
        *methods,
        set_tolerance=args.set_tolerance,
        speed_limit=args.speed_limit,
    )
    out["scored_by_both"] = {name: [len(sets[name]), sizes[name]] for name in sets}
    for name in sets:
        print(f"{name}: {len(sets[name])} of {sizes[name]} bundles scored by both")
        for m in methods:
            print(_line(m, out["per_set"][name][m]))
    print("pooled:")
    for m in methods:
        print(_line(m, out["pooled"][m]))
    print(f"  speed ratio {out['speed_ratio']:.2f}")
    for key, value in out["conditions"].items():
        print(f"  ({key}) {'met' if value else 'NOT met'}")
    if out["sets_more_than_tolerance_worse"]:
        worse = out["sets_more_than_tolerance_worse"]
        print(f"  (a): more than {args.set_tolerance} worse on {worse}")
    print("rule met" if out["met"] else "rule NOT met")
    for key, groups in out["beside"].items():
        print(f"by {key}:")
        for group, figs in groups.items():
            print(f" {group}")
            for m in methods:
                print(_line(m, figs[m]))
    if out["lobe_families"]:
        print("lobe families where the candidate fitted (median weight, MAE of the family's fit):")
        for group, figs in out["lobe_families"].items():
            print(f" {group} (n {figs['n']})")
            for m in methods:
                fams = "  ".join(
                    f"{f} {v['median_weight']:.2f}/{v['mae']:.3f}" for f, v in figs[m].items()
                )
                print(f"  {m:<16} {fams}")
    if args.blend_truth:
        blended = {}
        for name, scores in sets.items():
            path = HERE / "results" / f"blend_truth_{name}.json"
            sampled = json.loads(path.read_text())["sequences"] if path.exists() else {}
            blended[name] = with_blend_truth(scores, sampled)
        again = rule(
            blended, *methods, set_tolerance=args.set_tolerance, speed_limit=args.speed_limit
        )
        out["blend_truth"] = {"per_set": again["per_set"], "pooled": again["pooled"]}
        print("with the smooth metals' sampled gloss as truth (reported beside the rule):")
        for m in methods:
            print(_line(m, again["pooled"][m]))
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1, default=_plain) + "\n")
    return out


def _sunless_main(args, sets, sizes, methods) -> dict:
    """``--sunless``: :func:`sunless_rule`, printed (and written with ``--json``)."""
    out = sunless_rule(
        sets, *methods, mae_tolerance=args.mae_tolerance, speed_limit=args.speed_limit
    )
    out["scored_by_both"] = {name: [len(sets[name]), sizes[name]] for name in sets}
    for name in sets:
        print(f"{name}: {len(sets[name])} of {sizes[name]} bundles scored by both")
    for m in methods:
        f = out["pooled"][m]
        print(
            f"  {m:<16} overcast {f['overcast_ok']}/{f['sunless']}  held {f['held']}"
            f"  confident misses {len(f['confident_misses'])} {f['confident_misses']}"
            f"  MAE {f['mae']:.3f}  width {f['median_width']:.2f}"
            f"  median s {f['median_seconds']:.0f}"
        )
    print(f"  speed ratio {out['speed_ratio']:.2f}")
    for key, value in out["conditions"].items():
        print(f"  ({key}) {'met' if value else 'NOT met'}")
    print("rule met" if out["met"] else "rule NOT met")
    for day in out["days"]:
        answers = "  ".join(
            f"{m} {day[m]['median']:.3f} [{day[m]['interval'][0]:.2f}, {day[m]['interval'][1]:.2f}]"
            f"{' ok' if day[m]['overcast_ok'] else ''} ({day[m]['most_weight']})"
            for m in methods
        )
        about = f"{day['bundle'][:22]:<22} {day['sky']:<16} {day['facets']:>3} {day['truth']:.3f}"
        print(f" {about}  {answers}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1, default=_plain) + "\n")
    return out


def _plain(value):
    """A numpy scalar (a count, a flag) as the Python number JSON writes."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


if __name__ == "__main__":
    main()
