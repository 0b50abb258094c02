"""One fit per choice of a model's part, stacked by PSIS-LOO under the day's sky.

The glossy lobe's family (:mod:`bayesgloss.lobe_families`) and the albedo of
a non-convex object's own faces (:mod:`bayesgloss.occluder_albedo`) are
parts of the one-material model that nobody tells the estimator. Each is
averaged the same way: the joint model
(:func:`bayesgloss.joint_estimate.joint_fit`) is fitted once for each choice
(a value of one of its options), and the object's gloss is the mixture of
the fits' posteriors with the stacking weights of their leave-one-out
predictive densities (Yao, Vehtari, Simpson & Gelman 2018;
:func:`bayesgloss.sky_families.loo_stacking_weights`). A choice the data
cannot tell from another then widens the object's interval instead of
biasing it.

Stacking weights are not identified among fits whose predictive densities
are the same: any split of the weight between them is optimal, and the
optimiser may hand all of it to one (Mitsuba holdout 1, ms16: four lobe
fits of an overcast day within 0.61 of each other in elpd, gammas 0.11 to
0.95, Ward given weight 1.00, the object read 0.94 for a true 0.10). With
``ties="spread"`` (:func:`spread_tied_weights`) the fits tied with the best
share their weight evenly, the uniform prior over choices the data do not
tell apart, so the interval carries every tied answer.

The sky is chosen first: with ``illumination="families"`` the sky families
are stacked with the part's default choice
(:func:`bayesgloss.sky_families.fit_families`) and the other choices are
fitted under the most-weighted sky family, so a part of k choices costs
k - 1 fits more than the sky alone (not k times as many); with a named sky
(or ``"auto"``) every choice is fitted under it. The default choice's
component of the mixture keeps the sky mixture's draws.

Where the sky families were given equal weights because their PSIS-LOO is
unreliable (:func:`bayesgloss.sky_families.equal_when_unreliable`: the
day's sky is not identified, as on most objects of 1-3 facets), a choice
fitted under one sky would drop the sky's uncertainty the equal mixture
carries (stop 35: a box's answer narrowed to one sky's fit while flagged
``sky-family-not-identifiable``). Two ways out (``unidentified_sky``):

- ``"default-alone"`` (the default until stop 61): the other choices are not fitted;
  the answer is the default choice's sky mixture, and the record says the
  part was not stacked. The part's uncertainty is then dropped instead:
  every box was answered by the Phong lobe alone, and on Mitsuba's boxes
  (GGX lobes, Fresnel) 5 of 14 sun-lit intervals of the seen holdouts 7-9
  missed, rough plastics read 0.30-0.76 for 0.07-0.18.
- ``"every-near-sky"`` (:func:`_stacked_under_near_skies`): every choice is
  fitted under each sky family that shares the weight, the choices are
  weighed within each sky as elsewhere (with the same guard: where their
  PSIS-LOO is unreliable too, those not behind beyond doubt
  (:func:`~bayesgloss.sky_families.equal_when_unreliable`) share
  the weight evenly), and the answer is the mixture over (sky, choice)
  with weight w_sky w_choice|sky: the sky's uncertainty and the part's
  both carried. It costs (choices - 1) fits per near sky, cheap on the few
  facets where it acts. The default since stop 61, by a rule written
  before its sets were drawn (holdout 24 and Mitsuba holdout 11, 32 boxes:
  interval held 22 of 26 sun-lit against 19, confident misses 3 against
  7; ``studies/README.md``).
"""

from __future__ import annotations

import json
from concurrent.futures import as_completed
from dataclasses import dataclass

import numpy as np

from . import sky_families
from .intervals import GAMMA_BOUNDS
from .intervals import posterior_quantiles as _quantiles
from .joint_estimate import add_facet_posteriors, joint_fit
from .pool import process_pool, shares

__all__ = [
    "TIED_ELPD",
    "UNIDENTIFIED_SKY",
    "DEFAULT_UNIDENTIFIED_SKY",
    "StackedFits",
    "fit_stacked",
    "spread_tied_weights",
]

#: Posterior variables of the object that the stacked mixture replaces.
MIXED = ("gamma_object", "n_object", "roughness_object")
#: PSIS-LOO elpd difference from the best below which a fit predicts the
#: data as well as the best: differences under 4 are small next to the
#: estimate's own error (Sivula, Magnusson & Vehtari 2020).
TIED_ELPD = 4.0
#: How :func:`fit_stacked` weighs fits tied with the best.
TIES = ("stacking", "spread")
#: What :func:`fit_stacked` fits where the sky is not identified (module docstring).
UNIDENTIFIED_SKY = ("default-alone", "every-near-sky")
#: :func:`fit_stacked`'s ``unidentified_sky`` by default (since stop 61).
DEFAULT_UNIDENTIFIED_SKY = "every-near-sky"


def spread_tied_weights(scores: dict, tied_elpd: float = TIED_ELPD) -> dict:
    """Stacking weights with the fits tied with the best sharing their
    weight evenly.

    Parameters
    ----------
    scores : dict of str to dict
        :func:`~bayesgloss.sky_families.loo_stacking_weights`' entries
        (``weight``, ``elpd_diff`` from the best fit).
    tied_elpd : float
        A fit whose ``elpd_diff`` is below it is tied with the best.

    Returns
    -------
    dict
        ``scores`` where fewer than two fits are tied; else a copy in which
        each tied fit's ``weight`` is the tied fits' total weight over their
        number, its stacking weight kept as ``stacking_weight``, and
        ``tied`` marks the tied fits. The other fits keep their weights,
        so the weights still sum to one.
    """
    tied = [label for label, s in scores.items() if s["elpd_diff"] < tied_elpd]
    if len(tied) < 2:
        return scores
    share = sum(scores[label]["weight"] for label in tied) / len(tied)
    out = sky_families.share_weight(scores, tied, share)
    return {label: {**s, "tied": label in tied} for label, s in out.items()}


@dataclass
class StackedFits:
    """The fits of :func:`fit_stacked` and their stacking.

    Attributes
    ----------
    idata : arviz.InferenceData
        The most-weighted choice's fit (with its facets' posteriors), its
        object variables (:data:`MIXED`, where every fit has them) replaced
        by the stacked mixture's draws; the posterior's attributes
        ``<attribute>_weights`` (JSON) and ``<attribute>_most_weight``.
    samples : bayesgloss.sampling.JointSamples
        The most-weighted choice's run.
    used : ndarray of bool
        Frames used.
    fits : dict of str to tuple
        Each choice's (idata, samples, used); the most-weighted one's idata
        is ``idata``.
    own : dict of str to xarray.Dataset
        Each choice's own posterior, before the mixture.
    scores : dict of str to dict
        Each choice's :func:`~bayesgloss.sky_families.loo_stacking_weights` entry.
    best : str
        The most-weighted choice.
    sky : dict or None
        Where the sky was stacked, :func:`~bayesgloss.sky_families.fit_families`'s
        record (``families``, ``most_weight``).
    seconds : float
        Sampling time of every fit.
    beside_own : xarray.Dataset or None
        With ``sunless_spread`` on a sunless day, where the other choices
        were fitted beside the default that answers alone (``own`` and
        ``scores`` then hold all of them, the default first): the default's
        own posterior under the day's sky (:meth:`beside`); None elsewhere.
    """

    idata: object
    samples: object
    used: np.ndarray
    fits: dict
    own: dict
    scores: dict
    best: str
    sky: dict | None
    seconds: float
    beside_own: object | None = None

    def beside(self) -> dict | None:
        """Where the other choices were fitted beside the default: their
        stacking weights and own posteriors under the day's sky,
        ``{"weights", "own"}``, the default first; None elsewhere."""
        if self.beside_own is None:
            return None
        default = next(iter(self.own))
        own = {k: self.beside_own if k == default else post for k, post in self.own.items()}
        return {"weights": {k: float(self.scores[k]["weight"]) for k in own}, "own": own}

    def entries(self) -> dict:
        """Per choice, in the choices' order: its stacking scores and the
        quantiles of its own ``gamma_object``."""
        return {
            label: {
                **self.scores[label],
                "gamma": _quantiles(own["gamma_object"].values, GAMMA_BOUNDS),
            }
            for label, own in self.own.items()
        }

    def record(self, key: str, entries: dict, best_key: str, best) -> dict:
        """The wrappers' ``info``: ``entries`` under ``key``, the most-weighted
        choice under ``best_key``, ``seconds``, ``stacked`` (False where the
        default choice was fitted alone: the sky not identified, or, with
        ``sunless_default``, an overcast one), and
        ``sky_families`` where stacked."""
        info = {key: entries, best_key: best, "seconds": self.seconds}
        info["stacked"] = len(self.own) > 1 and self.beside_own is None
        if self.sky is not None:
            info["sky_families"] = self.sky
        return info


def _fit_each(args, illumination, seed, options, choices, progress, jobs):
    """joint_fit of each choice (label to options) under one sky: {label: fit}."""
    tasks = {label: (illumination, opts) for label, opts in choices.items()}
    return _fit_tasks(args, seed, tasks, progress, jobs)


def _fit_tasks(args, seed, tasks, progress, jobs):
    """joint_fit of each task (key to (sky, options)), ``jobs`` at once: {key: fit}."""
    fits = {}
    outer, inner = shares(jobs, len(tasks))
    if outer > 1:
        with process_pool(outer) as pool:
            futures = {
                pool.submit(joint_fit, *args, sky, seed, opts, facets=False, jobs=inner): key
                for key, (sky, opts) in tasks.items()
            }
            for done, future in enumerate(as_completed(futures), 1):
                fits[futures[future]] = future.result()
                if progress is not None:
                    progress(done, len(tasks))
    else:
        for key, (sky, opts) in tasks.items():
            fits[key] = joint_fit(*args, sky, seed, opts, facets=False, jobs=inner)
            if progress is not None:
                progress(len(fits), len(tasks))
    return {key: fits[key] for key in tasks}  # in the tasks' order


def fit_stacked(
    b,
    curves,
    y,
    usable,
    censored,
    keep,
    illumination,
    seed,
    options,
    *,
    option,
    choices,
    default,
    attribute,
    progress=None,
    jobs=1,
    overcast_variants=False,
    unreliable_loo="equal",
    perez_families=sky_families.DEFAULT_PEREZ_FAMILIES,
    ties="stacking",
    sunless_default=False,
    sunless_spread=False,
    unidentified_sky=DEFAULT_UNIDENTIFIED_SKY,
) -> StackedFits:
    """The joint model once per choice of one option, stacked (module docstring).

    Parameters
    ----------
    b, curves, y, usable, censored, keep
        As :func:`bayesgloss.joint_estimate.joint_fit`'s.
    illumination : str
        A sky model, ``"auto"`` or ``"families"``.
    seed : int
    options : dict
        Sampler options; ``option`` is set per fit.
    option : str or tuple of str
        The option of :func:`~bayesgloss.joint_estimate.joint_fit` that
        varies (``"lobe_family"``, ``"occluder_albedo"``), or several that
        vary together (``("lobe_family", "fresnel")``).
    choices : dict of str to object
        Label to the option's value (a tuple of values, one per option, where
        ``option`` is a tuple), in the order of the results.
    default : str
        The label fitted with the sky families where they are stacked.
    attribute : str
        Prefix of the posterior's attributes that record the weights.
    progress : callable, optional
        Called with (fits done, fits) for the fits under the chosen sky.
    jobs : int
        Fits at once in worker processes.
    overcast_variants, unreliable_loo, perez_families
        As :func:`bayesgloss.sky_families.fit_families`' (the sky's stack).
    ties : {"stacking", "spread"}
        The stacking weights as they are, or with the choices tied with the
        best sharing their weight (:func:`spread_tied_weights`).
    sunless_default : bool
        Fit the default choice alone (not stacked) where the day's sky is an
        overcast one (the most-weighted sky family, or the named sky, of
        :data:`bayesgloss.sky_families.OVERCAST_GROUP`): for the glossy
        lobe's family, which only the sun's highlight tells. On sunless days
        the lobe fits predict alike and their gloss trades off with the
        lobe's shape: the lobe stack read 0.94 [0.79, 1.00] for a true 0.10
        (Mitsuba holdout 1, ms16) and 0.054 [0, 0.15] for a true 0 where
        Phong alone read 0.012 (holdout 8, vs18; ``studies/README.md``).
    sunless_spread : bool
        Where ``sunless_default`` leaves the default alone, fit the other
        choices beside it all the same, under the day's most-weighted (or
        named) sky, and weigh them as a stack would (``ties``); the answer
        stays the default's, and :meth:`StackedFits.beside` gives the
        others for :func:`bayesgloss.model_error.choice_spread`.
    unidentified_sky : {"every-near-sky", "default-alone"}
        Where the sky families got equal weights (the sky not identified):
        every choice fitted under each sky family sharing the weight, or
        the default choice alone (module docstring).
    """
    if ties not in TIES:
        raise ValueError(f"unknown ties {ties!r}; valid: {', '.join(TIES)}")
    if unidentified_sky not in UNIDENTIFIED_SKY:
        raise ValueError(
            f"unknown unidentified_sky {unidentified_sky!r}; valid: {', '.join(UNIDENTIFIED_SKY)}"
        )
    args = (b, curves, y, usable, censored, keep)
    keys = (option,) if isinstance(option, str) else tuple(option)
    options = {k: v for k, v in options.items() if k not in keys}
    labels = list(choices)

    def opts(label):
        values = (choices[label],) if isinstance(option, str) else choices[label]
        return {**options, **dict(zip(keys, values, strict=True))}

    seconds, sky_info = 0.0, None
    if illumination == "families":
        first = sky_families.fit_families(
            *args,
            seed,
            opts(default),
            None,
            jobs,
            overcast_variants=overcast_variants,
            unreliable_loo=unreliable_loo,
            perez_families=perez_families,
            keep_fits=True,
        )
        sky_info = first[3]
        sky_fits, unmixed = sky_info.pop("fits"), sky_info.pop("posteriors")
        seconds += sky_info.pop("seconds")
        others = {label: opts(label) for label in labels if label != default}
        sunless = sunless_default and sky_info["most_weight"] in sky_families.OVERCAST_GROUP
        every = unidentified_sky == "every-near-sky" and len(labels) > 1
        if sky_info.get("equal_weights") and every and not sunless:
            return _stacked_under_near_skies(
                args, seed, first, sky_fits, unmixed, labels, default, opts, ties, attribute,
                progress, jobs, seconds,
            )  # fmt: skip
        beside = others if sunless and sunless_spread else {}
        if sky_info.get("equal_weights") or sunless:  # the default alone
            labels, others = [default], {}
        fits = {default: first[:3]}
        fits.update(_fit_each(args, sky_info["most_weight"], seed, options, others, progress, jobs))
        day_sky, default_own = sky_info["most_weight"], unmixed.get(sky_info["most_weight"])
    else:
        beside = {}
        if sunless_default and illumination in sky_families.OVERCAST_GROUP:
            if sunless_spread:
                beside = {k: opts(k) for k in labels if k != default}
            labels = [default]
        fits = _fit_each(
            args, illumination, seed, options, {k: opts(k) for k in labels}, progress, jobs
        )
        day_sky, default_own = illumination, None
    own = {label: fits[label][0].posterior.copy(deep=True) for label in labels}
    scores = _choice_weights({label: fits[label][0] for label in labels}, ties, guard=False)
    weights = np.array([scores[label]["weight"] for label in labels])
    best = labels[int(np.argmax(weights))]
    idata, samples, used = fits[best]
    if "gamma" not in idata.posterior:  # facets' own posteriors of the chosen fit only
        add_facet_posteriors(idata, samples, seed, jobs)
    for label, fit in fits.items():
        if label != default or sky_info is None:
            seconds += fit[1].seconds
    seconds += samples.facets.seconds
    mixed = [v for v in MIXED if all(v in own[k] for k in labels)]
    sky_families.mix_posteriors(
        idata, [own[k] for k in labels], mixed, weights, np.random.default_rng(seed)
    )
    if sky_info is not None and best != default:  # keep the sky's record
        for key in ("sky_family_weights", "sky_family_most_weight", "sky_family_equal_weights"):
            idata.posterior.attrs[key] = own[default].attrs[key]
    idata.posterior.attrs[f"{attribute}_weights"] = json.dumps(
        {label: float(w) for label, w in zip(labels, weights, strict=True)}
    )
    idata.posterior.attrs[f"{attribute}_most_weight"] = best
    idata.posterior.attrs[f"{attribute}_stacked"] = int(len(labels) > 1)
    beside_own = None
    if beside:  # the other choices fitted beside the default, which answers alone
        extra = _fit_each(args, day_sky, seed, options, beside, progress, jobs)
        seconds += sum(fit[1].seconds for fit in extra.values())
        pool = {default: fits[default][0], **{k: fit[0] for k, fit in extra.items()}}
        scores = _choice_weights(pool, ties, guard=False)
        beside_own = own[default] if default_own is None else default_own
        own = {default: own[default], **{k: fit[0].posterior for k, fit in extra.items()}}
    return StackedFits(idata, samples, used, fits, own, scores, best, sky_info, seconds, beside_own)


def _choice_weights(idatas: dict, ties: str, guard: bool) -> dict:
    """Stacking weights of the choices' fits under one sky, ``ties`` as in
    :func:`fit_stacked`. ``guard``: equal weights where their PSIS-LOO is
    unreliable (:func:`bayesgloss.sky_families.equal_when_unreliable`, the
    sky stack's guard; used under each near sky, not under the chosen one)."""
    scores = sky_families.loo_stacking_weights(idatas)
    if guard:
        guarded = sky_families.equal_when_unreliable(scores)
        if guarded is not scores:
            return guarded
    return spread_tied_weights(scores) if ties == "spread" else scores


def _stacked_under_near_skies(
    args, seed, first, sky_fits, unmixed, labels, default, opts, ties, attribute, progress,
    jobs, seconds,
) -> StackedFits:  # fmt: skip
    """:func:`fit_stacked` where the sky is not identified, with
    ``unidentified_sky="every-near-sky"`` (module docstring): every choice
    under each sky family that shares the weight, mixed with weight
    w_sky w_choice|sky."""
    sky_w = json.loads(first[0].posterior.attrs["sky_family_weights"])
    near = [sky for sky, w in sky_w.items() if w > 0]
    tasks = {
        (label, sky): (sky, opts(label)) for sky in near for label in labels if label != default
    }
    fitted = _fit_tasks(args, seed, tasks, progress, jobs)
    fits, post = {}, {}  # (label, sky) to the fit and to its own posterior
    for sky in near:
        fits[default, sky], post[default, sky] = sky_fits[sky], unmixed[sky]
        for label in labels:
            if label != default:
                fits[label, sky] = fitted[label, sky]
                post[label, sky] = fitted[label, sky][0].posterior
    within = {
        sky: _choice_weights({lb: fits[lb, sky][0] for lb in labels}, ties, guard=True)
        for sky in near
    }
    pairs = [(label, sky) for sky in near for label in labels]
    joint = np.array([sky_w[sky] * within[sky][label]["weight"] for label, sky in pairs])
    joint /= joint.sum()
    marginal = {
        lb: float(sum(w for (k, _), w in zip(pairs, joint, strict=True) if k == lb))
        for lb in labels
    }
    best = max(labels, key=lambda lb: marginal[lb])
    best_sky = max(near, key=lambda sky: sky_w[sky] * within[sky][best]["weight"])
    rng = np.random.default_rng(seed)
    own = {}  # each choice's own answer: its fits mixed over the near skies
    for label in labels:
        ws = np.array([sky_w[sky] * within[sky][label]["weight"] for sky in near])
        ds = post[label, near[0]].copy(deep=True)
        if ws.sum() > 0:
            mixed = [v for v in MIXED if v in ds]
            holder = _Posterior(ds)
            sky_families.mix_posteriors(
                holder, [post[label, sky] for sky in near], mixed, ws / ws.sum(), rng
            )
        own[label] = ds
    if best == default:
        idata, samples, used = first[:3]
    else:
        idata, samples, used = fits[best, best_sky]
        if "gamma" not in idata.posterior:
            add_facet_posteriors(idata, samples, seed, jobs)
        for key in ("sky_family_weights", "sky_family_most_weight", "sky_family_equal_weights"):
            idata.posterior.attrs[key] = first[0].posterior.attrs[key]
    mixed = [v for v in MIXED if all(v in post[p] for p in pairs)]
    sky_families.mix_posteriors(idata, [post[p] for p in pairs], mixed, joint, rng)
    most = max(near, key=lambda sky: sky_w[sky])  # the sky whose PSIS-LOO entries are kept
    scores = {
        label: {
            **within[most][label],
            "weight": marginal[label],
            "weight_by_sky": {
                sky: float(sky_w[sky] * within[sky][label]["weight"]) for sky in near
            },
        }
        for label in labels
    }
    idata.posterior.attrs[f"{attribute}_weights"] = json.dumps(marginal)
    idata.posterior.attrs[f"{attribute}_most_weight"] = best
    idata.posterior.attrs[f"{attribute}_stacked"] = 1
    seconds += sum(fit[1].seconds for fit in fitted.values())
    by_label = {label: fits[label, best_sky] for label in labels}
    sky_info = first[3]
    return StackedFits(idata, samples, used, by_label, own, scores, best, sky_info, seconds)


@dataclass
class _Posterior:
    """A posterior dataset where :func:`bayesgloss.sky_families.mix_posteriors`
    expects an InferenceData."""

    posterior: object
