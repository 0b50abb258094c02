"""SBC of one of ``test_one_material_sbc``'s designs, resumable: a candidate's gate.

``tests/test_material.py::test_one_material_sbc`` runs 60 objects of 6
facets over 6 frames drawn from the one-material model's prior, fitted
with the stopping rule capped at 1500 sweeps (Talts et al. 2018). A
candidate that changes the model (a patch on a worktree) must pass the
same designs before its rule is written; this script runs one design
with the bayesgloss on ``PYTHONPATH`` and that tree's ``sbc_material.py``,
appends each object's row (its ranks and run) to ``--rows`` as it ends
(a stopped run resumes with the objects missing), and when all are in
writes the chi-square p of every ranked quantity (10 bins) and each
one's 90 % hold (ranks 5-94 of 99) to ``--out``.

    env PYTHONPATH=<worktree> python studies/sbc_gate.py radiance \
        --rows rows.jsonl --out summary.json [--jobs 1]

Designs: ``phong`` (no Fresnel), ``radiance`` (Phong with Radiance's
Fresnel raise), ``ggx``, ``ward``; ``--exposure unknown`` for the
exposure-unknown design. The gate passes where every p > 0.001 and
gamma's hold is 46-59 of 60 (the binomial 99.9 % range at 0.9).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

DESIGNS = {  # name: (Fresnel model, lobe family)
    "phong": ("none", "phong"),
    "radiance": ("radiance", "phong"),
    "ggx": ("none", "ggx"),
    "ward": ("none", "ward"),
}


def study_of_tree():
    """The ``sbc_material`` study beside the bayesgloss imported (a worktree's own)."""
    import bayesgloss

    studies = Path(bayesgloss.__file__).resolve().parents[1] / "studies"
    sys.path.insert(0, str(studies))
    import sbc_material

    return sbc_material, studies / "sbc_material.py"


def read_rows(path: Path) -> list[dict]:
    """The objects' rows in ``path`` (none if it does not exist yet); a line
    that is not an object's row stops with the file and line named."""
    if not path.exists():
        return []
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as err:
            raise SystemExit(
                f"sbc_gate: {path}, line {number}: not an object's row ({err})"
            ) from None
        if not isinstance(row, dict) or {"index", "ranks", "seconds"} - set(row):
            raise SystemExit(
                f"sbc_gate: {path}, line {number}: not an object's row (no index, ranks, seconds)"
            )
        rows.append(row)
    return rows


def summary(study, rows: list[dict], names) -> dict:
    """The tree's :func:`sbc_material.rank_summary` of the objects' ``rows``,
    their median seconds, and whether the gate passes (every p > 0.001,
    gamma's hold 46-59 of 60)."""
    out = {"n": len(rows), **study.rank_summary(rows, names)}
    out["median_seconds"] = float(np.median([r["seconds"] for r in rows]))
    out["passed"] = study.rank_summary_passes(out, names, held90=(46, 59))
    return out


def main(argv=None) -> dict | None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("design", choices=tuple(DESIGNS))
    ap.add_argument("--exposure", choices=("known", "unknown"), default="known")
    ap.add_argument("--rows", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--n", type=int, default=60)
    args = ap.parse_args(argv)
    if not args.out.parent.is_dir():  # said now, not after an hour of objects
        raise SystemExit(f"sbc_gate: --out {args.out}: no folder {args.out.parent}")
    from bayesgloss.pool import process_pool
    from bayesgloss.runner import script_unit

    study, path = study_of_tree()
    fresnel, lobe = DESIGNS[args.design]
    ref = study.sbc_design(
        study.paper_three_skies(lobe),
        facets=6,
        frames=6,
        fresnel=fresnel,
        exposure_known=args.exposure == "known",
    )
    if not hasattr(study, "rank_summary"):
        raise SystemExit(f"sbc_gate: {path} has no rank_summary: run the gate from that tree")
    names = study.rank_names(ref)
    done = {r["index"] for r in read_rows(args.rows)}
    todo = [i for i in range(args.n) if i not in done]
    print(f"sbc_gate: {args.design}, {len(todo)} of {args.n} objects to run; ranks of {names}")
    with process_pool(args.jobs) as pool:
        futures = [
            pool.submit(
                script_unit, str(path), "sbc_object", ref=ref, seed=2028, index=i, max_sweeps=1500
            )
            for i in todo
        ]
        for future in futures:
            row = future.result()
            with args.rows.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            print(f"object {row['index']}: {row['seconds']:.0f} s", flush=True)
    rows = sorted(read_rows(args.rows), key=lambda r: r["index"])
    if len(rows) < args.n:
        return None
    out = {
        "design": {
            "lobe_family": lobe,
            "fresnel": fresnel,
            "exposure": args.exposure,
            "facets": 6,
            "frames": 6,
            "seed": 2028,
            "max_sweeps": 1500,
        }
    }
    out.update(summary(study, rows, names))
    out["objects"] = rows
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps({k: v for k, v in out.items() if k != "objects"}, indent=1))
    return out


if __name__ == "__main__":
    main()
