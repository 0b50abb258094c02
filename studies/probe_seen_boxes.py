"""Probe: single fits of seen sequences against the default's committed answers.

A candidate's first look at renders (not a holdout: every sequence here is
of a set already scored and read). Each sequence is fitted once with
``estimate``'s defaults by whatever code is imported (a candidate's
worktree with ``PYTHONPATH=<worktree>``), and its object's answer is
appended to a JSON-lines file beside the truth and the default's answer
from ``results/validation_<set>.json``; sequences already in the file are
skipped, so a stopped run resumes. The table printed at the end has the
reported interval of each and ``*`` where it misses the truth. The
committed answers are the default's that scored each set (for Mitsuba
holdouts 13 and 14, stop 63's and 66's; the default's changes since act
on sunless days only).

The default list is stop 68's nine sun-lit Mitsuba boxes of Mitsuba
holdouts 13 and 14 and its four many-facet controls (``studies/README.md``,
"Stop 68: Mitsuba's plastic boxes", and "Stop 72: the day's light built");
their bundles must be in ``studies/out/<set>/bundles`` (render the
probe's sequences of a set again from its committed config, with the
set's keys: ``mitsuba_set.py --config studies/configs/<set>.json --cache
studies/out/<set>/bundles --only msNN ...``, about 2 min a sequence on
two threads).

Usage: PYTHONPATH=<worktree> python studies/probe_seen_boxes.py --name day-light
       [--out studies/out/probe_day_light.jsonl] [--options JSON] [SET:msNN ...]

``--options`` passes keywords to ``estimate_bundle`` (a probe of one lobe,
``'{"lobe": "ggx", "fresnel": "schlick-lobe"}'``) and is recorded per row.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from bayesgloss.intervals import reported_interval

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from code_under_test import check as check_code  # noqa: E402
from validate_radiance import SETS  # noqa: E402  (each set's committed results file)

#: stop 68's nine sun-lit boxes, then its four many-facet controls
STOP68 = (
    "mitsuba_holdout13:ms03", "mitsuba_holdout13:ms05", "mitsuba_holdout13:ms07",
    "mitsuba_holdout13:ms14", "mitsuba_holdout13:ms18", "mitsuba_holdout14:ms02",
    "mitsuba_holdout14:ms09", "mitsuba_holdout14:ms15", "mitsuba_holdout14:ms17",
    "mitsuba_holdout14:ms06", "mitsuba_holdout14:ms19", "mitsuba_holdout14:ms22",
    "mitsuba_holdout13:ms11",
)  # fmt: skip


@functools.cache
def committed(set_name: str) -> dict:
    """The set's committed scores by bundle name (``results/<file>.json``,
    the file :data:`validate_radiance.SETS` names), read once a run."""
    if set_name not in SETS:
        raise SystemExit(f"probe: no set {set_name!r} (validate_radiance.SETS names the sets)")
    path = HERE / "results" / f"{SETS[set_name]}.json"
    return {s["bundle"]: s for s in json.loads(path.read_text())["sequences"]}


def bundle_of(set_name: str, prefix: str) -> Path:
    """The bundle of ``set_name`` whose name starts with ``prefix`` (msNN)."""
    found = sorted((HERE / "out" / set_name / "bundles").glob(f"{prefix}-*"))
    if len(found) != 1:
        raise SystemExit(
            f"probe: {len(found)} bundles {prefix}-* in studies/out/{set_name}/bundles "
            "(render the set again from its committed config)"
        )
    return found[0]


def fit(path: Path, seed: int, options: dict | None = None) -> dict:
    """One ``estimate`` with its defaults, or with ``options`` (keyword arguments
    of :func:`bayesgloss.estimate.estimate_bundle`): the object's answer and the
    run's seconds."""
    from bayesgloss import estimate

    t0 = time.time()
    res = estimate.estimate_bundle(str(path), seed=seed, jobs=2, **(options or {}))
    obj = res.summary["object"]
    return {
        "median": obj["gamma"]["median"],
        "hdi90": list(reported_interval(obj["gamma"])),
        "within_model": obj["gamma_within_model"]["median"],
        "flags": obj["flags"],
        "facets": obj["facets"],
        "day_light": res.summary.get("day_light"),
        "seconds": time.time() - t0,
    }


def table(rows: list[dict]) -> str:
    """The probe's rows against the default's answers, and their MAE and hold."""
    lines = ["| sequence | facets | truth | default | probe |", "|---|---|---|---|---|"]
    errs = {"default": [], "probe": []}
    held = {"default": 0, "probe": 0}
    for r in rows:
        cells = []
        for who in ("default", "probe"):
            lo, hi = r[who]["hdi90"]
            miss = not lo <= r["truth"] <= hi
            errs[who].append(abs(r[who]["median"] - r["truth"]))
            held[who] += not miss
            cells.append(f"{r[who]['median']:.3f} [{lo:.2f}, {hi:.2f}]{'*' * miss}")
        head = f"| {r['sequence']} | {r['facets']} | {r['truth']:.3f}"
        lines.append(f"{head} | {' | '.join(cells)} |")
    n = len(rows)
    lines.append(
        f"| MAE, held | | | {np.mean(errs['default']):.3f}, {held['default']}/{n} | "
        f"{np.mean(errs['probe']):.3f}, {held['probe']}/{n} |"
    )
    return "\n".join(lines)


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequences", nargs="*", default=list(STOP68), help="SET:msNN")
    ap.add_argument("--name", required=True, help="what is probed (recorded)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--options",
        type=json.loads,
        default=None,
        help='estimate_bundle\'s keywords as JSON, e.g. \'{"lobe": "ggx"}\'',
    )
    ap.add_argument("--out", default=None, help="JSON lines (default studies/out/probe_NAME.jsonl)")
    args = ap.parse_args(argv)
    check_code("probe_seen_boxes")  # the candidate probed is the tree on PYTHONPATH
    warnings.simplefilter("ignore")
    out = Path(args.out or HERE / "out" / f"probe_{args.name}.jsonl")
    out.parent.mkdir(parents=True, exist_ok=True)
    done = [json.loads(x) for x in out.read_text().splitlines()] if out.exists() else []
    seen = {r["sequence"] for r in done}
    for item in args.sequences:
        set_name, prefix = item.split(":")
        if item in seen:
            continue
        path = bundle_of(set_name, prefix)
        default = committed(set_name)[path.name]
        answer = default["perez"]
        row = {
            "sequence": item,
            "bundle": path.name,
            "probe_name": args.name,
            "options": args.options,
            "truth": default["truth"],
            "facets": default["facets"],
            "default": {"median": answer["median"], "hdi90": reported_interval(answer)},
            "probe": fit(path, args.seed, args.options),
        }
        with out.open("a") as f:
            f.write(json.dumps(row) + "\n")
        done.append(row)
        print(item, row["probe"]["median"], flush=True)
    print(table(done))
    return done


if __name__ == "__main__":
    main()
