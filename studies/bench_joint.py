"""Benchmark: ``estimate``'s default (per-frame illumination, sky families
stacked) and ``--sky auto``, in one run beside the fixed-brightness
estimate of the same bundle (issue 13's speed goal: ``--sky auto`` on a
30-facet, 20-frame bundle in at most 30 s).

The bundle: the paper's site and date (40 N, 21 June), a hemisphere of 6
rings of 18 segments (30-odd facets usable) of grey plastic of specularity
0.5, seen from the south-west, 20 frames from 5:00 to 18:18 local solar
time (every 42 min), rendered with Radiance under gensky's clear sky (cached
in ``studies/out/bench_joint/``). Each estimate runs ``--repeats`` times with
different seeds in one process (``--jobs 2`` by default, as the command
line's: the sampler's two groups of ensembles, and the default's fits, run
two at a time; ``--jobs 1`` runs them in turn in one process, about 1.7
times as long, which stop 66 mistook for a slower machine), and the figures
are wall-clock seconds, sweeps, and whether the run met the convergence
rule, with the ratios of the medians measured in this run.

With ``--before`` the default and ``--sky auto`` are timed again as stop
36 ran them (:data:`BEFORE`: burn-in rounds of 200 sweeps, the rule
checked every 200 sweeps from 800 on, every sky family run in full),
interleaved with today's (rounds of 100, every 100 from 400 on, families
far behind at their first check kept there). With ``--lobes`` the
default estimate is timed again with ``--lobe families``
(:mod:`bayesgloss.lobe_families`: two fits more, the Ward and GGX lobes
under the most-weighted sky family).

With ``--against REV`` the default and ``--sky auto`` are timed, each in
a fresh process, with the code of the git revision REV (checked out in
``studies/out/bench_joint/against-REV``) and with today's, in turn, seed
by seed: the code changes of a stop measured in one run. A fresh process
also pays what a command-line run pays once (the population summary's
table of Beta masses, about 3 s), which the in-process rows pay only in
their first estimate.

With ``--variants auto-command`` (beside ``--against``) the command line
``bayesgloss estimate BUNDLE --sky auto`` is timed as a user runs it, from
the interpreter's start to the result files written.

Usage: python studies/bench_joint.py [--repeats 3] [--jobs 2] [--max-sweeps N] [--before] [--lobes]
       [--against REV [--variants auto,default,auto-command]]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
OUT = HERE / "out" / "bench_joint"


def bench_config():
    """The benchmark's sequence (module docstring)."""
    from bayesgloss import sequences

    return sequences.SequenceConfig(
        name="bench-joint",
        view="SW",
        material="plastic",
        specularity=0.5,
        n_rings=6,
        n_segments=18,
        image_size=128,
        sky="gensky-clear",
        solar_hours=tuple(float(h) for h in np.round(5.0 + 0.7 * np.arange(20), 2)),
    )


#: Stop 36's schedule of the one-material sampler, every sky family run in
#: full (sampler options).
BEFORE = {
    "burn_rounds": (200, 200, 200),
    "min_sweeps": 800,
    "chunk": 200,
    "screen_families": False,
}


def variants(before: bool, lobes: bool) -> list[tuple[str, dict]]:
    """(label, estimate_bundle's keywords) of each timed estimate."""
    out = [("fixed", {"per_frame": False, "illumination": "gensky-clear"})]
    for label, sky in (("auto", "auto"), ("default", None)):
        out.append((label, {"illumination": sky}))
        if before:
            out.append((f"{label}, stop 36", {"illumination": sky, "options": BEFORE}))
    if lobes:
        out.append(("default, lobe families", {"lobe": "families"}))
    return out


#: One estimate in a fresh process (``--against``): its arguments as JSON in
#: argv[1], its record as JSON on the last line of stdout.
CHILD = """
import json, sys, time, warnings
warnings.simplefilter("ignore")
from bayesgloss import bundle, estimate
a = json.loads(sys.argv[1])
b = bundle.read_bundle(a["path"])
t0 = time.perf_counter()
res = estimate.estimate_bundle(
    b, seed=a["seed"], jobs=a["jobs"], sampler_options=a["options"] or None, **a["kw"]
)
obj = res.summary["object"]
print(json.dumps({
    "seconds": time.perf_counter() - t0,
    "sweeps": res.summary["sampler"].get("sweeps"),
    "converged": obj["converged"],
    "gamma": obj["gamma"]["median"],
    "hdi90": obj["gamma"]["hdi90"],
}))
"""


def checkout(rev: str) -> Path:
    """A git worktree of revision ``rev`` under :data:`OUT` (made once)."""
    path = OUT / f"against-{rev}"
    if not path.exists():
        root = HERE.parent
        cmd = ["git", "-C", str(root), "worktree", "add", "--detach", "-f", str(path), rev]
        subprocess.run(cmd, check=True, capture_output=True)
    return path


def timed_in(tree: Path, args: dict, child: str | None = None) -> dict:
    """One estimate (``child``'s code, default :data:`CHILD`, given ``args``
    as JSON) with the bayesgloss of ``tree``: the JSON its last line prints."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run(
        [sys.executable, "-c", child or CHILD, json.dumps(args)],
        env=env,
        cwd=tree,  # not the caller's folder: python -c puts it first on sys.path
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def timed_command(tree: Path, path: Path, seed: int, jobs: int) -> dict:
    """``bayesgloss estimate BUNDLE --sky auto`` as a user runs it, with the
    bayesgloss of ``tree``: wall-clock seconds from the interpreter's start to
    the result files written (imports, reading, estimate, ``posterior.nc`` and
    ``summary.json``)."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = OUT / "command-line" / f"{tree.name}-{seed}"
    argv = ["bayesgloss", "estimate", str(path), "--sky", "auto", "--seed", str(seed)]
    argv += ["--jobs", str(jobs), "--out", str(out), "--quiet"]
    code = f"import sys; from bayesgloss.cli import main; sys.argv = {argv!r}; main()"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], env=env, cwd=tree, check=True, capture_output=True)
    seconds = time.perf_counter() - t0
    obj = json.loads((out / "summary.json").read_text())["object"]
    return {"seconds": seconds, "converged": obj["converged"], "gamma": obj["gamma"]["median"]}


#: The variants ``--against`` can time: (label, sky) for an estimate in a
#: fresh process; ``auto-command`` is :func:`timed_command`.
AGAINST_VARIANTS = {"auto": "auto", "default": None, "auto-command": "command"}


def run_against(rev: str, repeats: int, jobs: int, labels=("auto", "default")) -> dict:
    """The ``labels`` of :data:`AGAINST_VARIANTS` (the default and ``--sky
    auto``) with revision ``rev``'s code and today's, each in a fresh process,
    seeds in turn, the order of the two codes alternating from seed to seed.
    Whether the user's cache already held the population's table of Beta
    masses (:mod:`bayesgloss._cache`, new at stop 39) is recorded: a warm
    cache is every run's state but a machine's first."""
    from bayesgloss import _cache, sequences

    (path,) = sequences.render_bundles([bench_config()], OUT, jobs=2, progress=False)
    folder = _cache.cache_dir()
    warm = folder is not None and any(folder.glob("beta_bin_masses-*.npy"))
    trees = [(rev, checkout(rev)), ("today", HERE.parent)]
    rows = []
    for seed in range(repeats):
        for label in labels:
            sky = AGAINST_VARIANTS[label]
            for code, tree in trees if seed % 2 == 0 else trees[::-1]:
                row = {"variant": f"{label} ({code})", "seed": seed, "jobs": jobs}
                if sky == "command":
                    rows.append(row | timed_command(tree, path, seed, jobs))
                else:
                    kw = {"illumination": sky}
                    args = {"path": str(path), "seed": seed, "jobs": jobs, "options": {}, "kw": kw}
                    rows.append(row | timed_in(tree, args))
                print(json.dumps(rows[-1]), flush=True)
    med = {
        v: float(np.median([r["seconds"] for r in rows if r["variant"] == v]))
        for v in dict.fromkeys(r["variant"] for r in rows)
    }
    return {"rows": rows, "median_seconds": med, "against": rev, "beta_table_cached": warm}


def run(repeats: int, max_sweeps: int, lobes: bool = False, before=False, jobs=1) -> dict:
    """Time each variant ``repeats`` times, seeds in turn; the rows and their medians."""
    from bayesgloss import bundle, estimate, sequences

    warnings.simplefilter("ignore")
    (path,) = sequences.render_bundles([bench_config()], OUT, jobs=2, progress=False)
    b = bundle.read_bundle(path)
    rows = []
    for seed in range(repeats):  # interleaved, so that a slow spell hits every variant
        for label, kw in variants(before, lobes):
            kw = dict(kw)
            options = dict(kw.pop("options", {}))
            if max_sweeps:
                options["max_steps"] = max_sweeps
            t0 = time.perf_counter()
            res = estimate.estimate_bundle(
                b, seed=seed, jobs=jobs, sampler_options=options or None, **kw
            )
            obj = res.summary["object"]
            rows.append(
                {
                    "variant": label,
                    "model": res.summary["sampler"]["model"],
                    "illumination": res.summary["illumination"],
                    "seed": seed,
                    "jobs": jobs,
                    "seconds": time.perf_counter() - t0,
                    "sweeps": res.summary["sampler"].get("sweeps"),
                    "converged": obj["converged"],
                    "facets": obj["facets"],
                    "frames": int(b.sun_up.sum()),
                    "gamma": obj["gamma"]["median"],
                    "hdi90": obj["gamma"]["hdi90"],
                    "stopped_early": res.summary.get("sky_families", {}).get("stopped_early"),
                }
            )
            print(json.dumps(rows[-1]))
    med = {
        v: float(np.median([r["seconds"] for r in rows if r["variant"] == v]))
        for v in dict.fromkeys(r["variant"] for r in rows)
    }
    return {"rows": rows, "median_seconds": med, "truth": b.truth["gloss"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--jobs", type=int, default=2, help="as the command line's --jobs")
    ap.add_argument(
        "--before", action="store_true", help="also time stop 36's schedule, no screen (BEFORE)"
    )
    ap.add_argument(
        "--lobes", action="store_true", help="also time --lobe families (bayesgloss.lobe_families)"
    )
    ap.add_argument(
        "--max-sweeps", type=int, default=None, help="default: estimate's (2000 sweeps, 8000 steps)"
    )
    ap.add_argument(
        "--against", default=None, help="a git revision whose code to time beside today's"
    )
    ap.add_argument(
        "--variants",
        default="auto,default",
        help=f"with --against, which of {','.join(AGAINST_VARIANTS)} (comma-separated)",
    )
    args = ap.parse_args(argv)
    if args.against:
        labels = tuple(args.variants.split(","))
        out = run_against(args.against, args.repeats, args.jobs, labels)
        OUT.mkdir(parents=True, exist_ok=True)
        (OUT / f"bench_joint_against_{args.against}.json").write_text(json.dumps(out, indent=1))
        med = out["median_seconds"]
        print("median seconds:", json.dumps(med))
        for label in labels:
            old, new = med[f"{label} ({args.against})"], med[f"{label} (today)"]
            print(f"{label}: {args.against} / today: {old / new:.2f}x")
        return
    out = run(args.repeats, args.max_sweeps, args.lobes, args.before, args.jobs)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "bench_joint.json").write_text(json.dumps(out, indent=1))
    med = out["median_seconds"]
    print("median seconds:", json.dumps(med))
    for label, seconds in med.items():
        print(f"{label} / fixed: {seconds / med['fixed']:.1f}x")
        old = med.get(f"{label}, stop 36")
        if old is not None:
            print(f"{label}: stop 36 / today: {old / seconds:.2f}x")


if __name__ == "__main__":
    main()
