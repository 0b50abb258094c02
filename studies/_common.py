"""Shared plumbing of the sensitivity studies (issue 7): configs, simulated
objects, batched posterior fits, the baseline, and writing results.

Not library code: the studies' scripts import it, nothing in ``bayesgloss``
does. Every study simulates (or renders) one object per condition, a set of
facets of the paper hemisphere made of one material (gamma, n), and puts the
posterior object gloss (the hierarchical population mean of
:func:`bayesgloss.pooling.population_gloss`) beside the paper's peak-frame
baseline (mean over sunlit facets, :func:`bayesgloss.baseline.peak_frame_gloss`).

Every study cuts its work into units (one object, or a few fitted together)
that :func:`bayesgloss.runner.run_units` runs on local processes (``--jobs``)
or a Dask cluster (``--scheduler``) into ``<out>/units/``, one folder per
finished unit, written atomically: a killed run restarted recomputes
nothing that finished. A unit is a pure function of its options (the
config without the lists the study is cut along, and the unit's own cell)
and draws its random numbers from :func:`unit_seed` (the config's seed and
the unit's labels), so the numbers depend neither on ``--jobs``, nor on the
executor, nor on the order in which units run. The tables are gathered from
the unit folders in the config's order.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import hashlib
import json
import re
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bayesgloss import (
    baseline,
    diagnostics,
    pooling,
    render,
    runner,
    sampling,
    scene,
    sky,
    sun,
)
from bayesgloss import likelihood as lk

STUDIES = Path(__file__).resolve().parent
#: Frames with the sun at least this high (sun_z) are used [-] (about 1 deg).
SUN_UP_Z = 0.02
#: Facets seen at least this obliquely (cos of the view angle) are used [-].
MIN_COS_VIEW = 0.1


def load_config(name: str, quick: bool = False, override: dict | None = None) -> dict:
    """The committed config ``studies/configs/<name>.json``; with ``quick`` its
    ``"quick"`` entries replace the top-level ones; ``override`` last."""
    cfg = json.loads((STUDIES / "configs" / f"{name}.json").read_text())
    quick_part = cfg.pop("quick", {})
    if quick:
        cfg.update(quick_part)
    cfg.update(override or {})
    return cfg


def parse_args(name: str, argv=None, doc: str = "") -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=doc.splitlines()[0] if doc else name)
    ap.add_argument("--quick", action="store_true", help="the config's tiny test-size run")
    ap.add_argument("--jobs", type=int, default=2, help="local worker processes (default 2)")
    ap.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run the units on this Dask distributed scheduler (tcp://host:8786) "
        "instead of local processes; the numbers are the same",
    )
    ap.add_argument("--out", default=str(STUDIES / "out" / name))
    ap.add_argument(
        "--results",
        default=None,
        help="copy small results and the figure here (default: studies/results/<name>, "
        "not in --quick runs)",
    )
    args = ap.parse_args(argv)
    if args.results is None and not args.quick:
        args.results = str(STUDIES / "results" / name)
    return args


def publish(out: Path, results: str | None, files) -> None:
    """Copy the small result files and the figure from ``out`` to ``results``."""
    if not results:
        return
    dest = Path(results)
    dest.mkdir(parents=True, exist_ok=True)
    for f in files:
        shutil.copy2(out / f, dest / f)


def unit_seed(seed: int, *labels) -> np.random.SeedSequence:
    """The seed of one unit of work: the config's ``seed`` and the unit's
    ``labels`` (numbers and strings naming it, e.g. ``"data", 0.5, 0.01``),
    hashed, never the order in which units run."""
    text = json.dumps([seed, *labels], default=str)
    words = np.frombuffer(hashlib.sha256(text.encode()).digest(), dtype="<u4")
    return np.random.SeedSequence([int(seed), *map(int, words)])


def seed_int(seed: np.random.SeedSequence) -> int:
    """An integer seed drawn from a seed sequence (for functions taking ints)."""
    return int(seed.generate_state(1, np.uint64)[0])


def unit_name(study: str, *labels) -> str:
    """A readable unit folder name (:func:`bayesgloss.runner.unit_key` adds a hash)."""
    return "-".join([study, *(re.sub(r"[^A-Za-z0-9.]+", "_", str(x)) for x in labels)])


def unit_options(cfg: dict, axes, **cell) -> dict:
    """A unit's options: ``cfg`` without the entries ``axes`` the study is cut
    along, and the unit's own ``cell``. Adding a condition to a config thus
    leaves the other units' folders (and numbers) as they were."""
    return {"cfg": {k: v for k, v in cfg.items() if k not in axes}, **cell}


def _plain(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable: {value!r}")


def unit_files(tables: dict[str, list[dict]]) -> dict[str, bytes]:
    """A unit's result: its rows of each table (``{"objects.csv": [row, ...]}``)
    as ``rows.json`` (floats written exactly)."""
    return {"rows.json": json.dumps(tables, default=_plain).encode()}


def run_units(name: str, units: list[tuple[str, dict]], out: Path, args, **fixed) -> dict:
    """Run the study's ``unit(**options)`` for every unit not finished under
    ``out/units/`` (:func:`bayesgloss.runner.run_units`, ``args.jobs`` local
    processes or ``args.scheduler``), then gather each table's rows from the
    unit folders in the order of ``units``.

    ``fixed`` are further keyword arguments of every unit that do not change
    its numbers (a cache folder): they are not part of the units' keys.

    Returns
    -------
    dict
        ``{table file name: rows}``.
    """
    func = functools.partial(runner.script_unit, str(STUDIES / f"study_{name}.py"), "unit", **fixed)

    def progress(done: int, total: int) -> None:
        print(f"\r{name}: {done}/{total} units", end="", file=sys.stderr, flush=True)

    folders = runner.run_units(
        func, units, out / "units", jobs=args.jobs, scheduler=args.scheduler, progress=progress
    )
    print(file=sys.stderr)
    tables: dict[str, list[dict]] = {}
    for folder in folders:
        for table, rows in json.loads((folder / "rows.json").read_text()).items():
            tables.setdefault(table, []).extend(rows)
    return tables


@dataclass(frozen=True)
class Scene:
    """Facets of the paper hemisphere under one sky: geometry, bases, frames."""

    geometry: render.ViewGeometry
    bases: render.FacetBases
    sun_direction: np.ndarray
    solar_hours: np.ndarray
    valid: np.ndarray  # (F, T)
    facet_index: np.ndarray  # indices into the hemisphere's facets


def _subset(g: render.ViewGeometry, idx) -> render.ViewGeometry:
    return render.ViewGeometry(g.normal[idx], g.view_direction[idx], g.center[idx], g.occluder)


def paper_sequence(view: str, sky_model: str, **overrides) -> scene.Sequence:
    """:func:`bayesgloss.scene.paper_sequence`, also for ``"point-sun"`` (built
    here from the sequence's sun: that sky takes no ground reflectance)."""
    if sky_model != "point-sun":
        return scene.paper_sequence(view=view, sky_model=sky_model, **overrides)
    seq = scene.paper_sequence(view=view, sky_model="gensky-clear", **overrides)
    p = {**scene.PAPER, **overrides}
    sun_dir = sun.sun_direction_at(seq.times, p["latitude"], p["longitude"], refraction=False)
    return dataclasses.replace(seq, sky=sky.daylight("point-sun", sun_dir))


def facet_choice(view: str, n_facets: int, seed: int) -> np.ndarray:
    """Indices of ``n_facets`` facets seen from ``view`` that the sun lights at
    some time of the paper's day (all of them if fewer), chosen with ``seed``."""
    seq = paper_sequence(view, "point-sun")
    g = seq.geometry
    sun = seq.sky.sun_direction
    lit = np.any((g.normal @ sun.T > 0) & (sun[:, 2] > SUN_UP_Z), axis=1)
    ok = np.flatnonzero((g.cos_view > MIN_COS_VIEW) & lit)
    if n_facets >= len(ok):
        return ok
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(ok, n_facets, replace=False))


@functools.lru_cache(maxsize=64)
def paper_scene(
    view: str, sky_model: str, facets: tuple, solar_hours: tuple | None = None
) -> Scene:
    """The paper scene's chosen facets under ``sky_model`` with forward-model bases.

    ``"point-sun"`` uses no ground (the paper's model), as
    :func:`bayesgloss.estimate.bundle_bases` does.
    """
    over = {} if solar_hours is None else {"solar_hours": np.asarray(solar_hours, float)}
    seq = paper_sequence(view, sky_model, **over)
    idx = np.asarray(facets, int)
    g = _subset(seq.geometry, idx)
    ground = "sky" if sky_model == "point-sun" else "plane"
    bases = render.facet_bases(g, seq.sky, ground=ground)
    sun = np.asarray(seq.sky.sun_direction)
    valid = np.broadcast_to(sun[:, 2] > SUN_UP_Z, bases.diffuse.shape).copy()
    return Scene(g, bases, sun, seq.solar_hours, valid, idx)


def simulate(sc: Scene, gamma: float, exponent: float, rel_noise: float, rng, scale=89.5):
    """Facet curves of one material through the forward model with relative
    noise of sd ``rel_noise`` x (prediction + 1 % floor) (the likelihood's
    default noise model), (F, T). ``rel_noise`` 0 gives the noiseless curves."""
    design = lk.curve_data(
        np.ones_like(sc.bases.diffuse),
        sc.valid,
        sc.bases,
        priors=lk.Priors(log_s_center=float(np.log(scale))),
    )
    theta = np.empty((len(sc.valid), 1, 4))
    theta[..., 0] = gamma
    theta[..., 1] = np.log(exponent)
    theta[..., 2] = np.log(scale)
    theta[..., 3] = np.log(max(rel_noise, 1e-12))
    if rel_noise <= 0:
        return lk.predict(theta, design)[:, 0]
    return lk.simulate(theta, design, rng)[:, 0]


@dataclass
class Fit:
    """Posterior summary of one object (group of facets)."""

    facet_median: np.ndarray
    facet_q05: np.ndarray
    facet_q95: np.ndarray
    median: float
    q05: float
    q95: float
    converged: float  # fraction of facets that met the sampler's stopping rule


def fit_groups(
    groups, cfg: dict, seed: np.random.SeedSequence, camera: str = "linear"
) -> list[Fit]:
    """Posterior of every facet of every group in one batched sampler call
    (one process, one stream), then the object's gloss per group.

    Parameters
    ----------
    groups : list of dict
        ``y`` (F, T), ``valid`` (F, T), ``bases`` (FacetBases), optional
        ``censored`` (F, T).
    cfg : dict
        The study config: ``sampler`` (keyword arguments of
        :func:`bayesgloss.sampling.sample_posterior`) and ``population_draws``.
    seed : numpy.random.SeedSequence
        The unit's seed (:func:`unit_seed`): the sampler and each group's
        population draws get children of it.
    camera : str
        The likelihood's camera model.
    """
    if not groups:
        return []
    exps = groups[0]["bases"].exponents
    y = np.concatenate([g["y"] for g in groups])
    valid = np.concatenate([g["valid"] for g in groups])
    cens = np.concatenate([g.get("censored", np.zeros_like(g["valid"])) for g in groups])
    bases = render.FacetBases(
        np.concatenate([g["bases"].diffuse for g in groups]),
        np.concatenate([g["bases"].glossy for g in groups]),
        exps,
    )
    data = lk.curve_data(y, valid, bases, censored=cens, camera=camera)
    opts = dict(cfg.get("sampler", {}))
    n = len(y)
    opts.setdefault("stream_size", n)  # one stream: the unit's facets batched together
    opts.setdefault("min_streams", 1)
    fit_seed, *pop_seeds = seed.spawn(1 + len(groups))
    samples = sampling.sample_posterior(data, seed=seed_int(fit_seed), **opts)
    gam = samples.draws[..., 0].reshape(n, -1)  # (F, E*S)
    ess = diagnostics.rank_diagnostics(samples.draws[..., 0])[1]  # bulk ESS of each gamma
    max_steps = opts.get("max_steps", 8000)
    conv = samples.n_steps < max_steps
    out, lo = [], 0
    for g, pop_seed in zip(groups, pop_seeds, strict=True):
        hi = lo + len(g["y"])
        pop = pooling.population_gloss(
            gam[lo:hi],
            ess=ess[lo:hi],
            seed=seed_int(pop_seed),
            max_draws=cfg.get("population_draws", 1000),
        )["mu"]
        q = np.quantile(gam[lo:hi], [0.05, 0.5, 0.95], axis=1)
        out.append(
            Fit(
                q[1],
                q[0],
                q[2],
                float(np.median(pop)),
                float(np.quantile(pop, 0.05)),
                float(np.quantile(pop, 0.95)),
                float(np.mean(conv[lo:hi])),
            )
        )
        lo = hi
    return out


def baseline_fit(sc: Scene, y, valid=None) -> baseline.BaselineResult:
    """The paper's peak-frame estimate on the same curves."""
    v = sc.valid if valid is None else valid
    return baseline.peak_frame_gloss(
        y, v, sc.geometry, sc.sun_direction, frame_hours=sc.solar_hours
    )


def write_table(path: Path, rows: list[dict]) -> None:
    import csv

    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def read_table(path: Path) -> list[dict]:
    """CSV rows with numbers parsed (floats where they parse)."""
    import csv

    def num(v):
        try:
            return float(v)
        except ValueError:
            return v

    with open(path, newline="") as fh:
        return [{k: num(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def save_figure(fig, path: Path, dpi: int = 100) -> None:
    fig.savefig(path, dpi=dpi)
    import matplotlib.pyplot as plt

    plt.close(fig)


def plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def finish(
    name: str, out: Path, results, cfg: dict, tables: dict, summary, plot, published=None
) -> dict:
    """The end of every study: tables as CSV, ``summary.json`` (config and
    summary), the figure drawn from the saved tables, and the copies into
    ``studies/results/<name>/`` (``published``: which tables, default all)."""
    for file, rows in tables.items():
        write_table(out / file, rows)
    doc = {"config": cfg, "summary": summary}
    (out / "summary.json").write_text(json.dumps(doc, indent=1))
    plot(out)
    publish(out, results, [*(published or tables), "summary.json", f"{name}.png"])
    return doc
