"""Benchmark: the default estimate against a candidate's on objects whose sky families tie.

Condition (e) of the rule "Holdout 24 and Mitsuba holdout 11: every lobe
under every tied sky" (``studies/README.md``, as amended in stop 60): the
candidate (branch ``lobes-every-sky``) fits every lobe under each tied sky
family, the default Phong alone, so it costs more exactly on the objects
whose sky families tie, most of them boxes of 1-3 facets. Each bundle
(default: holdout 23's boxes, ``out/validation_holdout23/bundles``, seen:
only their timing is used here) is estimated with ``estimate``'s default
options, as ``validate_radiance.py`` scores the default (``perez``), by the
code of two git revisions in turn, bundle by bundle, each estimate in a
fresh process with ``--jobs 1``: wall-clock seconds from the interpreter's
start to the answer. The figure is the ratio of the two medians, measured
in this one run (and each run's seconds beside it).

Usage::

    python studies/bench_tied_skies.py --against REV --candidate REV2 \\
        [--bundles 'studies/out/validation_holdout23/bundles/*'] [--boxes 6] \\
        [--max-sweeps 2000] [--json FILE]

Revisions are checked out as git worktrees under ``out/bench_joint/``
(:func:`bench_joint.checkout`). Run it on a machine doing nothing else.
"""

from __future__ import annotations

import argparse
import glob
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from bench_joint import checkout, timed_in  # noqa: E402

#: The default's estimate of one bundle, in a fresh process: what
#: ``validate_radiance.py`` runs as ``perez`` (estimate's defaults).
CHILD = """
import json, sys, warnings
warnings.simplefilter("ignore")
from bayesgloss import bundle, estimate
args = json.loads(sys.argv[1])
b = bundle.read_bundle(args["path"])
res = estimate.estimate_bundle(b, sampler_options={"max_steps": args["max_sweeps"]}, jobs=1)
obj = res.summary["object"]
print(json.dumps({"gamma": obj["gamma"]["median"], "flags": obj.get("flags", [])}))
"""


def boxes(pattern: str, count: int) -> list[Path]:
    """The first ``count`` bundles of ``pattern`` whose object is a box of
    1-3 seen facets (the objects whose sky families tie)."""
    found = []
    for path in sorted(glob.glob(pattern)):
        facets = json.loads((Path(path) / "sequence.json").read_text())["facets"]
        if len(facets) <= 3:
            found.append(Path(path))
    return found[:count]


def timed(tree: Path, path: Path, max_sweeps: int) -> dict:
    """One default estimate of ``path`` with the bayesgloss of ``tree``:
    wall-clock seconds of the whole process, its answer and flags."""
    t0 = time.perf_counter()
    answer = timed_in(tree, {"path": str(path), "max_sweeps": max_sweeps}, child=CHILD)
    return {"seconds": time.perf_counter() - t0, **answer}


def run(against: str, candidate: str, bundles: list[Path], max_sweeps: int) -> dict:
    """Both revisions on every bundle, in turn; the ratio of the medians."""
    trees = {"default": checkout(against), "candidate": checkout(candidate)}
    rows = []
    for path in bundles:
        row = {"bundle": path.name}
        for label, tree in trees.items():
            row[label] = timed(tree, path, max_sweeps)
            print(f"{path.name} {label}: {row[label]['seconds']:.0f} s", flush=True)
        rows.append(row)
    medians = {k: float(np.median([r[k]["seconds"] for r in rows])) for k in trees}
    return {
        "against": against,
        "candidate": candidate,
        "max_sweeps": max_sweeps,
        "rows": rows,
        "median_seconds": medians,
        "ratio_of_medians": medians["candidate"] / medians["default"],
    }


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", required=True, help="the default's revision")
    ap.add_argument("--candidate", required=True, help="the candidate's revision")
    ap.add_argument("--bundles", default=str(HERE / "out/validation_holdout23/bundles/*"))
    ap.add_argument("--boxes", type=int, default=6, help="bundles of 1-3 facets used")
    ap.add_argument("--max-sweeps", type=int, default=2000)
    ap.add_argument("--json", help="also write the figures to this file")
    args = ap.parse_args(argv)
    chosen = boxes(args.bundles, args.boxes)
    if not chosen:
        raise SystemExit(f"bench_tied_skies: no bundle of 1-3 facets in {args.bundles}")
    out = run(args.against, args.candidate, chosen, args.max_sweeps)
    text = json.dumps(out, indent=1)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    return out


if __name__ == "__main__":
    main()
