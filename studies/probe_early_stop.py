"""Probe: each chain's stopping rule check by check, for an early stop's threshold.

Stop 80 counted where a set's scoring hours go: 41-85 % to sequences whose
answer is flagged ``not-converged``, most of them boxes whose fits run to
the sweep cap without meeting the rule (R-hat < 1.01, bulk and tail ESS
>= 400, :mod:`bayesgloss.diagnostics`). A run could stop earlier once its
chains are "near enough", but only if what it would report there is
what it reports at the cap. This probe measures that on seen sequences
before any threshold is chosen.

Each sequence is fitted once with ``estimate``'s defaults (the code
imported: main, or a worktree with ``PYTHONPATH``). At every check of
every chain (:func:`bayesgloss.sampling.schedule.run_chain`) the probe
records the sweeps, the largest R-hat and the smallest bulk and tail ESS
of gamma and of the frames' latents, and the 5, 50 and 95 % quantiles of
each diagnosed facet's gamma over the kept half, the draws a run stopped
there would keep. One JSON line a check, to ``--out``; the chains of a
fit are told apart by process and start time (a fit's sky families may
run in worker processes, forked from this one, where the same recording
is in place).

:func:`shifts` then asks, for a threshold on R-hat (from half the cap
on), where each chain would have stopped, how far its quantiles were from
those at its real end in units of its real 90 % width, and what share of
its sweeps it would have saved.

Usage: python studies/probe_early_stop.py [--out studies/out/probe_early_stop.jsonl]
       [--options JSON] [SET:msNN | BUNDLE_PATH ...]   (default: probe_seen_boxes' list)
       python studies/probe_early_stop.py --read FILE [--rhat 1.05 1.1 1.2]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from probe_seen_boxes import STOP68, bundle_of  # noqa: E402

_STATE = {"chain": None, "sweeps": None, "max_sweeps": None, "out": None}


def _record(row: dict) -> None:
    with open(_STATE["out"], "a") as f:
        f.write(json.dumps(row) + "\n")


def install(out: Path) -> None:
    """Wrap the schedule's rule check so that every check of every chain is
    recorded to ``out`` (this process and the workers it forks)."""
    from bayesgloss.sampling import joint, material, schedule

    _STATE["out"] = str(out)
    rule_checked, diagnosed, run_chain = (
        schedule._rule_checked,
        schedule._diagnosed,
        schedule.run_chain,
    )

    def rule_checked_logged(kept, sweeps, min_sweeps, needed):
        _STATE["sweeps"] = sweeps
        return rule_checked(kept, sweeps, min_sweeps, needed)

    def diagnosed_logged(th_kept, lam_kept):
        out = diagnosed(th_kept, lam_kept)
        rhat, eb, et, ok = out
        f = th_kept.shape[2]
        gamma = th_kept[..., 0].astype(float)  # (n, E, F, W)
        q = np.quantile(gamma.transpose(2, 0, 1, 3).reshape(f, -1), [0.05, 0.5, 0.95], axis=1)
        _record(
            {
                "chain": _STATE["chain"],
                "sweeps": _STATE["sweeps"],
                "max_sweeps": _STATE["max_sweeps"],
                "facets": f,
                "rhat_gamma": float(np.max(rhat[:f])),
                "rhat_frames": float(np.max(rhat[f:])) if len(rhat) > f else None,
                "ess_min_gamma": float(min(np.min(eb[:f]), np.min(et[:f]))),
                "ess_min_frames": float(min(np.min(eb[f:]), np.min(et[f:])))
                if len(rhat) > f
                else None,
                "met": bool(np.all(ok)),
                "q": q.T.round(5).tolist(),  # (F, 3)
            }
        )
        return out

    def run_chain_logged(*args, **kwargs):
        _STATE["chain"] = f"{os.getpid()}-{time.time():.6f}"
        _STATE["max_sweeps"] = kwargs.get("max_sweeps")
        _STATE["sweeps"] = None
        if kwargs.get("resume") is not None:
            _STATE["chain"] += "-resumed"
        return run_chain(*args, **kwargs)

    schedule._rule_checked = rule_checked_logged
    schedule._diagnosed = diagnosed_logged
    joint.run_chain = material.run_chain = run_chain_logged


def shifts(
    rows: list[dict],
    rhat_max: float | None,
    from_share: float = 0.5,
    only_capped: bool = False,
    ess_min: float = 400.0,
) -> dict:
    """Where each chain that ran past its first check would have stopped
    under "every R-hat below ``rhat_max`` at a check from ``from_share`` of
    the cap on" (or at its real end): the largest shift of a quantile
    against its real end's, in units of the real 90 % width, and the share
    of its sweeps saved. Chains are keyed as recorded; a resumed chain is
    its own key (its checks go on from the first run's sweeps).
    ``rhat_max`` None: the other rule, "stop where the chain cannot reach
    ``ess_min`` by its cap": the smallest ESS at a check from ``from_share``
    of the cap on, grown in proportion to the sweeps, is below ``ess_min``
    at the cap (a flagged answer sooner; a chain on its way is let run).
    ``only_capped``: only the chains that ran to their cap unconverged,
    past a first check (the runs an early stop is for; a sky family's
    screen, capped at its first check, has nothing to stop early)."""
    chains: dict[str, list[dict]] = {}
    for r in rows:
        chains.setdefault(r["chain"], []).append(r)
    shift, saved, met = [], [], []
    for checks in chains.values():
        end = checks[-1]
        cap = end["max_sweeps"] or end["sweeps"]
        capped = len(checks) > 1 and end["sweeps"] == cap and not end.get("met", False)
        if only_capped and not capped:
            continue
        stop = next(
            (
                c
                for c in checks
                if c["sweeps"] is not None
                and c["sweeps"] >= from_share * cap
                and _stops(c, cap, rhat_max, ess_min)
            ),
            end,
        )
        q_end, q_stop = np.array(end["q"]), np.array(stop["q"])
        width = np.maximum(q_end[:, 2] - q_end[:, 0], 1e-3)
        shift.append(float(np.max(np.abs(q_stop - q_end) / width[:, None])))
        saved.append(1.0 - (stop["sweeps"] or 0) / max(end["sweeps"] or 1, 1))
        met.append(len(checks) > 1 and end.get("met", False))
    shift, saved, met = np.array(shift), np.array(saved), np.array(met, dtype=bool)
    return {
        "rhat_max": rhat_max,
        "only_capped": only_capped,
        "chains": len(shift),
        "stopped_early": int(np.sum(saved > 0)),
        "shift_median": float(np.median(shift)) if len(shift) else None,
        "shift_max": float(np.max(shift)) if len(shift) else None,
        "shift_over_0.1": int(np.sum(shift > 0.1)),
        "sweeps_saved_share": float(np.mean(saved)) if len(saved) else None,
        # chains that met the rule after more than one check, and that this
        # rule would have stopped sooner (accepted sooner, or given up on)
        "met_later": int(np.sum(met)),
        "met_later_stopped_sooner": int(np.sum(met & (saved > 0))),
    }


def _stops(check: dict, cap: int, rhat_max: float | None, ess_min: float) -> bool:
    """Whether a check stops its chain: every R-hat below ``rhat_max``, or
    (``rhat_max`` None) its smallest ESS grown to the cap below ``ess_min``."""
    frames = check["rhat_frames"] is not None  # None: no frame latents diagnosed
    if rhat_max is not None:
        return max(check["rhat_gamma"], check["rhat_frames"] if frames else 0.0) < rhat_max
    ess = min(check["ess_min_gamma"], check["ess_min_frames"] if frames else np.inf)
    return ess * cap / check["sweeps"] < ess_min


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequences", nargs="*", default=list(STOP68), help="SET:msNN, or a path")
    ap.add_argument(
        "--options",
        type=json.loads,
        default=None,
        help='estimate_bundle\'s keywords as JSON, e.g. \'{"illumination": "auto"}\'',
    )
    ap.add_argument("--out", default=str(HERE / "out" / "probe_early_stop.jsonl"))
    ap.add_argument("--read", default=None, help="only read a probe's file")
    ap.add_argument("--rhat", type=float, nargs="*", default=[1.02, 1.05, 1.1, 1.2])
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if args.read is None:
        from code_under_test import check as check_code

        from bayesgloss import estimate

        check_code("probe_early_stop")
        warnings.simplefilter("ignore")
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        install(out)
        for item in args.sequences:
            path = Path(item) if ":" not in item else bundle_of(*item.split(":"))
            _record({"sequence": item, "options": args.options, "start": time.time()})
            t0 = time.time()
            kw = args.options or {}
            res = estimate.estimate_bundle(str(path), seed=args.seed, jobs=2, **kw)
            g = res.summary["object"]["gamma"]
            _record({"sequence": item, "seconds": time.time() - t0, "median": g["median"]})
            print(item, f"{time.time() - t0:.0f} s", flush=True)
    rows = [json.loads(x) for x in Path(args.read or args.out).read_text().splitlines()]
    checks = [r for r in rows if "chain" in r]
    for capped in (False, True):
        for t in args.rhat:
            print(json.dumps(shifts(checks, t, only_capped=capped)))
        print(json.dumps(shifts(checks, None, only_capped=capped)))


if __name__ == "__main__":
    main()
