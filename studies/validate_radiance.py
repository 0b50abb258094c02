"""Score the estimators on the Radiance validation set (issue 13).

For every bundle of ``studies/validation_set.py`` (rendered into
``studies/out/validation_set/bundles``) this runs, as a new user would and
with nothing the spec does not allow (no ``truth``, no sky name):

- the paper's peak-frame baseline (``bayesgloss baseline``);
- ``estimate`` with fixed brightnesses (gensky clear, the facets sampled
  alone: the estimator before per-frame illumination);
- ``estimate --per-frame`` (each frame's sun, sky and exposure inferred with
  the facets, :mod:`bayesgloss.illumination`).

Goals, fixed before any result was seen (the issue's): the object's gamma
within 0.04 of the truth on average over sequences with direct sun, for
every sky category separately; overcast sequences within 0.05 or flagged
``gloss-not-identifiable`` with an interval wider than 0.5; the 90 %
interval's coverage reported. The interval is the one ``estimate`` reports,
the highest-density one (:mod:`bayesgloss.intervals`; from stop 26 on; runs
1-3 scored the equal-tailed one, which cannot hold a truth of 0); the
equal-tailed coverage is kept beside it. The truth is the bundle's ``truth.gloss``
(spec / (spec + (1 - spec) rho) for plastic, spec for metal: Fresnel
aside, which the issue "Gloss that means the material's gloss" owns).

Each bundle's scores are cached in ``studies/out/<set>/scores``
(resumable); the table and the figures go to ``studies/results/``
(``validation_radiance.json``, ``.png`` and ``_broken_cloud_sun.png``; for
``--set validation_holdout``, ``validation_holdout.*``).

Usage: python studies/validate_radiance.py [--jobs 2] [--max-sweeps 2000]
[--redo per-frame ...] (score those methods afresh, keeping the others' cached scores)
[--set validation_set|validation_holdout|...] [--merge METHOD FOLDER] (copy a
method scored on another commit's worktree into this set's scores) [--summary-only] (rebuild the
tables and figures from the committed scores, fitting nothing) [--summary-cached]
(the same from the scores cached so far, for a run stopped part way)
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
from code_under_test import check as check_code  # a sibling study (studies/ on sys.path)

from bayesgloss.intervals import reported_interval
from bayesgloss.pool import process_pool

HERE = Path(__file__).parent
#: The sets: the 48-sequence validation set, and the 24-sequence holdout drawn
#: after its first run (``configs/validation_holdout.json``).
SETS = {
    "validation_set": "validation_radiance",
    "validation_holdout": "validation_holdout",
    "validation_holdout2": "validation_holdout2",
    "validation_holdout3": "validation_holdout3",
    "validation_holdout4": "validation_holdout4",
    "validation_holdout5": "validation_holdout5",
    "validation_holdout6": "validation_holdout6",
    "validation_holdout7": "validation_holdout7",
    "validation_holdout8": "validation_holdout8",
    "validation_holdout9": "validation_holdout9",
    "validation_holdout10": "validation_holdout10",
    "validation_holdout11": "validation_holdout11",
    "validation_holdout12": "validation_holdout12",
    "validation_holdout13": "validation_holdout13",
    "validation_holdout14": "validation_holdout14",
    "validation_holdout15": "validation_holdout15",
    "validation_holdout16": "validation_holdout16",
    "validation_holdout17": "validation_holdout17",
    "validation_holdout18": "validation_holdout18",
    "validation_holdout19": "validation_holdout19",
    "validation_holdout20": "validation_holdout20",
    "validation_holdout21": "validation_holdout21",
    "validation_holdout22": "validation_holdout22",
    "validation_holdout23": "validation_holdout23",
    "validation_holdout24": "validation_holdout24",
    "validation_holdout25": "validation_holdout25",
    "validation_holdout26": "validation_holdout26",
    "validation_holdout27": "validation_holdout27",
    "validation_holdout28": "validation_holdout28",
    "validation_holdout29": "validation_holdout29",
    "validation_holdout30": "validation_holdout30",
    "validation_holdout31": "validation_holdout31",
    "validation_holdout32": "validation_holdout32",
    "validation_holdout33": "validation_holdout33",
    "mitsuba_set": "validation_mitsuba",
    "mitsuba_holdout": "validation_mitsuba_holdout",
    "mitsuba_holdout2": "validation_mitsuba_holdout2",
    "mitsuba_holdout3": "validation_mitsuba_holdout3",
    "mitsuba_holdout4": "validation_mitsuba_holdout4",
    "mitsuba_holdout5": "validation_mitsuba_holdout5",
    "mitsuba_holdout6": "validation_mitsuba_holdout6",
    "mitsuba_holdout7": "validation_mitsuba_holdout7",
    "mitsuba_holdout8": "validation_mitsuba_holdout8",
    "mitsuba_holdout9": "validation_mitsuba_holdout9",
    "mitsuba_holdout10": "validation_mitsuba_holdout10",
    "mitsuba_holdout11": "validation_mitsuba_holdout11",
    "mitsuba_holdout12": "validation_mitsuba_holdout12",
    "mitsuba_holdout13": "validation_mitsuba_holdout13",
    "mitsuba_holdout14": "validation_mitsuba_holdout14",
    "mitsuba_holdout15": "validation_mitsuba_holdout15",
    "mitsuba_holdout16": "validation_mitsuba_holdout16",
    "mitsuba_holdout17": "validation_mitsuba_holdout17",
    "mitsuba_holdout18": "validation_mitsuba_holdout18",
    "mitsuba_holdout19": "validation_mitsuba_holdout19",
}
RESULTS = HERE / "results"
#: Levels of the object posterior's quantiles kept in each score (200, evenly
#: spread inside (0, 1)): enough to redraw its interval with a model-error term.
QUANTILE_LEVELS = (np.arange(200) + 0.5) / 200
METHODS = (
    "baseline", "fixed", "per-frame", "families", "ground-kept", "overcast-variants",
    "loo-equal", "fresnel", "schlick", "lobes", "shadow", "materials", "clipped", "perez",
    "lobe-floor", "cie-families", "equal-near", "day-exposure", "ground-shadow",
    "radiance-ward", "within-10", "in-lobe", "cie-overcast", "sun-side-overcast",
    "lobes-every-sky",
)  # fmt: skip
#: Methods scored on another commit (a worktree of it, as ``perez``) and
#: copied into this set's scores under their own name (:func:`merge_scores`):
#: ``lobe-floor``, holdout 12's candidate, branch ``lobe-floor`` (the prior of
#: log n from log 6 up; studies/README.md, "holdout 12's rule"), and
#: ``cie-families``, holdout 13's, branch ``cie-families`` (CIE general skies
#: 13 and 15 in the sky families' stack; "holdout 13's rule"), and
#: ``equal-near``, its second, branch ``equal-near`` (equal weights only among
#: the families not beyond doubt behind the best where PSIS-LOO is unreliable),
#: and ``day-exposure``, Mitsuba holdout 4's, branch ``day-exposure`` (each
#: frame's unknown exposure drawn about the day's; "Mitsuba holdout 4"), on
#: the default (so in ``perez``) since stop 47: scores of ``perez`` cached
#: before then are the frames' exposures each free on its own.
SCORED_ELSEWHERE = {
    "lobe-floor": "perez",
    "cie-families": "perez",
    "equal-near": "perez",
    "day-exposure": "perez",
    # holdout 17's candidate, branch radiance-ward: the ward lobe family by
    # Radiance's own rough-specular rules (bayesgloss.radiance_ward)
    "radiance-ward": "perez",
    # holdout 18's candidate, branch tied-within-10: where PSIS-LOO is
    # unreliable, the sky families within 10 nats of the best share the weight
    "within-10": "perez",
    # holdout 18's second candidate, branch schlick-in-lobe: ggx-schlick with
    # Schlick's rise inside the lobe's integral (bayesgloss.lobes.ggx_schlick_rise_basis)
    "in-lobe": "perez",
    # holdout 21's candidate, branch cie-overcast: --overcast-variants on by default,
    # its shapes CIE types 2, 3, 4 and the uniform sky (bayesgloss.sky_families)
    "cie-overcast": "perez",
    # holdout 22's candidate (studies/patches/sun-side-overcast.patch): CIE
    # types 2 and 4 in the first sky stack (sky_families.FIRST_STACK_OVERCAST)
    "sun-side-overcast": "perez",
    # holdout 24's and Mitsuba holdout 11's candidate, branch lobes-every-sky: where
    # the sky families tie, every lobe fitted under each tied sky (stacking.fit_stacked)
    "lobes-every-sky": "perez",
    # stop 65's candidate, branch within-2se, the default since stop 66: where
    # PSIS-LOO is unreliable, a family within 2 standard errors of the best
    # shares the weight too (bayesgloss.sky_families.equal_when_unreliable,
    # UNRELIABLE_NEAR_DSE)
    "within-2se": "perez",
    # stop 66's probe on the seen pool, branch sunless-lobes: the lobe families
    # stacked on sunless days too (lobe_families' sunless_default off)
    "sunless-lobes": "perez",
    # stop 67's probe on the seen pool: sunless-lobes with every lobe's
    # roughness at most 0.5 (the exponent prior's n >= 6)
    "sunless-lobes-cap": "perez",
    # stop 69's candidate, branch sunless-lobe-error, the default since stop
    # 70: on sunless days Phong answers alone as before, the other lobes
    # fitted beside it and their spread in the model error
    # (bayesgloss.model_error.choice_spread)
    "sunless-lobe-error": "perez",
    # stop 74's candidate (studies/patches/fresnel-start.patch): the
    # one-material chain started at gamma, n, k and A profiled with the
    # data's own Fresnel model (bayesgloss.sampling.starts.starting_material)
    "fresnel-start": "perez",
    # stop 72's design on the default of stop 78 (studies/patches/day-light-fs.patch):
    # each frame's clear sun and sky about the day's trends in air mass and cos z
    # (bayesgloss.day_light), their six day-level coordinates sampled with the rest
    "day-light": "perez",
}
#: How each estimating method calls :func:`bayesgloss.estimate.estimate_bundle`.
#: Every method scored before stop 43 fits the sky families' stack of four
#: it was scored with (:data:`FOUR_SKY_FAMILIES`; the Perez shapes joined
#: the default at stop 43, after holdout 11; ``"perez"`` is that default).
FOUR_SKY_FAMILIES = {
    "per_frame": True,
    "illumination": "families",
    "perez_families": False,
    "overcast_variants": False,  # on by default since stop 57; these methods were scored without
}
ESTIMATES = {
    "fixed": {"per_frame": False},
    "per-frame": {"per_frame": True},
    "families": FOUR_SKY_FAMILIES,
    # the default with facets facing the ground kept (stop 32's change undone)
    "ground-kept": {**FOUR_SKY_FAMILIES, "ground_facing": "keep"},
    # the default with CIE type 3 and a uniform sky fitted where the overcast sky wins
    # (holdouts 4-5; since stop 57 the shapes are CIE 2, 3, 4 and uniform)
    "overcast-variants": {**FOUR_SKY_FAMILIES, "overcast_variants": True},
    # the default with equal weights where the stack's PSIS-LOO is unreliable
    "loo-equal": {**FOUR_SKY_FAMILIES, "unreliable_loo": "equal"},
    "fresnel": {**FOUR_SKY_FAMILIES, "fresnel": "radiance"},
    "schlick": {**FOUR_SKY_FAMILIES, "fresnel": "schlick"},
    "lobes": {**FOUR_SKY_FAMILIES, "lobe": "families"},
    # the lobes and a dielectric coating (GGX with Schlick's Fresnel), stacked
    "materials": {**FOUR_SKY_FAMILIES, "lobe": "materials"},
    # the default with the convex object's shadow on the ground (bayesgloss.object_shadow)
    "shadow": {**FOUR_SKY_FAMILIES, "ground_shadow": "convex"},
    # the default of stop 42 (the lobe stack) with clipped entries kept as lower
    # bounds (bayesgloss.sampling.censored)
    "clipped": {**FOUR_SKY_FAMILIES, "lobe": "materials", "clipped": "likelihood"},
    # the default since stop 43: the lobe stack, the clear-sky Perez shapes in the sky's stack
    # (bayesgloss.sky_families.PEREZ_FAMILIES); since stop 45 with no weight for the sky
    # families beyond doubt behind where PSIS-LOO is unreliable (holdout 13's "equal-near");
    # estimate's own defaults since: the day-level exposure (47), the convex ground
    # shadow (49), within-10 and the coating's rise inside the lobe (55), and the CIE
    # overcast shapes where the overcast sky wins (57, holdout 21's "cie-overcast")
    "perez": {
        "per_frame": True,
        "illumination": "families",
        "lobe": "materials",
        "perez_families": True,
    },
}
# holdout 16's candidate (stop 48): the default with the convex object's shadow on
# the ground (``estimate --ground-shadow convex``, bayesgloss.object_shadow)
ESTIMATES["ground-shadow"] = {**ESTIMATES["perez"], "ground_shadow": "convex"}
#: Methods scored by default on a set that has none cached (``--methods``).
DEFAULT_METHODS = {
    "mitsuba_set": ("families", "lobes"),
    "mitsuba_holdout": ("families", "materials"),
    "mitsuba_holdout2": ("families", "materials"),
    "mitsuba_holdout3": ("families", "materials"),
    "mitsuba_holdout4": ("baseline", "perez"),
    "mitsuba_holdout5": ("baseline", "perez"),  # and day-exposure, merged
    "mitsuba_holdout6": ("baseline", "perez", "ground-shadow"),
    "mitsuba_holdout7": ("baseline", "perez"),  # and radiance-ward, merged
    "mitsuba_holdout8": ("baseline", "perez"),  # and within-10, in-lobe, merged
    "mitsuba_holdout9": ("baseline", "perez"),  # the default after stop 55, measured
    "mitsuba_holdout10": ("baseline", "perez"),  # the floor by facet count applied (stop 59)
    "mitsuba_holdout11": ("baseline", "perez"),  # boxes; and lobes-every-sky, merged (stop 60)
    "mitsuba_holdout12": ("baseline", "perez"),  # the default after stop 61, measured (stop 62)
    "mitsuba_holdout13": ("baseline", "perez"),  # the default after stop 63, measured
    "mitsuba_holdout14": ("baseline", "perez"),  # the same, again; and within-2se, merged
    "mitsuba_holdout15": ("baseline", "perez"),  # sunless; sunless-lobe-error merged (70)
    "mitsuba_holdout16": ("baseline", "perez"),  # the default; the floor 0.01 applied (71)
    "mitsuba_holdout17": ("baseline", "perez"),  # mostly boxes; fresnel-start merged (75)
    "mitsuba_holdout18": ("baseline", "perez"),  # mostly boxes; day-light merged (78)
    "mitsuba_holdout19": ("baseline", "perez"),  # mostly boxes; day-light-lines merged (82)
    "validation_holdout4": ("baseline", "fixed", "families", "overcast-variants"),
    "validation_holdout5": ("baseline", "fixed", "families", "overcast-variants"),
    "validation_holdout6": ("baseline", "fixed", "families", "loo-equal"),
    "validation_holdout7": ("baseline", "fixed", "families", "shadow"),
    "validation_holdout8": ("baseline", "families", "materials"),
    "validation_holdout9": ("baseline", "families", "materials"),
    "validation_holdout10": ("baseline", "materials", "clipped"),
    "validation_holdout11": ("baseline", "materials", "perez"),
    "validation_holdout12": ("baseline", "perez"),  # and lobe-floor, merged
    "validation_holdout13": ("baseline", "perez"),  # and cie-families, equal-near, merged
    "validation_holdout14": ("baseline", "perez"),
    "validation_holdout15": ("baseline", "perez"),  # and day-exposure, merged
    "validation_holdout16": ("baseline", "perez", "ground-shadow"),
    "validation_holdout17": ("baseline", "perez"),  # and radiance-ward, merged
    "validation_holdout18": ("baseline", "perez"),  # and within-10, in-lobe, merged
    "validation_holdout19": ("baseline", "perez"),  # the default after stop 55, measured
    "validation_holdout20": ("baseline", "perez"),  # the default after holdout 21, measured
    "validation_holdout21": ("baseline", "perez"),  # sunless days; and cie-overcast, merged
    "validation_holdout22": ("baseline", "perez"),  # and sun-side-overcast, merged (stop 58)
    "validation_holdout23": ("baseline", "perez"),  # the floor by facet count applied (stop 59)
    "validation_holdout24": ("baseline", "perez"),  # boxes; and lobes-every-sky, merged (stop 60)
    "validation_holdout25": ("baseline", "perez"),  # the default after stop 61, measured (stop 62)
    "validation_holdout26": ("baseline", "perez"),  # the default after stop 63, measured
    "validation_holdout27": ("baseline", "perez"),  # sunless days; the sun floor's second test
    "validation_holdout28": ("baseline", "perez"),  # the default again; within-2se merged
    "validation_holdout29": ("baseline", "perez"),  # sunless; sunless-lobe-error merged (70)
    "validation_holdout30": ("baseline", "perez"),  # the default; the floor 0.01 applied (71)
    "validation_holdout31": ("baseline", "perez"),  # mostly boxes; fresnel-start merged (75)
    "validation_holdout32": ("baseline", "perez"),  # mostly boxes; day-light merged (78)
    "validation_holdout33": ("baseline", "perez"),  # mostly boxes; day-light-lines merged (82)
}


def direct_sun(truth: dict) -> bool:
    """Whether the sequence had a sun in its sky (not overcast)."""
    sky = truth.get("sky", "")
    if sky == "gensky-overcast":
        return False
    if sky.startswith("cie-"):
        return int(sky.split("-")[1]) >= 6
    return True


def material_class(truth: dict) -> str | None:
    """Scoring class of a bundle's material: smooth or rough, plastic or metal
    (the Mitsuba renderer writes it as ``material_class``; a Radiance
    material is smooth where its roughness is 0)."""
    if "material_class" in truth:
        return truth["material_class"]
    if truth.get("material") not in ("plastic", "metal"):
        return None
    smooth = "smooth" if not truth.get("roughness") else "rough"
    return f"{smooth}-{truth['material']}"


def lambertian_indirect_gloss(truth: dict) -> bool:
    """Whether Radiance rendered the bundle's material with Lambertian indirect
    gloss (:meth:`bayesgloss.sequences.SequenceConfig.lambertian_indirect_gloss`:
    rough, and no more specular than rtrace's ``-st``): its truth's flag, or
    for bundles written before the flag, from its config."""
    if "lambertian_indirect_gloss" in truth:
        return bool(truth["lambertian_indirect_gloss"])
    if truth.get("renderer") != "radiance" or "config" not in truth:
        return False
    from bayesgloss.sequences import SequenceConfig

    return SequenceConfig.from_dict(truth["config"]).lambertian_indirect_gloss()


def _overcast_lost(entry: dict | None) -> bool:
    """Whether a default estimate's stack gave gensky's overcast sky less
    weight than another family (so ``overcast_variants`` fits nothing more:
    the same fit as the default's, same seed)."""
    stack = (entry or {}).get("sky_families")
    return bool(stack) and stack["most_weight"] != "gensky-overcast"


def _loo_reliable(entry: dict | None) -> bool:
    """Whether a default estimate's stack rests on reliable PSIS-LOO (so
    ``unreliable_loo="equal"`` keeps its weights: the same fit, same seed)."""
    from bayesgloss.sky_families import loo_unreliable

    stack = (entry or {}).get("sky_families")
    return bool(stack) and not loo_unreliable(stack.get("high_k_share", 1.0))


def _faces_ground(b) -> bool:
    """Whether the default leaves any facet of bundle ``b`` out as facing the ground."""
    from bayesgloss.ground_facing import facets_facing_ground

    return bool(facets_facing_ground(b.facets.normal, b.has_mesh).any())


def calibration_figure(scores: list[dict], path: Path, methods) -> dict | None:
    """Nominal against observed coverage of the central intervals of the
    object's gamma, per material class, from each score's ``pit`` (the
    posterior CDF at the truth; a central interval of level c holds the
    truth where |pit - 0.5| <= c / 2); direct-sun sequences. None where no
    score has one.

    Where the posterior has an atom at the truth (the reported draws are
    clipped to [0, 1], and a matt metal's truth is exactly 0) the PIT is
    randomised within it (Czado, Gneiting & Held 2009): pit + u (pit_le -
    pit), u ~ U(0, 1) from a fixed seed, with ``pit_le`` the share of draws
    at or below the truth (scores of stop 32 on; older ones have none, and
    a truth on the atom then never falls in a central interval)."""
    rows = [s for s in scores if s["direct_sun"] and s.get("class")]
    levels = np.linspace(0.1, 0.9, 9)
    u = np.random.default_rng(0).uniform(size=len(rows))
    out = {}
    for m in methods:
        for cls in sorted({s["class"] for s in rows}):
            pits = [
                s[m]["pit"] + u[i] * (s[m].get("pit_le", s[m]["pit"]) - s[m]["pit"])
                for i, s in enumerate(rows)
                if s["class"] == cls and s.get(m, {}).get("pit") is not None
            ]
            if pits:
                dist = np.abs(np.asarray(pits) - 0.5)
                out.setdefault(m, {})[cls] = {
                    "n": len(pits),
                    "observed": [float(np.mean(dist <= c / 2)) for c in levels],
                }
    if not out:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(out), figsize=(4.2 * len(out), 4.2), squeeze=False)
    for ax, (m, classes) in zip(axes[0], out.items(), strict=True):
        for cls, row in classes.items():
            ax.plot(levels, row["observed"], "o-", ms=3, label=f"{cls} ({row['n']})")
        ax.plot([0, 1], [0, 1], "k:", lw=0.8)
        ax.set(xlabel="nominal coverage", ylabel="observed coverage", title=m, xlim=(0, 1))
        ax.set_ylim(0, 1)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"levels": levels.tolist(), **out}


def class_table(scores: list[dict]) -> dict:
    """Per material class and method: MAE and 90 % coverage (the reported
    interval) on direct-sun sequences."""
    out = {}
    for cls in sorted({s.get("class") for s in scores if s.get("class")}):
        sun = [
            s
            for s in scores
            if s.get("class") == cls and s["direct_sun"] and s["truth"] is not None
        ]
        for m in METHODS:
            rows = [s for s in sun if m in s]
            if not rows:
                continue
            out.setdefault(cls, {})[m] = {
                "n": len(rows),
                "mae_direct_sun": float(np.mean([abs(s[m]["median"] - s["truth"]) for s in rows])),
                "coverage90_direct_sun": float(np.mean([_holds(s[m], s["truth"]) for s in rows]))
                if m != "baseline"
                else None,
            }
    return out


def score_bundle(path: str, max_sweeps: int, methods=METHODS, out: dict | None = None) -> dict:
    """The estimates ``methods`` of one bundle (the truth read only to score),
    added to ``out`` (a cached score) or to a new one."""
    from bayesgloss import baseline, estimate
    from bayesgloss import bundle as bundle_io

    warnings.simplefilter("ignore")
    b = bundle_io.read_bundle(path)
    truth = b.truth or {}
    out = dict(out or {})
    out |= {
        "bundle": Path(path).name,
        "category": truth.get("config", {}).get("category", truth.get("sky")),
        "sky": truth.get("sky"),
        "truth": truth.get("gloss"),
        "direct_sun": direct_sun(truth),
        "class": material_class(truth),
        "lambertian_indirect_gloss": lambertian_indirect_gloss(truth),
        "encoding": b.pixel_encoding,
        "facets": len(b.facets.ids),
    }
    if "baseline" in methods:
        t0 = time.perf_counter()
        base = baseline.bundle_peak_frame_gloss(b)
        out["baseline"] = {"median": float(base.object_gloss), "seconds": time.perf_counter() - t0}
    if "lobes" in methods and "families" in methods:
        # read off the lobes fit below (its Phong fit's own posterior: the
        # default's before the model error was added to its interval, stop 30)
        methods = [m for m in methods if m != "families"]
    for name, kwargs in ESTIMATES.items():
        if name not in methods:
            continue
        if name == "ground-kept" and "families" in out and not _faces_ground(b):
            out[name] = {**out["families"], "same_fit_as": "families"}  # nothing left out
            continue
        if name == "overcast-variants" and _overcast_lost(out.get("families")):
            out[name] = {**out["families"], "same_fit_as": "families"}  # no variant fitted
            continue
        if name == "loo-equal" and _loo_reliable(out.get("families")):
            out[name] = {**out["families"], "same_fit_as": "families"}  # weights kept
            continue
        per_frame = kwargs["per_frame"]
        t0 = time.perf_counter()
        res = estimate.estimate_bundle(b, **kwargs, sampler_options={"max_steps": max_sweeps})
        obj = res.summary["object"]
        post = res.idata.posterior
        # the reported answer's draws: with the model's error where estimate adds it
        draws = next((post[v] for v in ("gamma_material", "gamma_object") if v in post), None)
        out[name] = {
            **{k: obj["gamma"][k] for k in ("median", "q05", "q95", "hdi90")},
            # the posterior's CDF at the truth (for calibration at every level)
            "pit": None
            if draws is None or truth.get("gloss") is None
            else float(np.mean(draws.values < truth["gloss"])),
            # at or below: the two differ where the draws have an atom at the truth
            "pit_le": None
            if draws is None or truth.get("gloss") is None
            else float(np.mean(draws.values <= truth["gloss"])),
            "flags": obj.get("flags", []),
            "model": res.summary["sampler"]["model"],
            "illumination": res.summary["illumination"],
            "seconds": time.perf_counter() - t0,
        }
        # what a model-error term is computed from (bayesgloss.model_error):
        # each facet's own posterior, and the object's posterior as quantiles
        if "gamma_object" in post:  # the model's own posterior, the model error aside
            own = post["gamma_object"].values
            out[name]["object_quantiles"] = np.quantile(own, QUANTILE_LEVELS).tolist()
            out[name]["within_model"] = reported_interval(obj["gamma_within_model"])
            out[name]["model_error"] = obj["model_error"]
        if "gamma" in post:
            g = post["gamma"].values.reshape(-1, post["gamma"].shape[-1])
            out[name]["facet_gamma"] = {"mean": g.mean(0).tolist(), "sd": g.std(0).tolist()}
            # each facet's reported interval (with the model error) and its own
            seen = [f for f in res.summary["facets"] if f["gamma"]]
            out[name]["facet_hdi90"] = [reported_interval(f["gamma"]) for f in seen]
            out[name]["facet_within_hdi90"] = [
                reported_interval(f.get("gamma_within_model", f["gamma"])) for f in seen
            ]
        if per_frame and "frames" in res.summary:
            frames = res.summary["frames"]
            out[name]["frame"] = [f["frame"] for f in frames]
            for v in ("sun", "sky"):
                out[name][v] = [f[v]["median"] for f in frames]
                out[name][f"{v}_q05"] = [f[v]["q05"] for f in frames]
                out[name][f"{v}_q95"] = [f[v]["q95"] for f in frames]
            out[name]["sky_models"] = res.summary.get("sky_models")
        if "sky_families" in res.summary:
            out[name]["sky_families"] = res.summary["sky_families"]
        if "lobe_families" in res.summary:
            lobes = res.summary["lobe_families"]
            out[name]["lobe_families"] = lobes
            if "families" not in out and name == "lobes":  # the Phong fit over the sky families
                g = lobes["phong"]["gamma"]  # is exactly estimate's default answer (same seed)
                out["families"] = {
                    **{k: g[k] for k in ("median", "q05", "q95", "hdi90")},
                    "flags": ["gloss-not-identifiable"]
                    if np.ptp(g["hdi90"]) > estimate.NOT_IDENTIFIABLE_WIDTH
                    else [],
                    "model": "joint, one fit per sky family, stacked (read off 'lobes')",
                    "illumination": "families",
                }
    return out


def _within_2se_acts(entry: dict) -> bool:
    """Whether stop 65's ``within-2se`` can answer otherwise than the
    default whose ``perez`` entry is ``entry`` (:data:`CANDIDATE_ACTS`):
    a family left out more than 10 nats behind but not beyond doubt by
    ``sky_families``' margins (on main since stop 66)."""
    from bayesgloss.sky_families import (
        UNRELIABLE_NEAR_DSE,
        UNRELIABLE_NEAR_NATS,
        behind_beyond_doubt,
    )

    sky = entry.get("sky_families") or {}
    families = dict(sky.get("families") or {})
    if sky.get("equal_weights") and not families:
        return True
    lobes = [v for v in (entry.get("lobe_families") or {}).values() if isinstance(v, dict)]
    if any("weight_by_sky" in v for v in lobes):
        return True
    rows = list(families.values()) + [v for v in lobes if "elpd_diff" in v]
    return any(
        r.get("weight", 1.0) == 0.0
        and r["elpd_diff"] > UNRELIABLE_NEAR_NATS
        and not behind_beyond_doubt(r, UNRELIABLE_NEAR_NATS, UNRELIABLE_NEAR_DSE)
        for r in rows
    )


def _lobes_not_stacked(entry: dict) -> bool:
    """The default answered with Phong alone because the day's most-weighted
    sky was an overcast one (flagged ``lobe-family-not-stacked``): where
    the sunless-lobes probes act."""
    return "lobe-family-not-stacked" in entry.get("flags", [])


#: Where a candidate scored on its own commit (as ``perez``) can answer
#: otherwise than the default: a test of the default's ``perez`` entry of the
#: same bundle. Where it is false the candidate runs the default's fits
#: exactly (same seeds, same code on that path), so its answer is copied
#: instead of fitted again (``--candidate``, :func:`_cached`):
#: ``within-10`` changes only the weights that ``equal_when_unreliable``
#: gives where its guard acts (flagged ``sky-family-not-identifiable``);
#: ``in-lobe`` only the ``ggx-schlick`` fit of the lobe stack, which runs
#: where the lobe families were stacked (a ``ggx-schlick`` entry);
#: ``lobes-every-sky`` only where the sky families tied and the lobes were
#: therefore not stacked (flagged both ``sky-family-not-identifiable`` and
#: ``lobe-family-not-stacked``); ``within-2se`` only where a sky or lobe
#: family got no weight while more than 10 nats but at most 2 standard
#: errors behind, or where the lobes were weighed under each tied sky
#: (their weights under each sky are not all kept), or where the sky
#: families' record is empty (:func:`_within_2se_acts`); ``sunless-lobes``
#: and ``sunless-lobes-cap`` only where the lobes were not stacked
#: (:func:`_lobes_not_stacked`).
CANDIDATE_ACTS = {
    "within-10": lambda entry: "sky-family-not-identifiable" in entry.get("flags", []),
    "in-lobe": lambda entry: "ggx-schlick" in (entry.get("lobe_families") or {}),
    "lobes-every-sky": lambda entry: (
        {"sky-family-not-identifiable", "lobe-family-not-stacked"} <= set(entry.get("flags", []))
    ),
    "within-2se": _within_2se_acts,
    "sunless-lobes": _lobes_not_stacked,
    "sunless-lobes-cap": _lobes_not_stacked,
}


def _same_as_default(path: Path, candidate: tuple | None) -> dict | None:
    """The default's score of this bundle: its ``perez`` entry, marked
    ``same_fit_as``, with the bundle's description (truth, category, class,
    ...; no other method), where ``candidate`` (its name, the default's score
    folder) cannot change it (:data:`CANDIDATE_ACTS`); None where it can, or
    the default has not scored the bundle yet."""
    if candidate is None:
        return None
    name, folder = candidate
    file = Path(folder) / f"{path.name}.json"
    if not file.exists():
        return None
    record = json.loads(file.read_text())
    entry = record.get("perez")
    if entry is None or CANDIDATE_ACTS[name](entry):
        return None
    about = {k: v for k, v in record.items() if k not in METHODS}
    return {**about, "perez": {**entry, "same_fit_as": "default"}}


def _cached(
    path: Path,
    max_sweeps: int,
    redo=(),
    scores: Path | None = None,
    committed: dict | None = None,
    methods=METHODS,
    candidate: tuple | None = None,
) -> dict:
    """The scores of one bundle, from the cache in ``scores`` where it has
    them, else from ``committed`` (the set's committed results, by bundle
    name: a fresh checkout recomputes only what they lack); the methods in
    ``redo`` (and any the cache lacks) computed afresh. ``candidate``
    (name, the default's score folder): ``perez`` copied from the default
    where the candidate cannot change it (:func:`_same_as_default`)."""
    scores = scores or path.parent.parent / "scores"
    scores.mkdir(parents=True, exist_ok=True)
    file = scores / f"{path.name}.json"
    if file.exists():
        out = json.loads(file.read_text())
    else:
        out = dict((committed or {}).get(path.name, {}))
    todo = [m for m in methods if m in redo or m not in out]
    same = _same_as_default(path, candidate) if "perez" in todo else None
    if same is not None:  # the bundle's description too: the summary reads it
        out = {**same, **out, "perez": same["perez"]}
        todo.remove("perez")
    if todo:
        out = score_bundle(str(path), max_sweeps, todo, out)
    if todo or same is not None:
        file.write_text(json.dumps(out, indent=1))
    return out


def merge_scores(scores: Path, other: Path, method: str) -> int:
    """Copy each bundle's ``SCORED_ELSEWHERE[method]`` score from the cache
    ``other`` (a worktree's) into the cache ``scores`` as ``method``; the
    number of bundles copied."""
    copied = 0
    for file in sorted(other.glob("*.json")):
        mine = scores / file.name
        if not mine.exists():
            continue
        out = json.loads(mine.read_text())
        out[method] = json.loads(file.read_text())[SCORED_ELSEWHERE[method]]
        mine.write_text(json.dumps(out, indent=1))
        copied += 1
    return copied


def unpack_scores(results: Path, scores: Path) -> int:
    """Write each sequence of a set's committed results (``results``, a
    ``validation_<set>.json``) into the score cache ``scores``, one
    ``<bundle>.json`` a bundle, as scoring wrote it there, leaving a file
    already there as it is; the number written. A new machine has the
    results but not the cache, which ``--candidate`` reads the default's
    scores from."""
    scores.mkdir(parents=True, exist_ok=True)
    written = 0
    for entry in json.loads(results.read_text())["sequences"]:
        file = scores / f"{entry['bundle']}.json"
        if not file.exists():
            file.write_text(json.dumps(entry, indent=1))
            written += 1
    return written


def _holds(entry: dict, truth: float) -> bool:
    """Whether the interval bayesgloss reports (:mod:`bayesgloss.intervals`;
    quantiles in scores cached before it had one) holds the truth."""
    lo, hi = reported_interval(entry)
    return lo <= truth <= hi


def confident_miss(entry: dict, truth: float) -> bool:
    """The truth outside a reported interval narrower than 0.5."""
    return not _holds(entry, truth) and np.ptp(reported_interval(entry)) < 0.5


def overcast_ok(entry: dict, truth: float) -> bool:
    """The overcast rule on one sunless sequence: within 0.05 of the truth, or
    flagged ``gloss-not-identifiable`` with a reported interval wider than 0.5."""
    if abs(entry["median"] - truth) <= 0.05:
        return True
    return "gloss-not-identifiable" in entry["flags"] and np.ptp(reported_interval(entry)) > 0.5


def methods_run(scores: list[dict]) -> list[str]:
    """The methods of :data:`METHODS` that any of ``scores`` holds, in that order."""
    return [m for m in METHODS if any(m in s for s in scores)]


def table(scores: list[dict]) -> dict:
    """Per category and method: MAE and 90 % coverage on direct-sun sequences,
    and the overcast sequences' outcome."""
    out = {}
    cats = sorted({s["category"] for s in scores})
    for cat in [*cats, "all"]:
        rows = [s for s in scores if cat in ("all", s["category"]) and s["truth"] is not None]
        sun = [s for s in rows if s["direct_sun"]]
        entry = {"sequences": len(rows), "direct_sun": len(sun)}
        for m in methods_run(scores):
            # the baseline has no answer where no facet has the sun at its peak (NaN)
            err = [abs(s[m]["median"] - s["truth"]) for s in sun if m in s]
            err = [x for x in err if np.isfinite(x)]
            e = {"mae_direct_sun": float(np.mean(err)) if err else None}
            if m == "baseline":
                e["answered"] = len(err)
            if m != "baseline":
                cover = [_holds(s[m], s["truth"]) for s in sun if m in s]
                e["coverage90_direct_sun"] = float(np.mean(cover)) if cover else None
                # the model's own interval, where the score has it (stop 30 on)
                own = [
                    s[m]["within_model"][0] <= s["truth"] <= s[m]["within_model"][1]
                    for s in sun
                    if "within_model" in s.get(m, {})
                ]
                if own:
                    e["coverage90_within_model_direct_sun"] = float(np.mean(own))
                # each facet's interval on the sun-lit days (the truth is the object's)
                for key, name in (("facet_hdi90", "facets"), ("facet_within_hdi90", "facets_own")):
                    held = [
                        lo <= s["truth"] <= hi for s in sun for lo, hi in s.get(m, {}).get(key, [])
                    ]
                    if held:
                        e[f"coverage90_{name}_direct_sun"] = float(np.mean(held))
                # confident misses: the truth outside a reported interval narrower than 0.5
                e["confident_misses_direct_sun"] = [
                    s["bundle"][:4] for s in sun if m in s and confident_miss(s[m], s["truth"])
                ]
                tails = [s[m]["q05"] <= s["truth"] <= s[m]["q95"] for s in sun if m in s]
                e["coverage90_equal_tailed_direct_sun"] = float(np.mean(tails)) if tails else None
                over = [s for s in rows if not s["direct_sun"] and m in s]
                e["overcast_ok"] = int(sum(overcast_ok(s[m], s["truth"]) for s in over))
                e["overcast"] = len(over)
                e["not_converged"] = sum("not-converged" in s[m]["flags"] for s in rows if m in s)
            out.setdefault(cat, {})[m] = e
        out[cat]["n"] = entry
    return out


def figure(
    scores: list[dict], path: Path, methods=METHODS, title="Radiance validation set"
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(methods), figsize=(4.3 * len(methods), 4.5), sharey=True)
    axes = np.atleast_1d(axes)
    cats = sorted({s["category"] for s in scores})
    colours = dict(zip(cats, plt.cm.tab10(np.arange(len(cats))), strict=False))
    for ax, m in zip(axes, methods, strict=True):
        if not any(m in s for s in scores):
            ax.set_title(f"{m} (not run)")
        for s in scores:
            if s["truth"] is None or m not in s:
                continue
            y = s[m]["median"]
            marker = "o" if s["direct_sun"] else "x"
            if m != "baseline":
                lo, hi = reported_interval(s[m])
                ax.errorbar(
                    s["truth"],
                    y,
                    yerr=[[y - lo], [hi - y]],
                    color=colours[s["category"]],
                    marker=marker,
                    ms=4,
                    lw=0.8,
                )
            else:
                ax.plot(s["truth"], y, marker, color=colours[s["category"]], ms=4)
        ax.plot([0, 1], [0, 1], "k:", lw=0.8)
        ax.set_title(m)
        ax.set_xlabel("true gamma")
        ax.set_xlim(-0.05, 1.05)
        ax.set_ylim(-0.05, 1.05)
    axes[0].set_ylabel("object gamma (median, 90 % interval)")
    handles = [plt.Line2D([], [], color=colours[c], marker="o", ls="") for c in cats]
    fig.legend(handles, cats, loc="lower center", ncol=min(len(cats), 2 * len(methods)), fontsize=8)
    fig.suptitle(f"{title}: o direct sun, x overcast")
    fig.tight_layout(rect=(0, 0.14 if len(methods) < 4 else 0.08, 1, 0.95))
    fig.savefig(path, dpi=120)


#: gensky's three CIE skies and the name of the estimator's sky family for each.
GENSKY_FAMILIES = {
    "gensky-clear": "gensky-clear",
    "gensky-intermediate": "gensky-intermediate",
    "gensky-overcast": "gensky-overcast",
}

#: The method whose answers the family table and the broken-cloud figure
#: describe: ``estimate``'s default, then the older per-frame mixture (sets
#: scored before the default had sky families: the first holdout, the
#: validation set).
NAMING_METHODS = ("families", "per-frame")


def _naming_entry(score: dict) -> tuple[str, dict] | tuple[None, None]:
    """The first of :data:`NAMING_METHODS` that ``score`` holds, and its entry."""
    for method in NAMING_METHODS:
        if method in score:
            return method, score[method]
    return None, None


def named_family(entry: dict) -> str | None:
    """The sky family an estimate named.

    With stacked sky families (``sky_families``), the most-weighted family;
    where that is the per-frame mixture ``auto``, the mixture's most-weighted
    sky model (``sky_models``), so that a day the mixture fits best is still
    named by the shape it found. Without stacking (the per-frame mixture
    alone), the mixture's most-weighted model. None where the entry holds
    neither (a fixed-brightness fit).
    """
    stack = entry.get("sky_families")
    models = entry.get("sky_models") or {}
    if stack:
        best = stack["most_weight"]
        return models.get("most_weight", best) if best == "auto" else best
    return models.get("most_weight")


def family_table(scores: list[dict]) -> dict:
    """Which sky family the default estimate names, per rendering sky
    (:func:`named_family`): named right for gensky's skies (the issue's
    goal: at least 90 %), and what wins for the others, with the stack's
    weight of the winner (median over the category's sequences)."""
    out, weights, named = {}, {}, []
    for s in scores:
        method, entry = _naming_entry(s)
        win = None if entry is None else named_family(entry)
        if win is None:
            continue
        cat = s["category"]
        row = out.setdefault(cat, {"sequences": 0, "method": method, "most_weight": {}, "right": 0})
        row["sequences"] += 1
        row["most_weight"][win] = row["most_weight"].get(win, 0) + 1
        row["right"] += GENSKY_FAMILIES.get(s["sky"]) == win
        if stack := entry.get("sky_families"):
            weights.setdefault(cat, []).append(stack["families"][stack["most_weight"]]["weight"])
        # every sequence rendered under one of gensky's skies, whatever its
        # category (an auto-exposure day's sky is one of them too)
        if s.get("sky") in GENSKY_FAMILIES:
            named.append(GENSKY_FAMILIES[s["sky"]] == win)
    for cat, w in weights.items():
        out[cat]["median_weight"] = float(np.median(w))
    out["gensky_named_right"] = {"right": sum(named), "sequences": len(named)}
    return out


def sun_figure(scores: list[dict], bundles: Path, path: Path) -> dict:
    """Broken-cloud days: each frame's inferred sun brightness against the DNI
    that rendered it, both relative to their medians over the frames whose
    beam was not cut (the level is the exposure's and the scale's; the
    shape over the day is what the object tells). Returns the points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 4.8))
    points = {}
    for s in scores:
        pf = _naming_entry(s)[1] or {}
        if s["category"] != "broken-cloud" or "frame" not in pf:
            continue
        manifest = bundles / s["bundle"] / "sequence.json"
        if not manifest.exists():  # the set not rendered here: no DNI to plot against
            print(f"broken-cloud figure: {manifest} not found, {s['bundle']} left out")
            continue
        truth = json.loads(manifest.read_text())["truth"]
        dni = np.asarray(truth["dni"], float)[pf["frame"]]
        sun, lo, hi = (np.asarray(pf[k], float) for k in ("sun", "sun_q05", "sun_q95"))
        clear = dni > 0.5 * dni.max()
        ref_dni, ref_sun = np.median(dni[clear]), np.median(sun[clear])
        x, y = dni / ref_dni, sun / ref_sun
        ax.errorbar(
            x,
            y,
            yerr=[y - lo / ref_sun, hi / ref_sun - y],
            fmt="o",
            ms=4,
            lw=0.8,
            label=s["bundle"][:20],
        )
        points[s["bundle"]] = {"dni_relative": x.tolist(), "sun_relative": y.tolist()}
    ax.plot([0, 1.3], [0, 1.3], "k--", lw=0.8)
    ax.set(
        xlabel="rendered DNI / its median over unclouded frames",
        ylabel="inferred sun / its median over those frames",
        title="broken-cloud days: each frame's sun (90 %)",
    )
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return points


def write_summary(scores: list[dict], set_name: str, max_sweeps: int) -> dict:
    """The tables and figures of a set's scores, written to ``studies/results/``."""
    bundles = HERE / "out" / set_name / "bundles"
    name = SETS[set_name]
    RESULTS.mkdir(exist_ok=True)
    summary = {
        "max_sweeps": max_sweeps,
        "table": table(scores),
        "sky_families": family_table(scores),
        "classes": class_table(scores),
        "sequences": scores,
    }
    summary["broken_cloud_sun"] = sun_figure(
        scores, bundles, RESULTS / f"{name}_broken_cloud_sun.png"
    )
    run = methods_run(scores)
    mitsuba = set_name.startswith("mitsuba")
    title = "Mitsuba validation set" if mitsuba else "Radiance validation set"
    figure(scores, RESULTS / f"{name}.png", run, title)
    calibration = calibration_figure(scores, RESULTS / f"{name}_calibration.png", run)
    if calibration is not None:
        summary["calibration"] = calibration
    (RESULTS / f"{name}.json").write_text(json.dumps(summary, indent=1))
    return summary


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--max-sweeps", type=int, default=2000)
    ap.add_argument("--set", default="validation_set", choices=tuple(SETS))
    ap.add_argument(
        "--redo", nargs="*", default=[], choices=METHODS, help="methods to score afresh"
    )
    ap.add_argument("--methods", nargs="*", default=None, choices=METHODS, help="methods to score")
    ap.add_argument(
        "--merge",
        nargs=2,
        metavar=("METHOD", "FOLDER"),
        help="copy a method of SCORED_ELSEWHERE from another worktree's score cache, and stop",
    )
    ap.add_argument(
        "--candidate",
        nargs=2,
        metavar=("NAME", "FOLDER"),
        help="score a candidate of CANDIDATE_ACTS on its own commit (as 'perez'), copying "
        "the default's answer from its score FOLDER where the candidate cannot change it",
    )
    ap.add_argument(
        "--unpack",
        action="store_true",
        help="fit nothing: write the set's committed scores into its score folder, one file "
        "a bundle (for --candidate on a machine that has the results but not the folder)",
    )
    ap.add_argument(
        "--summary-only",
        action="store_true",
        help="fit nothing: rebuild the tables and figures from the set's committed scores "
        "(the broken-cloud figure needs the set's bundles)",
    )
    ap.add_argument(
        "--summary-cached",
        action="store_true",
        help="fit nothing: write the tables and figures of the scores cached so far "
        "(a run stopped part way; its results then hold only the bundles scored)",
    )
    args = ap.parse_args(argv)
    check_code("validate_radiance")  # a candidate's worktree on PYTHONPATH is the code scored
    methods = args.methods or DEFAULT_METHODS.get(args.set, METHODS)
    if args.merge:  # another worktree's scores of the same set, under their own name
        method, folder = args.merge
        if method not in SCORED_ELSEWHERE:
            raise SystemExit(
                f"validate_radiance: --merge: {method!r} is not scored elsewhere; "
                f"one of {sorted(SCORED_ELSEWHERE)}"
            )
        if not Path(folder).is_dir():
            raise SystemExit(f"validate_radiance: --merge: {folder}: no such score folder")
        n = merge_scores(HERE / "out" / args.set / "scores", Path(folder), method)
        print(
            f"{n} bundles' '{SCORED_ELSEWHERE[method]}' scores from {folder} copied as '{method}'"
        )
        return
    results = RESULTS / f"{SETS[args.set]}.json"
    if args.unpack:
        if not results.exists():
            raise SystemExit(f"validate_radiance: --unpack: {results}: no committed scores")
        scores = HERE / "out" / args.set / "scores"
        print(f"{unpack_scores(results, scores)} bundles' scores written to {scores}")
        return
    candidate = None
    if args.candidate:
        name, folder = args.candidate
        if name not in CANDIDATE_ACTS:
            raise SystemExit(
                f"validate_radiance: --candidate: {name!r} is not one of {sorted(CANDIDATE_ACTS)}"
            )
        if not Path(folder).is_dir():
            raise SystemExit(f"validate_radiance: --candidate: {folder}: no such score folder")
        candidate = (name, str(Path(folder).resolve()))
    fitting = not (args.summary_only or args.summary_cached)
    elsewhere = set(methods) & set(SCORED_ELSEWHERE) if fitting else set()
    if elsewhere:
        raise SystemExit(
            f"validate_radiance: {sorted(elsewhere)} are scored on another commit; use --merge"
        )
    bundles = HERE / "out" / args.set / "bundles"
    committed = {}
    if results.exists():
        saved = json.loads(results.read_text())
        committed = {s["bundle"]: s for s in saved["sequences"]}
    if args.summary_cached:
        cached = sorted((HERE / "out" / args.set / "scores").glob("*.json"))
        scores = [json.loads(f.read_text()) for f in cached]
        scores = [s for s in scores if all(m in s for m in methods)]
        print(f"{len(scores)} bundles scored by {', '.join(methods)}")
        summary = write_summary(scores, args.set, args.max_sweeps)
    elif args.summary_only:
        if not committed:
            raise SystemExit(f"validate_radiance: no scores in {results} to summarise")
        summary = write_summary(list(committed.values()), args.set, saved["max_sweeps"])
    else:
        paths = sorted(p for p in bundles.iterdir() if (p / "sequence.json").exists())
        with process_pool(args.jobs) as pool:  # one BLAS thread a worker: arms run side by side
            n = len(paths)
            scores = list(
                pool.map(
                    _cached,
                    paths,
                    [args.max_sweeps] * n,
                    [args.redo] * n,
                    [None] * n,
                    [committed] * n,
                    [methods] * n,
                    [candidate] * n,
                )
            )
        summary = write_summary(scores, args.set, args.max_sweeps)
    for cat, row in summary["table"].items():
        print(cat, json.dumps(row))
    print("sky families:", json.dumps(summary["sky_families"]))


if __name__ == "__main__":
    main()
