"""The batched ensemble sampler: against emcee, closed forms and itself."""

import emcee
import numpy as np
import pytest
from scipy import stats

from bayesgloss import diagnostics, sampling
from bayesgloss import likelihood as lk
from bayesgloss.pool import process_pool
from bayesgloss.render import FacetBases


def test_integrated_time_of_ar1_processes():
    # AR(1) x_t = phi x_{t-1} + e_t has tau = (1 + phi) / (1 - phi)
    rng = np.random.default_rng(0)
    n, w = 20000, 8
    phis = np.array([0.5, 0.8, 0.9])
    x = np.zeros((n, len(phis), w, 1))
    e = rng.standard_normal(x.shape)
    for t in range(1, n):
        x[t] = phis[:, None, None] * x[t - 1] + e[t]
    tau = diagnostics.integrated_time(x)[:, 0]
    # 8 walkers x 20000 steps: the estimator's error is a few percent
    np.testing.assert_allclose(tau, (1 + phis) / (1 - phis), rtol=0.08)
    # and it agrees with emcee's own estimator on the walker-averaged ACF
    ref = [emcee.autocorr.integrated_time(x[:, i, :, 0], quiet=True)[0] for i in range(3)]
    np.testing.assert_allclose(tau, ref, rtol=0.05)


def test_integrated_time_of_a_narrow_float32_chain():
    # a posterior far narrower than its value (log s = 11.7, sd 4e-5, as for a
    # facet with 0.01 % noise) stored in float32: the estimate must equal the
    # float64 one (a float32 mean errs by more than the spread and gave tau ~ 2000
    # for this chain of tau 14); float32 rounding (ulp 1e-6 = sd / 40) adds a
    # little white noise, well under 1 %
    rng = np.random.default_rng(1)
    n, w, phi = 2000, 24, 0.88
    x = np.zeros((n, 1, w, 1))
    e = rng.standard_normal(x.shape)
    for t in range(1, n):
        x[t] = phi * x[t - 1] + np.sqrt(1 - phi**2) * e[t]
    chain = 11.727 + 4e-5 * x
    want = diagnostics.integrated_time(chain)
    np.testing.assert_allclose(
        diagnostics.integrated_time(chain.astype(np.float32)), want, rtol=0.01
    )
    assert 8 < want[0, 0] < 25  # (1 + phi) / (1 - phi) = 15.7


@pytest.mark.parametrize("moves", [(("stretch", 1.0),), sampling.DEFAULT_MOVES])
def test_batched_sampler_recovers_correlated_gaussians(moves):
    # 50 independent problems, each a 3-d Gaussian with its own mean and covariance
    rng = np.random.default_rng(1)
    b, p = 50, 3
    a = rng.normal(size=(b, p, p))
    cov = a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(p)
    prec = np.linalg.inv(cov)
    mean = rng.normal(size=(b, p)) * 3

    def logp(th):
        d = th - mean[:, None, :]
        return -0.5 * np.einsum("bki,bij,bkj->bk", d, prec, d)

    s = sampling.BatchedEnsemble(logp, moves, np.random.default_rng(2))
    start = mean[:, None, :] + rng.normal(size=(b, 16, p)) * 0.1
    chain, _, acc = s.run(start, 6000)
    x = chain[1000::5].transpose(0, 2, 1, 3).reshape(-1, b, p)
    # 16 walkers x 1000 thinned steps, tau < 30: ~1000 effective draws; mean error
    # ~ sd / 30, covariance within 15 %
    sd = np.sqrt(np.einsum("bii->bi", cov))
    assert np.all(np.abs(x.mean(0) - mean) < 0.15 * sd)
    emp = np.einsum("nbi,nbj->bij", x - x.mean(0), x - x.mean(0)) / len(x)
    np.testing.assert_allclose(np.einsum("bii->bi", emp), np.einsum("bii->bi", cov), rtol=0.15)
    assert np.all((acc > 0.1) & (acc < 0.9))


def _one_facet_problem(sigma=0.05, seed=3):
    rng = np.random.default_rng(seed)
    t = 15
    hours = np.linspace(-1.2, 1.2, t)
    d = np.cos(hours) + 0.2
    exps = np.logspace(0, 4, 25)
    g = (
        np.exp(-((hours[None, :] - 0.5) ** 2) * np.sqrt(exps)[:, None] / 2)
        * np.sqrt(exps)[:, None] ** 0.5
        * 0.5
        + 0.1
    )
    bases = FacetBases(d[None], g[None], exps)
    data = lk.curve_data(
        np.ones((1, t)), np.ones((1, t), bool), bases, priors=lk.Priors(log_s_center=0.0)
    )
    truth = np.array([[[0.4, np.log(30.0), 0.0, np.log(sigma)]]])
    y = lk.simulate(truth, data, rng)[:, 0]
    return lk.curve_data(y, np.ones((1, t), bool), bases, priors=lk.Priors(log_s_center=0.0))


def test_stretch_move_matches_emcee_on_a_facet_posterior():
    # the same posterior sampled by stock emcee (StretchMove) and by the batched
    # sampler with the stretch move only: the marginal of gamma and log n agree
    # (two-sample KS on thinned, nearly independent draws, at the 1 % level;
    # thinned by about twice emcee's integrated autocorrelation time, 45-59
    # steps in every coordinate here: at 40, less than one, consecutive draws
    # were correlated and the KS p-value too small, 0.003 for log n under
    # another prior at stop 44)
    data = _one_facet_problem()
    p, w, n, burn, thin = 4, 16, 12000, 2000, 100
    start = sampling.initial_ensemble(data, w, np.random.default_rng(4))[0]

    def logp(th):
        return lk.log_probability(th[None], data)[0]

    es = emcee.EnsembleSampler(w, p, logp, vectorize=True, moves=emcee.moves.StretchMove())
    es.random_state = np.random.RandomState(5).get_state()
    es.run_mcmc(start, n)
    ref = es.get_chain(discard=burn, thin=thin, flat=True)
    ours = sampling.BatchedEnsemble(
        lambda th: lk.log_probability(th, data), (("stretch", 1.0),), np.random.default_rng(6)
    )
    chain, _, _ = ours.run(start[None], n)
    got = chain[burn::thin, 0].reshape(-1, p)
    for k in (0, 1):
        assert stats.ks_2samp(ref[:, k], got[:, k]).pvalue > 0.01
    # acceptance fractions of the same move on the same target agree closely
    assert abs(np.mean(es.acceptance_fraction) - ours_acceptance(ours, start, data)) < 0.05


def ours_acceptance(sampler, start, data):
    _, _, acc = sampler.run(start[None], 2000)
    return float(acc.mean())


def test_results_do_not_depend_on_the_number_of_jobs():
    data = _one_facet_problem().take(np.zeros(6, dtype=int))
    kw = dict(
        seed=7,
        stream_size=3,
        slots=3,
        n_ensembles=2,
        burn=100,
        chunk=100,
        min_tau_multiple=5,
        draws_per_ensemble=40,
        max_steps=400,
    )
    one = sampling.sample_posterior(data, **kw)
    with process_pool(2) as pool:  # the streams spread over two processes
        two = sampling.sample_posterior(data, pool=pool, **kw)
    np.testing.assert_array_equal(one.draws, two.draws)
    again = sampling.sample_posterior(data, **kw)
    np.testing.assert_array_equal(one.draws, again.draws)
    other = sampling.sample_posterior(data, **{**kw, "seed": 8})
    assert not np.array_equal(one.draws, other.draws)


def test_ridge_coordinates_invert_and_carry_their_jacobian():
    # from_theta inverts to_theta, and the log Jacobian equals log |det| of the
    # finite-difference Jacobian d theta / d x, for active (low-noise) facets
    data = _one_facet_problem(sigma=0.002).take([0, 0])
    rc = sampling.RidgeCoordinates.of(data)
    assert rc.active.all()
    rng = np.random.default_rng(21)
    th = np.stack(
        [rng.uniform(0.2, 0.6, (2, 5)), rng.uniform(1, 8, (2, 5)), rng.normal(0, 0.05, (2, 5))],
        axis=-1,
    )
    x = rc.from_theta(th)
    back, log_jac = rc.to_theta(x)
    np.testing.assert_allclose(back, th, rtol=1e-10, atol=1e-12)
    h = 1e-6
    jac = np.empty((2, 5, 3, 3))
    for i in range(3):
        dx = np.zeros(3)
        dx[i] = h
        jac[..., :, i] = (rc.to_theta(x + dx)[0] - rc.to_theta(x - dx)[0]) / (2 * h)
    np.testing.assert_allclose(log_jac, np.log(np.abs(np.linalg.det(jac))), atol=1e-5)
    # inactive facets: the identity
    plain = sampling.RidgeCoordinates.of(data, max_rms=-1.0)
    assert not plain.active.any()
    np.testing.assert_array_equal(plain.from_theta(th), th)
    np.testing.assert_array_equal(plain.to_theta(th)[1], 0.0)


def test_default_sampler_matches_stock_emcee_in_plain_coordinates():
    # a low-noise facet (sigma 0.3 %: a thin curved ridge along log n), sampled
    # the default way (sigma integrated out, ridge coordinates, sigma drawn
    # afterwards) and by stock emcee on the plain 4-parameter posterior run long
    # enough to mix (tau ~ 50 steps there, 40000 steps); both marginals of all
    # four parameters agree (two-sample KS at 1 % on nearly independent draws:
    # ours every 8th draw of each walker, >= 2 tau apart; emcee's thinned by tau
    # after 10 tau of burn-in)
    data = _one_facet_problem(sigma=0.003, seed=5)
    assert sampling.RidgeCoordinates.of(data).active.all()
    post = sampling.sample_posterior(data, seed=9)
    ours = post.draws[0][:, ::8].reshape(-1, 4)
    assert len(ours) >= 400
    w = 32
    start = sampling.initial_ensemble(data, w, np.random.default_rng(11))[0]
    es = emcee.EnsembleSampler(
        w, 4, lambda th: lk.log_probability(th[None], data)[0], vectorize=True
    )
    es.random_state = np.random.RandomState(12).get_state()
    es.run_mcmc(start, 40000)
    tau = int(np.ceil(np.max(emcee.autocorr.integrated_time(es.get_chain(), quiet=True))))
    ref = es.get_chain(discard=10 * tau, thin=tau, flat=True)
    for k in range(4):
        assert stats.ks_2samp(ref[:, k], ours[:, k]).pvalue > 0.01, k


def _ar1(phi, shape, rng):
    """AR(1) series along the last axis, unit innovations."""
    e = rng.standard_normal(shape)
    x = np.zeros(shape)
    for t in range(shape[-1]):
        x[..., t] = (phi * x[..., t - 1] if t else 0.0) + e[..., t]
    return x


def test_rank_diagnostics_equal_arviz():
    """The vectorised R-hat and ESS the stopping rule uses are ArviZ's own:
    equal to 1e-9 relative (float rounding only) on mixing, sticky,
    anti-correlated, unmixed, tied and binary chains of odd and even lengths."""
    import arviz as az

    rng = np.random.default_rng(11)
    for n_draws in (5, 10, 11, 101, 996):
        for phi in (0.0, 0.5, 0.99, -0.6):
            x = _ar1(phi, (5, 4, n_draws), rng)
            x[1] = np.round(x[1])  # ties
            x[2] += 3.0 * np.arange(4)[:, None]  # chains that never met
            x[3] = (x[3] > 0.5).astype(float)  # binary
            rhat, ess_bulk, ess_tail = diagnostics.rank_diagnostics(x)
            for i in range(len(x)):
                with np.errstate(divide="ignore", invalid="ignore"):
                    ref = (
                        az.rhat(x[i]),
                        az.ess(x[i], method="bulk"),
                        az.ess(x[i], method="tail"),
                    )
                ours = (rhat[i], ess_bulk[i], ess_tail[i])
                np.testing.assert_allclose(ours, ref, rtol=1e-9, equal_nan=True)
    assert diagnostics.converged(_ar1(0.5, (3, 4, 996), rng)).all()
    stuck = _ar1(0.5, (1, 4, 996), rng) + 2.0 * np.arange(4)[None, :, None]
    assert not diagnostics.converged(stuck)[0]


def test_exponent_jump_gets_mode_weights_of_a_bimodal_target():
    """Two narrow modes in coordinate 0 (weights 0.3 and 0.7, 120 sd apart):
    stretch and DE moves started in one mode stay there; the n-jump move,
    with a deliberately wrong proposal (0.8 and 0.2 on the modes), still
    finds 0.3, which it does only with its independence factor (without it
    the chain would settle at 0.3 x 0.8 / (0.3 x 0.8 + 0.7 x 0.2) = 0.63).
    Tolerance 0.03: ~5 standard errors of the pooled fraction over 8
    problems x 6 walkers x 2500 kept steps (jumps are accepted often, so
    draws a few steps apart are nearly independent)."""
    sd, w_left = 0.05, 0.3

    def log_prob(x):
        x0 = x[..., 0]
        left = np.log(w_left) - 0.5 * ((x0 + 3) / sd) ** 2
        right = np.log(1 - w_left) - 0.5 * ((x0 - 3) / sd) ** 2
        return np.logaddexp(left, right) - 0.5 * np.sum(x[..., 1:] ** 2, axis=-1)

    b, w, p, cells = 8, 6, 3, 400
    lo, width = -6.0, 12.0 / cells
    centres = lo + width * (np.arange(cells) + 0.5)
    q = np.where(centres < 0, 0.8, 0.2) * np.exp(-0.5 * ((np.abs(centres) - 3) / (2 * sd)) ** 2)
    q = q / q.sum() + 1e-4
    q /= q.sum()
    cdf = np.cumsum(q)
    cdf /= cdf[-1]
    log_q, fit = np.tile(np.log(q / width), (b, 1)), np.zeros((b, cells, p))
    jump = sampling.ExponentJump(
        (lo, -lo),
        0.0,
        np.full(b, lo),
        np.full(b, width),
        log_q,
        np.tile(cdf, (b, 1)),
        fit,
        np.zeros(b, int),
    )
    rng = np.random.default_rng(5)
    start = rng.normal(0, 0.01, (b, w, p)) + [3.0, 0.0, 0.0]
    fractions = {}
    for moves in (sampling.DEFAULT_MOVES, sampling.FACET_MOVES):
        sampler = sampling.BatchedEnsemble(log_prob, moves, np.random.default_rng(6), jump=jump)
        chain, _, _ = sampler.run(start, 3000)
        fractions[moves] = np.mean(chain[500:, ..., 0] < 0)
    assert fractions[sampling.DEFAULT_MOVES] < 0.01
    assert abs(fractions[sampling.FACET_MOVES] - w_left) < 0.03


def test_ridge_jump_is_exact_with_an_offset_and_narrow_proposal():
    """The ridge-jump alone (an independence sampler of the whole point: log n
    from cells, the offsets from a bivariate t about a fit that moves with
    log n, scaled by ``spread``) on a Gaussian target whose offsets are centred
    elsewhere (0.3 + 0.5 log n, -0.2) and wider (sd 0.6) than the proposal's
    scale 0.5: means and sds recovered. Tolerance: 8 problems x 6 walkers x
    4000 kept steps of a sampler with acceptance ~0.5 give standard errors
    ~0.01 sd; 0.05 is 5 of them, while a factor without the t densities or
    without the fit's offset moves the offsets' sd or mean by > 0.1."""
    b, w, cells = 8, 6, 200
    lo, hi = 0.0, 4.0
    width = (hi - lo) / cells
    centres = lo + width * (np.arange(cells) + 0.5)
    n_mean, n_sd, u_sd = 2.0, 0.3, 0.6

    def log_prob(x):
        u1 = x[..., 1] - (0.3 + 0.5 * x[..., 0])
        u2 = x[..., 2] + 0.2
        inside = (x[..., 0] >= lo) & (x[..., 0] <= hi)
        lp = -0.5 * ((x[..., 0] - n_mean) / n_sd) ** 2 - 0.5 * (u1**2 + u2**2) / u_sd**2
        return np.where(inside, lp, -np.inf)

    q = np.exp(-0.5 * ((centres - 2.1) / 0.4) ** 2)  # a proposal off the target
    q /= q.sum()
    cdf = np.cumsum(q)
    cdf /= cdf[-1]
    fit = np.zeros((b, cells, 3))
    fit[..., 1] = 0.3 + 0.5 * centres  # the offsets' centre at each cell's exponent
    fit[..., 2] = -0.2
    jump = sampling.ExponentJump(
        (lo, hi),
        0.1,
        np.full(b, lo),
        np.full(b, width),
        np.tile(np.log(0.9 * q / width), (b, 1)),
        np.tile(cdf, (b, 1)),
        fit,
        np.zeros(b, int),
        None,
        np.full(b, 0.5),
    )
    rng = np.random.default_rng(8)
    start = np.stack(
        [rng.normal(2, 0.1, (b, w)), rng.normal(1.3, 0.1, (b, w)), rng.normal(-0.2, 0.1, (b, w))],
        axis=-1,
    )
    sampler = sampling.BatchedEnsemble(log_prob, [("ridge-jump", 1.0)], rng, jump=jump)
    chain, _, acc = sampler.run(start, 4500)
    x = chain[500:].reshape(-1, 3)
    u1 = x[:, 1] - (0.3 + 0.5 * x[:, 0])
    np.testing.assert_allclose([x[:, 0].mean(), x[:, 0].std()], [n_mean, n_sd], atol=0.05 * n_sd)
    np.testing.assert_allclose([u1.mean(), u1.std()], [0.0, u_sd], atol=0.05 * u_sd)
    np.testing.assert_allclose([x[:, 2].mean(), x[:, 2].std()], [-0.2, u_sd], atol=0.05 * u_sd)
    assert 0.2 < acc.mean() < 0.9


def test_proposal_square_root_of_a_matrix_rounding_made_indefinite():
    # the frame move's proposal covariance (info + diag(prior))^-1: its
    # Cholesky factor where it exists, and a square root from the floored
    # eigendecomposition where rounding (a 1e12 precision of a fixed latent
    # beside data of order 1e-4) or a non-finite entry made it fail; a
    # holdout run stopped on such a matrix (stop 28)
    from bayesgloss.sampling.moves import proposal_square_root

    prior = np.array([1e12, 1 / 1.5**2, 1 / 0.7**2, 1e12])
    g = np.array([[1.0, 2.0, 3.0, 0.0], [0.5, 0.1, 2.0, 0.0], [2.0, 1.0, 0.2, 0.0]])
    good = g.T @ g
    m = proposal_square_root(good, prior)
    exact = np.linalg.inv(good + np.diag(prior))
    assert np.allclose(m @ m.T, exact, rtol=1e-9, atol=1e-15)
    assert np.allclose(m, np.tril(m))  # the Cholesky factor where it exists
    bad = good.copy()
    bad[1, 2] = bad[2, 1] = 1e9  # indefinite: a 2x2 minor of determinant < 0
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(np.linalg.inv(bad + np.diag(prior)))
    m = proposal_square_root(bad, prior)
    cov = m @ m.T
    assert np.all(np.isfinite(m))
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert np.linalg.eigvalsh(cov).max() <= 1 / prior.min() * (1 + 1e-12)
    nan = good.copy()
    nan[0, 1] = nan[1, 0] = np.inf
    m = proposal_square_root(np.stack([good, nan]), prior)  # batched, one bad matrix
    assert np.all(np.isfinite(m))
    assert np.allclose(m[0] @ m[0].T, exact, rtol=1e-9, atol=1e-15)
