"""The flag ``sun-not-identifiable`` on the seen holdouts' committed scores.

A frame's sun is not identified where its 90 % interval runs from below
``joint_estimate.SUN_HIDDEN`` to above ``SUN_SHOWN`` of the sky model's
sun; :func:`bayesgloss.joint_estimate.sun_flags` flags an object where
more than ``SUN_UNIDENTIFIED_SHARE`` of its frames are such. Each score
of ``validate_radiance.py`` keeps every frame's sun quantiles, so the flag
can be read off every set scored with per-frame illumination (method
``perez``, the default of the day each set was read) without a fit.

Reported per renderer and pooled, for sun-lit and sunless sequences, the
flagged and the unflagged objects' count, MAE, how many intervals held the
truth and their median width. It is a reading of seen data that says what
the flag is worth to a user; it changes no answer, so it has no rule.

    python studies/sun_flag_seen.py [--set NAME ...] [--json studies/results/sun_flag_seen.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from validate_radiance import RESULTS, SETS, _holds, reported_interval

from bayesgloss.joint_estimate import (
    SUN_HIDDEN,
    SUN_SHOWN,
    SUN_UNIDENTIFIED_SHARE,
    sun_not_identified,
)

#: The sets stop 63 read the flag on: every set whose committed scores kept
#: each frame's sun when the flag was added (holdouts 11-25, Mitsuba
#: holdouts 4, 5 and 7-12). Sets scored later are read with ``--set``
#: only, so that no unread set is read by default.
SEEN_STOP63 = (
    *(f"validation_holdout{k}" for k in range(11, 26)),
    *(f"mitsuba_holdout{k}" for k in (4, 5, 7, 8, 9, 10, 11, 12)),
)


def unidentified_share(entry: dict) -> float | None:
    """The share of a score's frames whose sun is not identified, or None
    where the score keeps no per-frame sun."""
    lo, hi = entry.get("sun_q05"), entry.get("sun_q95")
    if not lo or not hi:
        return None
    return float(np.mean(sun_not_identified(lo, hi)))


def figures(rows: list[tuple[dict, float]]) -> dict:
    """Count, MAE, intervals held and their median width of (entry, truth) rows."""
    if not rows:
        return {"n": 0}
    return {
        "n": len(rows),
        "mae": float(np.mean([abs(e["median"] - t) for e, t in rows])),
        "held": int(sum(bool(_holds(e, t)) for e, t in rows)),
        "median_width": float(np.median([np.ptp(reported_interval(e)) for e, _ in rows])),
    }


def read_sets(names) -> dict:
    """Flagged and unflagged (entry, truth) rows per renderer and day
    (``sun-lit``, ``sunless``) over the sets ``names`` whose scores keep
    each frame's sun; with the sets read."""
    cells, used = {}, []
    for name in names:
        path = RESULTS / f"{SETS[name]}.json"
        if not path.exists():
            continue
        scores = json.loads(path.read_text()).get("sequences", [])
        rows = [
            (s, unidentified_share(s["perez"]))
            for s in scores
            if "perez" in s and s.get("truth") is not None
        ]
        rows = [(s, share) for s, share in rows if share is not None]
        if not rows:
            continue
        used.append(name)
        renderer = "mitsuba" if "mitsuba" in name else "radiance"
        for s, share in rows:
            flagged = "flagged" if share > SUN_UNIDENTIFIED_SHARE else "not flagged"
            day = "sun-lit" if s["direct_sun"] else "sunless"
            for key in ((renderer, day, flagged), ("pooled", day, flagged)):
                cells.setdefault(key, []).append((s["perez"], s["truth"]))
    return {"sets": used, "cells": cells}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="write the table here")
    ap.add_argument(
        "--set", action="append", choices=sorted(SETS), help="these sets (default: SEEN_STOP63)"
    )
    args = ap.parse_args(argv)
    read = read_sets(sorted(args.set or SEEN_STOP63))
    table = {" / ".join(k): figures(v) for k, v in sorted(read["cells"].items())}
    out = {
        "sun_hidden": SUN_HIDDEN,
        "sun_shown": SUN_SHOWN,
        "share": SUN_UNIDENTIFIED_SHARE,
        "sets": read["sets"],
        "table": table,
    }
    for key, f in table.items():
        if f["n"]:
            print(f"{key:40s} n {f['n']:4d}  MAE {f['mae']:.3f}  held {f['held']:4d}  "
                  f"median width {f['median_width']:.2f}")  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    return out


if __name__ == "__main__":
    main()
