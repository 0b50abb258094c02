"""Predictive model comparison by PSIS-LOO.

:func:`loo_compare` compares fitted models (:class:`bayesgloss.compare.ModelFit`)
through :func:`arviz.compare` (:func:`loo_table`, which takes any pointwise
log likelihoods): leave-one-frame-out per facet, and leave-one-facet-out
for the object model, with the Pareto k of every term
reported and k > 0.7 flagged, never dropped (Vehtari, Gelman & Gabry 2017;
Vehtari et al. 2024). :func:`select_parsimonious` picks the simplest model
within one standard error of the best.
"""

from __future__ import annotations

import logging
import warnings

import numpy as np

from ._thirdparty import arviz

__all__ = ["PARETO_K_MAX", "loo_compare", "loo_table", "select_parsimonious"]

log = logging.getLogger(__name__)

#: Pareto k above which a PSIS-LOO term is unreliable (Vehtari et al. 2024).
PARETO_K_MAX = 0.7


def _idata(log_lik):
    """InferenceData with one log-likelihood variable ``y`` (E, S, N)."""
    az = arviz()

    return az.from_dict(
        posterior={"draw_index": np.zeros(log_lik.shape[:2])}, log_likelihood={"y": log_lik}
    )


def loo_compare(fits: dict, *, problem: int | None = None) -> dict:
    """PSIS-LOO comparison of fitted models (:func:`arviz.compare`).

    Parameters
    ----------
    fits : dict
        ``name -> ModelFit`` on the same data and level.
    problem : int, optional
        Facet level: compare on this facet alone (leave-one-frame-out);
        ``None`` pools every facet's frames (each facet with its own
        parameters, draws of different facets paired). Object level:
        leave-one-facet-out (a facet's frames summed into one term).

    Returns
    -------
    dict
        ``table``: rows per model (rank, elpd_loo, se, p_loo, elpd_diff, dse,
        weight, max Pareto k, count of k > 0.7, warning); ``pareto_k``:
        ``name -> ndarray`` of every term's k; ``flagged``: models with any
        k > 0.7. High k is reported, never dropped.
    """
    terms = {}
    for name, fit in fits.items():
        ll = fit.log_lik
        valid = fit.valid
        if problem is not None:
            terms[name] = ll[problem][..., valid[problem]]
        elif fit.model.level == "object":
            if fit.model.n_problems > 1:
                raise ValueError("several objects: compare one at a time (problem=...)")
            terms[name] = ll[0]
        else:
            terms[name] = np.moveaxis(ll, 0, 2)[..., valid]  # (E, S, valid (facet, frame))
    return loo_table(terms)


def loo_table(terms: dict, *, method: str = "stacking", seed: int | None = None) -> dict:
    """PSIS-LOO comparison of models from their pointwise log likelihoods
    (:func:`arviz.compare`, stacking weights of Yao et al. 2018).

    Parameters
    ----------
    terms : dict
        ``name -> ndarray (E, S, N)``: each model's log likelihood of the
        same N terms at its E x S draws.
    method : {"stacking", "BB-pseudo-BMA", "pseudo-BMA"}
        How :func:`arviz.compare` weighs the models: stacking of the
        predictive distributions, or pseudo-BMA weights (proportional to
        exp(elpd_loo); "BB-" with the Bayesian bootstrap's regularisation,
        pseudo-BMA+ of Yao et al. 2018).
    seed : int, optional
        The Bayesian bootstrap's seed.

    Returns
    -------
    dict
        As :func:`loo_compare`.
    """
    az = arviz()
    idatas = {name: _idata(ll) for name, ll in terms.items()}
    ks = {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        table = az.compare(idatas, ic="loo", method=method, seed=seed)
        for name, idata in idatas.items():
            ks[name] = np.asarray(az.loo(idata, pointwise=True).pareto_k)
    for w in caught:  # surfaced in the result as flags, and logged
        log.info("arviz: %s", w.message)
    rows = []
    for name in table.index:
        k = ks[name]
        n_high = int(np.sum(k > PARETO_K_MAX))
        r = table.loc[name]
        rows.append(
            {
                "model": name,
                "rank": int(r["rank"]),
                "elpd_loo": float(r["elpd_loo"]),
                "se": float(r["se"]),
                "p_loo": float(r["p_loo"]),
                "elpd_diff": float(r["elpd_diff"]),
                "dse": float(r["dse"]),
                "weight": float(r["weight"]),
                "pareto_k_max": float(np.max(k)),
                "pareto_k_high": n_high,
                "n_terms": int(k.size),
                "warning": bool(n_high > 0),
            }
        )
    return {
        "table": rows,
        "pareto_k": ks,
        "flagged": [r["model"] for r in rows if r["warning"]],
    }


def select_parsimonious(rows: list[dict], n_params: dict) -> str:
    """The simplest model whose elpd lies within one dse of the best.

    Nested models tie in elpd when the simpler one is true; this rule (the
    "one standard error" choice) then picks the simpler.
    """
    best = min(rows, key=lambda r: r["rank"])
    close = [r for r in rows if r["elpd_diff"] <= max(r["dse"], 1e-9) or r is best]
    return min(close, key=lambda r: (n_params[r["model"]], r["rank"]))["model"]
