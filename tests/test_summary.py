"""The summary of an estimate (bayesgloss.summary): each facet's and the
object's reported interval, the model's error on it, and the flags."""

import arviz as az
import numpy as np
import pytest

from bayesgloss import bundle, estimate, summary


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A synthetic bundle's curves and a made-up posterior of its first three
    facets: two narrow near 0.3, one spread over the prior."""
    from conftest import make_synthetic_bundle

    b = bundle.read_bundle(make_synthetic_bundle(tmp_path_factory.mktemp("s") / "b"))
    curves = bundle.facet_curves(b)
    _, usable, censored = estimate.observations(curves)
    f = len(curves.ids)
    assert f >= 6
    keep = np.zeros(f, dtype=bool)
    keep[:3] = True
    usable = usable.copy()
    usable[3] = False
    usable[3, : estimate.MIN_FRAMES - 1] = True  # too few frames
    facing = np.zeros(f, dtype=bool)
    facing[5] = True  # left out as facing the ground; facet 4 as saturated
    rng = np.random.default_rng(3)
    gamma = np.stack(
        [
            np.clip(0.30 + 0.02 * rng.standard_normal((4, 500)), 0, 1),
            rng.uniform(0.05, 0.95, (4, 500)),
            np.clip(0.32 + 0.02 * rng.standard_normal((4, 500)), 0, 1),
        ],
        axis=-1,
    )
    n = np.exp(3 + 0.1 * rng.standard_normal((4, 500, 3)))
    idata = az.from_dict(posterior={"gamma": gamma, "n": n})
    return b, curves, keep, idata, usable, censored, facing, gamma


def _summarise(fitted, seed=0):
    b, curves, keep, idata, usable, censored, facing, _ = fitted
    samples = type("Run", (), {"facets": None, "converged": True})()
    return summary.summarise_estimate(
        *(b, curves, keep, idata.copy(), samples, "gensky-clear", "relative", "linear", seed),
        None,
        {"seconds": 0.0},
        facing,
        usable=usable,
        censored=censored,
        min_frames=estimate.MIN_FRAMES,
    )


def test_flags_and_reasons_of_each_facet(fitted):
    s = _summarise(fitted).summary
    by_id = {f["id"]: f for f in s["facets"]}
    ids = fitted[1].ids
    # only the facet whose own 90 % interval is wider than 0.6 (0.81 here)
    wide = ["gloss-not-identifiable" in by_id[ids[k]]["flags"] for k in range(3)]
    assert wide == [False, True, False]
    assert by_id[ids[3]]["flags"] == ["too-few-frames"]
    assert by_id[ids[4]]["flags"] == ["saturated"]
    assert by_id[ids[5]]["flags"] == ["faces-ground"]
    assert by_id[ids[3]]["gamma"] is None
    assert s["object"]["facets"] == 3 and s["per_frame_illumination"] is False


def test_reported_interval_carries_the_model_error(fitted):
    s = _summarise(fitted).summary
    gamma = fitted[-1]
    facet = s["facets"][0]
    # the model's own interval is the draws' own quantiles ...
    own = facet["gamma_within_model"]
    assert own["q05"] == pytest.approx(np.quantile(gamma[..., 0], 0.05), abs=1e-12)
    assert own["q95"] == pytest.approx(np.quantile(gamma[..., 0], 0.95), abs=1e-12)
    # ... and the reported one adds N(0, sd^2) of the model error (the facets'
    # disagreement, at least the few-facet floor) to each draw: a normal of sd
    # sqrt(0.02^2 + sd^2), whose 5-95 % width is 3.29 of it; 2000 draws pin
    # that width to about 3 %, so 8 % tells the error added from one left out
    err = s["object"]["model_error"]["sd"]
    assert err >= 0.13
    width = facet["gamma"]["q95"] - facet["gamma"]["q05"]
    assert width == pytest.approx(3.29 * np.hypot(0.02, err), rel=0.08)
    # the object is the facets' population (no one-material model here), near 0.3-0.5
    assert s["object"]["model"].startswith("population")
    assert 0.2 < s["object"]["gamma_within_model"]["median"] < 0.6


def test_model_error_draws_follow_the_seed(fitted):
    a, b = (_summarise(fitted, seed=s).summary["facets"][0]["gamma"] for s in (1, 1))
    c = _summarise(fitted, seed=2).summary["facets"][0]["gamma"]
    assert a == b and a != c
