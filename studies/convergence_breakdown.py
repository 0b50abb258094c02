"""Which quantities keep a joint fit from converging? (a probe, stop 41)

Mitsuba holdout 1's default answers carried the flag ``not-converged`` on
17 of 24 sequences. The joint sampler's stopping rule
(:mod:`bayesgloss.sampling.schedule`) asks R-hat < 1.01 and bulk and tail
ESS >= 400 of the object's gamma *and* of every frame's sun and sky
latents; a run that has not met it at ``max_sweeps`` is flagged. This
script fits bundles with the default options, records every joint run's
diagnostics (by wrapping the sky families' fitting step), and
prints, per run, gamma's R-hat and ESS and which frames' latents fail the
rule, with each frame's solar elevation and the latent's posterior width,
so that one can see whether the flag speaks of gamma or of frames the data
barely inform.

    python studies/convergence_breakdown.py BUNDLE [BUNDLE ...] [--jobs 2] [--out FILE.json]

Only for seen sequences: it is a probe, not a score.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from bayesgloss import diagnostics, sky_families
from bayesgloss.bundle import read_bundle
from bayesgloss.estimate import estimate_bundle


def _diagnostics(s, used) -> dict:
    """One joint run's diagnostics (:class:`bayesgloss.sampling.schedule.JointSamples`):
    gamma's, then each frame's sun and sky latents', each frame named by its
    index in the bundle (``used``: the run's frames of the bundle's, (T,) of bool)."""
    t = s.frames.shape[2]
    lam = s.frames[..., 1:3]  # (E, S, T, 2): log a (sun), log b (sky)

    def stats(k):
        return {
            "rhat": float(s.rhat[k]),
            "ess_bulk": float(s.ess_bulk[k]),
            "ess_tail": float(s.ess_tail[k]),
            "ok": bool(diagnostics.meets_rule(s.rhat[k], s.ess_bulk[k], s.ess_tail[k])),
        }

    return {
        "converged": bool(s.converged),
        "sweeps": int(s.n_sweeps),
        "seconds": float(s.seconds),
        "gamma": stats(0),
        "frames": [
            {
                "frame": int(f),
                **{
                    latent: {**stats(1 + j * t + i), "sd": float(lam[..., i, j].std())}
                    for j, latent in enumerate(("sun", "sky"))
                },
            }
            for i, f in enumerate(np.flatnonzero(used))
        ],
    }


def _record(runs: dict):
    """A wrapper of the sky families' fitting step that keeps, in ``runs``,
    each family's last run's diagnostics (the fits may run in worker
    processes; their samples come back to this one)."""
    real = sky_families._fit_each

    def wrapped(names, *args, **kw):
        fits = real(names, *args, **kw)
        for name, (_, samples, used) in fits.items():
            runs[name] = _diagnostics(samples, used)
        return fits

    return real, wrapped


def breakdown(path, jobs: int = 2) -> dict:
    """The default estimate of the bundle at ``path`` and every joint run's diagnostics."""
    runs: dict = {}
    real, wrapped = _record(runs)
    sky_families._fit_each = wrapped
    try:
        t0 = time.perf_counter()
        res = estimate_bundle(path, jobs=jobs)
        seconds = time.perf_counter() - t0
    finally:
        sky_families._fit_each = real
    b = read_bundle(path)
    elevation = 90.0 - np.degrees(np.arccos(np.clip(b.sun_direction[:, 2], -1, 1)))
    obj = res.summary["object"]
    return {
        "bundle": str(path),
        "seconds": seconds,
        "object": {"gamma": obj["gamma"], "flags": obj["flags"]},
        "sun_elevation_deg": elevation.tolist(),
        "runs": runs,
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bundle", nargs="+")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--out")
    args = p.parse_args(argv)
    out = []
    for path in args.bundle:
        r = breakdown(path, args.jobs)
        out.append(r)
        g = r["object"]["gamma"]
        print(f"{Path(path).name}: gamma {g['median']:.3f}, flags {r['object']['flags']}")
        elevation = r["sun_elevation_deg"]
        for k, run in r["runs"].items():
            bad = [
                f"{fr['frame']}:{latent}(sun at {elevation[fr['frame']]:.0f} deg, "
                f"R {q['rhat']:.3f}, ESS {q['ess_bulk']:.0f}/{q['ess_tail']:.0f}, sd {q['sd']:.2f})"
                for fr in run["frames"]
                for latent, q in fr.items()
                if latent != "frame" and not q["ok"]
            ]
            gq = run["gamma"]
            print(
                f"  run {k}: converged {run['converged']}, {run['sweeps']} sweeps, "
                f"gamma R {gq['rhat']:.3f} ESS {gq['ess_bulk']:.0f}/{gq['ess_tail']:.0f} "
                f"({'passes' if gq['ok'] else 'fails'}); "
                f"{len(bad)} of {2 * len(run['frames'])} frame latents fail: {' '.join(bad)}"
            )
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
