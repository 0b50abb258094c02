"""Probe (stop 67): one ``estimate`` of a bundle with every lobe's roughness
capped, i.e. the exponent prior's lower bound raised.

Under Ward and GGX a lobe of roughness alpha 0.5-0.8 (Phong-equivalent
exponent n = 2 / alpha^2 - 2 of 1-6, :mod:`bayesgloss.lobes`) is nearly
Lambertian, so its gamma trades against the diffuse albedo; on a sunless
day such lobes read a matt object glossy (studies/README.md, "Stop 67: a
roughness cap"). This script fits a bundle with the prior of log n
starting at log(2 / alpha_max^2 - 2) instead of 0 and appends the object's
answer to a JSON-lines file. The estimator builds its own
:class:`bayesgloss.likelihood.Priors`, so the bound is set as the class's
default for this process only.

Usage: python studies/probe_roughness_cap.py BUNDLE --alpha-max 0.5
       [--lobe ward] [--sky cie-1] [--out studies/out/roughness_cap.jsonl]
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np


def cap_exponent_prior(alpha_max: float) -> tuple[float, float]:
    """Set :class:`~bayesgloss.likelihood.Priors`'s default ``log_n`` to start
    at the exponent of roughness ``alpha_max`` (Walter et al. 2007, section
    5.2: n = 2 / alpha^2 - 2); returns the new bounds."""
    from bayesgloss import likelihood as lk

    defaults = list(lk.Priors.__init__.__defaults__)
    upper = defaults[0][1]
    defaults[0] = (float(np.log(2.0 / alpha_max**2 - 2.0)), upper)
    lk.Priors.__init__.__defaults__ = tuple(defaults)
    return lk.Priors().log_n


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundle")
    ap.add_argument("--alpha-max", type=float, required=True)
    ap.add_argument("--lobe", default=None, help="estimate's lobe (default: its own)")
    ap.add_argument("--sky", default=None, help="estimate's sky (default: its own)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="studies/out/roughness_cap.jsonl")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    bounds = cap_exponent_prior(args.alpha_max)
    from bayesgloss import estimate

    res = estimate.estimate_bundle(
        args.bundle, seed=args.seed, jobs=1, illumination=args.sky, lobe=args.lobe
    )
    obj = res.summary["object"]
    record = {
        "bundle": Path(args.bundle).name,
        "lobe": args.lobe,
        "sky": args.sky,
        "alpha_max": args.alpha_max,
        "log_n": bounds,
        "gamma": obj["gamma"]["median"],
        "hdi90": obj["gamma"]["hdi90"],
        "flags": obj.get("flags"),
    }
    print(json.dumps(record))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("a") as f:
        f.write(json.dumps(record) + "\n")


if __name__ == "__main__":
    main()
