"""The day-level exposure's moves (bayesgloss.sampling.exposure_moves) and
the direction they share (JointData.exposure_direction)."""

import numpy as np
import pytest

from bayesgloss import illumination as il
from bayesgloss.sampling import exposure_moves, sample_material


def _small_data(paper_three_skies, facets=3, **kwargs):
    full, up = paper_three_skies
    bases = full.take(slice(0, facets), up)
    f, t = bases.diffuse.shape[1:]
    y = np.random.default_rng(0).uniform(0.5, 1.5, (f, t))
    return il.joint_data(y, np.ones((f, t), bool), bases, **kwargs)


def test_exposure_direction_leaves_every_curve_unchanged(paper_three_skies):
    # The moves shift a frame's latents along (1, -1, -1, 0...): log exposure
    # up, log sun and log sky down. The curves depend on e a and e b only, so
    # every predicted value must stay the same to rounding; the same shift
    # with the sky left out (1, -1, 0, ...) must change them (by up to a
    # factor e^c on the sky's part), which shows the check can fail.
    data = _small_data(paper_three_skies)
    rng = np.random.default_rng(1)
    f, t, n_l = data.shape[0], data.shape[1], data.n_latents
    th = np.zeros((1, f, 2, 4))
    th[..., 0], th[..., 1], th[..., 2] = 0.4, np.log(80.0), rng.normal(0, 0.3, (1, f, 2))
    lam = rng.normal(0.0, 0.5, (1, 2, t, n_l))
    c = rng.normal(0.0, 1.0, (1, 2, t, 1))
    before = il.predict(th, lam, data)
    after = il.predict(th, lam + c * data.exposure_direction, data)
    np.testing.assert_allclose(after, before, rtol=1e-12)
    wrong = data.exposure_direction.copy()
    wrong[2] = 0.0
    assert np.max(np.abs(il.predict(th, lam + c * wrong, data) / before - 1)) > 0.05


def test_mean_shift_and_its_prior():
    # mean_shifted moves mu_e (column 4 of the hyper) only, broadcast over
    # the shifts; il.log_prior_exposure_mean is N(0, exposure_sd^2)'s log
    # density up to a constant: at mu_e = 2 sd it is -2.
    hyper = np.arange(12.0).reshape(2, 6)
    c = np.array([[0.5, -1.0], [2.0, 0.0]])  # (K, E)
    out = exposure_moves.mean_shifted(hyper, c)
    assert out.shape == (2, 2, 6)
    np.testing.assert_array_equal(out[..., 4], hyper[:, 4] + c)
    np.testing.assert_array_equal(
        np.delete(out, 4, -1), np.broadcast_to(np.delete(hyper, 4, -1), (2, 2, 5))
    )

    class Data:
        frame_priors = il.IlluminationPriors()

    h = np.zeros(6)
    h[4] = 2.0 * Data.frame_priors.exposure_sd
    assert il.log_prior_exposure_mean(h, Data) == pytest.approx(-2.0)


def test_a_known_exposure_leaves_the_day_level_exposure_out(paper_three_skies):
    # Where the bundle gives each frame's exposure there is nothing to tie:
    # the one-material model keeps its 4 day-level coordinates, and its
    # draws with IlluminationPriors.day_exposure on are the draws with it
    # off, bit for bit (same seed). Where the exposure is unknown the two
    # differ (6 coordinates, other draws).
    runs, n_t = {}, int(np.sum(paper_three_skies[1]))
    for known in (True, False):
        for day in (True, False):
            priors = il.IlluminationPriors(day_exposure=day)
            exposure = np.ones(n_t) if known else None
            data = _small_data(paper_three_skies, exposure=exposure, frame_priors=priors)
            assert il.hyper_size(data) == (6 if day and not known else 4)
            s = sample_material(
                data, seed=3, min_sweeps=150, max_sweeps=150, draws_per_ensemble=100
            )
            runs[known, day] = s.draws
    np.testing.assert_array_equal(runs[True, True], runs[True, False])
    assert not np.array_equal(runs[False, True], runs[False, False])
