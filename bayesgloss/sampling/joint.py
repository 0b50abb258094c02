"""The joint sampler: facets and per-frame illumination together (Metropolis within Gibbs).

The model of :mod:`bayesgloss.illumination` couples the facets only through
each frame's latents (log e_t, log a_t, log b_t). :func:`sample_joint`
runs E independent ensembles of W walkers; every walker is a whole state
(every facet's gamma, log n, log s and every frame's latents), and a sweep
updates one block at a time, each move leaving the joint posterior
invariant:

1. **facets given the frames**: one step of the affine-invariant ensemble
   moves (:class:`bayesgloss.sampling.ensemble.BatchedEnsemble`, stretch
   and differential evolution) on each facet's (gamma, log n, log s), sigma
   integrated out, every walker's density conditioned on its own frames
   (the moves stay valid, as the other walkers are held fixed while one
   half moves); the ensembles move log s plus the walker's brightness level
   (a translation per walker), so that their spread is the facets' own;
2. **sigma given the rest**: each facet's log sigma drawn exactly from its
   conditional (:func:`bayesgloss.likelihood.draw_log_sigma`), so that,
   given sigma, frames are independent (a partially collapsed Gibbs step,
   van Dyk & Park 2008: sigma is drawn after, and discarded before, the
   facet step that integrates it out);
3. **each frame's latents given the facets and sigma**: a Gaussian random
   walk, half the walkers at a time, whose covariance is the inverse of the
   frame's Fisher information (plus the priors' precisions) at the mean
   latents of the other half, so that it is symmetric and fits a
   conditional that is sharp where many facets see the frame and broad
   where none tells (a hidden sun);
4. **the exposure ridge**: where the exposure is unknown, log e_t + c with
   log a_t and log b_t - c (the likelihood is unchanged: accepted by the
   prior ratio);
5. **the scale ridge**: every facet's log s - c with every frame's
   brightness + c leaves the likelihood unchanged; accepted by the prior
   ratio (without it the sampler would cross this direction, which only the
   priors bound, in steps of the data's precision).
6. **the collective move**: one random-walk Metropolis step of the whole
   state in the span of the few directions in which the blocks above are
   slowest (adapted during burn-in, :meth:`_JointChain.adapt`).

The run stops when, over its second half, gamma of every facet and the sun
and sky latents of every frame have converged across the ensembles by the
rule of :mod:`bayesgloss.diagnostics` (R-hat < 1.01, bulk and tail ESS >=
400), or at ``max_sweeps`` (flagged): :func:`bayesgloss.sampling.schedule.run_chain`.
"""

from __future__ import annotations

import numpy as np

from .. import illumination as il
from .. import likelihood as lk
from .coordinates import node_fits
from .ensemble import BatchedEnsemble
from .moves import DEFAULT_MOVES, proposal_square_root
from .schedule import JointSamples, run_chain
from .starts import initial_ensemble

__all__ = ["JointSamples", "sample_joint"]

#: Directions in whose span the collective move steps (adapted during burn-in).
COLLECTIVE = 4


class _JointChain:
    """The state of E ensembles of W walkers and one sweep of the moves."""

    def __init__(self, data: il.JointData, n_ensembles, n_walkers, rng):
        if data.censored is not None:
            raise ValueError(
                "the per-facet joint sampler has no likelihood for clipped (censored) entries: "
                "leave them out of its data, or use the one-material sampler (sample_material)"
            )
        self._setup(data, n_ensembles, n_walkers, rng)
        lam0 = starting_frames(data)  # (T, L)
        start = initial_ensemble(
            _curve_data_at(data, lam0).take(np.tile(np.arange(self.f), self.e)), n_walkers, rng
        )
        self.th = np.ascontiguousarray(start[..., :3]).reshape(self.e, self.f, self.w, 3)
        self.lam = lam0 + 0.05 * rng.standard_normal((self.e, self.w, *lam0.shape)) * self.free
        self.ensemble = BatchedEnsemble(self._log_prob, DEFAULT_MOVES, rng, pass_walkers=True)
        self.log_p = self._log_prob(self._coords(), np.arange(self.w))
        q = data.priors.log_s_sd
        fp = data.frame_priors
        if data.exposure_known:
            precision = self.f / q**2 + self.t * (1 / fp.sun_clear_sd**2 + 1 / fp.sky_sd**2)
        else:
            precision = self.f / q**2 + self.t / fp.exposure_sd**2
        self.scale_step = 1.0 / np.sqrt(precision)
        self.accepted = {"facets": 0.0, "frames": 0.0, "scale": 0.0, "collective": 0.0}

    def _setup(self, data: il.JointData, n_ensembles, n_walkers, rng) -> None:
        """What every chain of this scheme holds besides its state."""
        self.data, self.rng = data, rng
        self.e, self.w = n_ensembles, n_walkers
        self.f, self.t = data.shape
        self.cd = data.curve_data()
        self.tables = data.tables
        self.free = data.free
        self.level = np.zeros((self.e, self.w))
        self.directions = None
        self._density = None  # the whole state's log density, where known
        self.sweeps = 0

    def _level(self) -> np.ndarray:
        """Each walker's brightness level, (E, W): the mean over frames of
        log e + (log a + log b) / 2, which the scale ridge shifts by c."""
        lam = self.lam
        log_e = lam[..., 0] if self.data.log_exposure is None else self.data.log_exposure
        return np.mean(log_e + 0.5 * (lam[..., 1] + lam[..., 2]), axis=-1)

    def _coords(self) -> np.ndarray:
        """The ensemble's coordinates of the facets, (E F, W, 3): gamma, log n
        and log s plus the walker's level (a translation per walker, fixed
        while the facets move, so that the ensemble's spread in the scale is
        the facets' own and not the scale ridge's)."""
        c = self.th.copy()
        c[..., 2] += self.level[:, None, :]
        return c.reshape(self.e * self.f, self.w, 3)

    def _log_prob(self, q, walkers):
        th = q.reshape(self.e, self.f, len(walkers), 3).copy()
        th[..., 2] -= self.level[:, None, walkers]
        lp = il.log_prior_facets(th, self.data)
        ok = np.isfinite(lp)
        ll = il.log_likelihood_sigma_marginal(th, self.lam[:, walkers], self.data)
        return np.where(ok, lp + ll, -np.inf).reshape(self.e * self.f, len(walkers))

    def sweep(self) -> None:
        data = self.data
        self.level = self._level()
        coords = self._coords()
        acc = self.ensemble.step(coords, self.log_p)
        self.accepted["facets"] += acc.mean()
        th = coords.reshape(self.e, self.f, self.w, 3)
        th[..., 2] -= self.level[:, None, :]
        self.th = th
        parts = il.unit_parts(th, data, self.tables)
        _, q = il.log_likelihood_sigma_marginal(th, self.lam, data, parts, with_q=True)
        log_sigma = self._draw_log_sigma(q)
        self._frame_moves(th, parts, log_sigma)
        if not data.exposure_known:
            self._exposure_ridge()
        self._scale_ridge()
        self.collective_moves()
        self.level = self._level()
        self.log_p = self._log_prob(self._coords(), np.arange(self.w))
        self.sweeps += 1

    def _draw_log_sigma(self, q, data=None):
        cd = self.cd if data is None or data is self.data else data.curve_data()
        return _log_sigma_draws(q, cd, self.rng)

    def _frame_prior(self, lam, walkers=slice(None)):
        """Each frame's log prior, (E, H, T), for the walkers' lam (E, H, T, L)."""
        return il.log_prior_frames(lam, self.data)

    def _frame_density(self, th, lam, parts, log_sigma, walkers=slice(None)):
        frame_ll = il.frame_log_likelihood(th, lam, log_sigma, self.data, parts)
        return frame_ll + self._frame_prior(lam, walkers)

    def _frame_moves(self, th, parts, log_sigma) -> None:
        """Random-walk Metropolis on each frame's latents, half the walkers at a
        time, with the proposal covariance (2.38^2 / d) H^-1 of the frame's
        conditional Fisher information H at the mean latents of the other
        half (fixed while this half moves, so the proposal is symmetric)."""
        rng, w = self.rng, self.w
        d = int(self.free.sum())
        cur = self._frame_density(th, self.lam, parts, log_sigma)  # (E, W, T)
        order = rng.permutation(w)
        halves = (order[: w // 2], order[w // 2 :])
        for k in (0, 1):
            idx, cidx = halves[k], halves[1 - k]
            ref = np.broadcast_to(self.lam[:, cidx].mean(1, keepdims=True), self.lam[:, idx].shape)
            sub = tuple(p[:, :, idx] for p in parts)
            chol = self._proposal_factor(th[:, :, idx], ref, sub, log_sigma[:, :, idx], idx)
            scale = 2.38 / np.sqrt(d) * (0.3 if rng.random() < 0.3 else 1.0)
            z = rng.standard_normal(chol.shape[:-1])
            prop = self.lam[:, idx] + scale * np.einsum("ewtij,ewtj->ewti", chol, z) * self.free
            new = self._frame_density(th[:, :, idx], prop, sub, log_sigma[:, :, idx], idx)
            ok = np.log(rng.random(new.shape)) < new - cur[:, idx]
            self.lam[:, idx] = np.where(ok[..., None], prop, self.lam[:, idx])
            cur[:, idx] = np.where(ok, new, cur[:, idx])
            self.accepted["frames"] += ok.mean() / 2

    def _proposal_factor(self, th, lam_ref, parts, log_sigma, walkers=slice(None)):
        """Cholesky factor of the inverse of the frame latents' Fisher
        information plus the priors' Gaussian precisions
        (:meth:`_prior_precisions` of ``walkers``), (E, H, T, L, L)."""
        data = self.data
        weights = il.frame_weights(lam_ref, data)
        s = np.exp(th[..., 2:3])
        mus = [s * w * p for w, p in zip(weights, parts, strict=True)]
        mu_sky = sum(mus[1:])
        v = mus[0] + mu_sky + data.floor[None, :, None, None]
        weight = (np.exp(-2 * log_sigma)[..., None] + 2.0) / v**2 * data.valid[None, :, None, :]
        # d mu / d (log e, log a, log b, u_1 ... u_(K-1)); d mu / d u_k = mu_k - w_k mu_sky
        grads = [mus[0] + mu_sky, mus[0], mu_sky]
        if data.shapes >= 2:
            w = np.exp(il.log_shape_weights(lam_ref))[:, None]  # (E, 1, H, T, K)
            grads += [mus[1 + k] - w[..., k] * mu_sky for k in range(1, data.shapes)]
        else:
            grads.append(np.zeros_like(mu_sky))
        g = np.moveaxis(np.stack(grads, axis=-1), 1, -2)  # (E, H, T, F, L)
        info = np.swapaxes(g * np.moveaxis(weight, 1, -1)[..., None], -1, -2) @ g
        return proposal_square_root(info, self._prior_precisions(walkers))

    def _prior_precisions(self, walkers=slice(None)) -> np.ndarray:
        """The frame latents' prior precisions for the proposals, (L,): the
        sun's cloud component's, the sky's, the exposure's (a huge one where
        it is known), and about the logistic's for the sky shapes' ratios."""
        data = self.data
        fp = data.frame_priors
        fixed = 1e12
        ratio = 1.0 / 1.8**2 if data.shapes >= 2 else fixed  # ~ the logistic's sd
        prior = np.array(
            [
                fixed if data.exposure_known else 1.0 / fp.exposure_sd**2,
                1.0 / fp.sun_cloud_sd**2,
                1.0 / fp.sky_sd**2,
                *[ratio] * (data.n_latents - 3),
            ]
        )
        return prior

    # -- collective moves: along the directions Gibbs is slow in ----------------

    def state(self) -> np.ndarray:
        """Every walker's whole state as a vector, (E, W, D): each facet's
        gamma, log n, log s, then each frame's free latents."""
        th = self.th.transpose(0, 2, 1, 3).reshape(self.e, self.w, -1)
        lam = self.lam[..., self.free].reshape(self.e, self.w, -1)
        return np.concatenate([th, lam], axis=-1)

    def _split(self, x):
        f3 = 3 * self.f
        th = x[..., :f3].reshape(self.e, self.w, self.f, 3).transpose(0, 2, 1, 3)
        lam = self.lam.copy()
        lam[..., self.free] = x[..., f3:].reshape(self.e, self.w, self.t, -1)
        return th, lam

    def _full_density(self, th, lam) -> np.ndarray:
        """The joint log posterior (sigma integrated out) of every walker, (E, W)."""
        lp = il.log_prior_facets(th, self.data)
        ll = il.log_likelihood_sigma_marginal(th, lam, self.data)
        out = np.sum(np.where(np.isfinite(lp), lp + ll, -np.inf), axis=1)
        return out + self._frame_prior(lam).sum(-1)

    def adapt(self, states) -> None:
        """Directions for the collective moves from burn-in states (n, E, W, D).

        The generalised eigenvectors of the states' covariance S against the
        block-diagonal conditional covariance C (the inverse of each block's
        part of S^-1: a facet's (gamma, log n, log s), a frame's latents):
        S v = lambda C v. Along a v with large lambda the posterior is lambda
        times wider than the blocks' moves can step, and the Gibbs sweeps
        crawl; :meth:`collective_moves` steps in the span of the ``COLLECTIVE`` widest.
        Called during burn-in only: the production run's kernel is fixed.
        """
        from scipy import linalg

        x = states.reshape(-1, states.shape[-1]).astype(float)
        cov = np.cov(x, rowvar=False)
        d = len(cov)
        cov += 1e-12 * np.trace(cov) / d * np.eye(d)
        prec = np.linalg.inv(cov)
        cond = np.zeros_like(cov)
        for b in self._blocks():
            cond[b, b] = np.linalg.inv(prec[b, b])
        vals, vecs = linalg.eigh(cov, cond)
        top = np.argsort(vals)[::-1][:COLLECTIVE]
        # scaled to the posterior's sd along each: v' S^-1 v = 1
        vecs = vecs[:, top]
        vecs /= np.sqrt(np.einsum("di,de,ei->i", vecs, prec, vecs))
        self.directions = vecs.T  # (K, D)
        self.inflation = vals[top]

    def _blocks(self) -> list[slice]:
        """The Gibbs blocks' slices of :meth:`state`: each facet's (gamma, log
        n, log s), then each frame's free latents."""
        k = int(self.free.sum())
        blocks = [slice(3 * i, 3 * i + 3) for i in range(self.f)]
        return blocks + [slice(3 * self.f + k * i, 3 * self.f + k * (i + 1)) for i in range(self.t)]

    def collective_moves(self) -> None:
        """One random-walk Metropolis step in the span of the adapted
        directions: x + z V with z ~ N(0, (2.38^2 / K) I) over the K
        directions (each scaled to the posterior's sd along it), shrunk 0.3
        times in three sweeps of ten, so that one step also fits a posterior
        narrower than the burn-in's. One joint step costs two evaluations
        of the density where one step along each direction in turn cost K +
        1: on four bundles (clear, Perez with broken cloud, CIE partly
        cloudy, overcast) gamma's effective sample size per second rose
        about 1.25 times (``studies/README.md``, "The sampler's schedule
        and speed"). Leaves the density of the state it ends in in
        ``_density`` (the next sweep's first move starts from it)."""
        self._density = None
        if self.directions is None:
            return
        x = self.state()
        cur = self._full_density(*self._parts())
        k = len(self.directions)
        scale = 2.38 / np.sqrt(k) * (1.0 if self.rng.random() < 0.7 else 0.3)
        prop = x + (scale * self.rng.standard_normal((self.e, self.w, k))) @ self.directions
        new = self._full_density(*self._split(prop))
        ok = np.log(self.rng.random(new.shape)) < new - cur
        self._assign(self._split(np.where(ok[..., None], prop, x)))
        self._density = np.where(ok, new, cur)
        self.accepted["collective"] += ok.mean()

    def _parts(self) -> tuple:
        """The state's parts as :meth:`_split` gives them: (th, lam)."""
        return self.th, self.lam

    def _assign(self, parts) -> None:
        self.th, self.lam = parts

    def _exposure_ridge(self) -> None:
        c = 0.5 * self.rng.standard_normal((self.e, self.w, self.t))
        prop = self.lam + c[..., None] * self.data.exposure_direction
        ratio = self._frame_prior(prop) - self._frame_prior(self.lam)
        ok = np.log(self.rng.random(ratio.shape)) < ratio
        self.lam = np.where(ok[..., None], prop, self.lam)

    def _scale_ridge(self, tries: int = 3) -> None:
        shift = np.zeros(self.data.n_latents)
        shift[[1, 2] if self.data.exposure_known else [0]] = 1.0
        for _ in range(tries):
            c = self.scale_step * self.rng.standard_normal((self.e, self.w))
            th = self.th
            th_new = th.copy()
            th_new[..., 2] -= c[:, None, :]
            lam_new = self.lam + c[:, :, None, None] * shift
            old = il.log_prior_facets(th, self.data).sum(1) + il.log_prior_frames(
                self.lam, self.data
            ).sum(-1)
            new = il.log_prior_facets(th_new, self.data).sum(1) + il.log_prior_frames(
                lam_new, self.data
            ).sum(-1)
            ok = np.log(self.rng.random(c.shape)) < new - old  # (E, W)
            th[..., 2] = np.where(ok[:, None, :], th_new[..., 2], th[..., 2])
            self.lam = np.where(ok[:, :, None, None], lam_new, self.lam)
            self.accepted["scale"] += ok.mean() / tries


def _log_sigma_draws(q, curve_data: lk.CurveData, rng) -> np.ndarray:
    """Each facet's log sigma from its conditional given Q (E, F, W), (E, F, W)
    (:func:`bayesgloss.likelihood.draw_log_sigma`, which takes facets first)."""
    e, f, w = q.shape
    qf = q.transpose(1, 0, 2).reshape(f, -1)  # (F, E W)
    ls = lk.draw_log_sigma(np.zeros(qf.shape + (3,)), curve_data, rng, q=qf)
    return ls.reshape(f, e, w).transpose(1, 0, 2)


def _curve_data_at(data: il.JointData, lam) -> lk.CurveData:
    """The facets alone with every frame's latents fixed at ``lam`` (T, L)."""
    weights = np.stack(
        [
            np.broadcast_to(w[0, 0, 0], lam.shape[:1])
            for w in il.frame_weights(lam[None, None], data)
        ]
    )  # (P, T)
    cd = data.curve_data()
    return lk.CurveData(
        cd.y,
        cd.valid,
        cd.censored if data.censored is None else data.censored,
        np.sum(weights[:, None] * data.diffuse, axis=0),
        np.sum(weights[:, None, None] * data.glossy, axis=0),
        cd.log_n_grid,
        cd.log_s_center,
        priors=cd.priors,
    )


def starting_frames(data: il.JointData, rounds: int = 8) -> np.ndarray:
    """A start for every frame's latents near the joint optimum, (T, L).

    Alternates least squares: the facets' best (gamma, n, s) on the
    exponent table given the frames (:func:`node_fits`), then each frame's
    sources (e a and each sky model's e b w_k) by non-negative weighted least
    squares over the facets given them (weights 1 / (y + c)^2, the relative
    noise), ``rounds`` times. It starts from every sky model alone with its
    own sun (:attr:`~bayesgloss.illumination.JointData.log_sun_ratio`), and
    from the even mixture with a clear and with a dimmed sun, and keeps the
    start that fits best: a glossy lobe can stand in for a circumsolar
    brightening or a sun brighter than the day's, and alternating least
    squares started there stays there (measured on a Radiance bundle under
    gensky's intermediate sky: from the clear sun, gamma 0.8 at a weighted
    rms of 3.5 %; from the intermediate sky's own sun, gamma 0.09 at 1.0 %).
    Without a start the sampler would spend its burn-in carrying all
    facets' gloss and the frames' brightness together from the model's
    brightness to theirs.
    """
    t = data.shape[1]
    ratio = data.log_sun_ratio
    if ratio is None:
        ratio = np.zeros((data.shapes, t))
    dimmed = np.full(t, data.frame_priors.sun_cloud_mean)
    starts = [(None, np.zeros(t)), (None, dimmed)]
    if data.shapes >= 2:
        starts += [(k, ratio[k]) for k in range(data.shapes)]
    best, best_rms = None, np.inf
    for shape, log_sun in starts:
        lam, rms = _alternating_fit(data, shape, log_sun, rounds)
        if rms < best_rms:
            best, best_rms = lam, rms
    return best


def _alternating_fit(data: il.JointData, shape, log_sun, rounds):
    """Alternating least squares of :func:`starting_frames` from one sky shape
    (None: the even mixture) and a sun (T,): (lam (T, L), weighted rms of the fit)."""
    from scipy import optimize

    f, t = data.shape
    k = data.shapes
    lam = np.zeros((t, data.n_latents))
    lam[:, 1] = log_sun
    if shape is not None and shape > 0:
        lam[:, 2 + shape] = 6.0  # w ~ 1 on that shape
    elif shape == 0:
        lam[:, 3:] = -6.0
    sw = np.sqrt(data.relative_weights)
    rms = np.inf
    for _ in range(rounds):
        cd = _curve_data_at(data, lam)
        a, b, node_rms = node_fits(cd)
        best = np.argmin(node_rms, axis=1)
        s = (a + b)[np.arange(f), best]
        gamma = np.where(s > 0, b[np.arange(f), best] / np.maximum(s, 1e-300), 0.5)
        th = np.zeros((1, f, 1, 3))
        th[..., 0] = gamma[None, :, None]
        th[..., 1] = data.log_n_grid[best][None, :, None]
        parts = il.unit_parts(th, data)
        sources = parts if k >= 2 else parts[:2]
        cols = np.stack([s[:, None] * p[0, :, 0] for p in sources], axis=-1)  # (F, T, P)
        x = np.empty((t, cols.shape[-1]))
        resid = 0.0
        for j in range(t):  # per frame: y_f = sum_p x_p cols_fp, x >= 0
            x[j], r = optimize.nnls(cols[:, j] * sw[:, j, None], data.y[:, j] * sw[:, j])
            resid += r**2
        rms = np.sqrt(resid / max(data.valid.sum(), 1))
        x = np.clip(x, 1e-3 * np.maximum(x.max(axis=1, keepdims=True), 1e-30), None)
        sun, sky_total = x[:, 0], x[:, 1:].sum(axis=1)
        log_e = lam[:, 0] if data.log_exposure is None else data.log_exposure
        # the scale is the facets' business: keep the frames' mean level at the prior's
        shift = np.mean(0.5 * (np.log(sun) + np.log(sky_total)))
        lam[:, 1] = np.log(sun) - log_e - shift
        lam[:, 2] = np.log(sky_total) - log_e - shift
        if k >= 2:
            lam[:, 3:] = np.log(x[:, 2:]) - np.log(x[:, 1:2])
    return lam, rms


def sample_joint(
    data: il.JointData,
    *,
    n_ensembles: int = 4,
    n_walkers: int = 16,
    chunk: int = 200,
    min_sweeps: int = 800,
    max_sweeps: int = 8000,
    draws_per_ensemble: int = 1000,
    seed: int | None = 0,
    progress=None,
    jobs: int = 1,
) -> JointSamples:
    """Sample the joint posterior of facets and per-frame illumination.

    Parameters
    ----------
    data : bayesgloss.illumination.JointData
    n_ensembles : int
        Independent ensembles (R-hat needs several).
    n_walkers : int
        Walkers per ensemble (even, >= 6).
    chunk : int
        Sweeps between convergence checks.
    min_sweeps, max_sweeps : int
        Sweeps at least and at most; the first half of the run is burn-in.
    draws_per_ensemble : int
        Draws kept per ensemble (every walker's trajectory thinned evenly).
    seed : int or None
    progress : callable, optional
        Called with (sweeps done, max_sweeps) after each chunk.
    jobs : int
        Worker processes for the ensembles' groups
        (:func:`~bayesgloss.sampling.schedule.run_chain`; the draws do not depend on it).

    Returns
    -------
    JointSamples
    """
    return run_chain(
        _JointChain,
        data,
        n_ensembles=n_ensembles,
        n_walkers=n_walkers,
        chunk=chunk,
        min_sweeps=min_sweeps,
        max_sweeps=max_sweeps,
        draws_per_ensemble=draws_per_ensemble,
        seed=seed,
        progress=progress,
        jobs=jobs,
    )
