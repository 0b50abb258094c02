"""The one-material sampler: the object's gloss, its facets' albedos and each frame's light.

The object's answer comes from a model in which the object is one material
(issue "Nobody tells bayesgloss the sky", item 4): every facet has the same
gamma and exponent n, and its own scale s_f (albedo times the camera's
units) drawn from one population,

    log s_f ~ N(m, tau^2),   m ~ N(median_f log s0_f, 3^2),   log tau ~ U(log 0.01, log 3),

with each frame's latents (sun, sky, sky shape, exposure) those of
:mod:`bayesgloss.illumination` (:func:`bayesgloss.illumination.log_prior_material`)
and one relative noise sigma for all facets, integrated out
(:func:`bayesgloss.illumination.log_likelihood_shared_sigma`, which says
why: a sigma for each facet let the frames fit one facet at a time exactly,
and the walkers jammed on those ridges).
Facets whose brightness differs for a reason the model does not know (a
patch of another paint, a shadow the geometry misses) widen tau instead of
bending gamma. Where the data cannot tell gloss (no direct sun), one albedo
still lets the sky's uneven brightness over the facets tell it, and if it
cannot, the posterior of gamma stays the prior's: the object's answer is the
posterior of one parameter, not a product of facet posteriors that the
shared frames make dependent (the product read 0.82 [0.71, 0.90] for a true
0.42 on a simulated overcast day).

:func:`sample_material` is :func:`bayesgloss.sampling.joint.sample_joint`'s
scheme (Metropolis within Gibbs, E ensembles of W walkers, each walker a
whole state) with these blocks per sweep:

1. **(gamma, log n) given the rest**: the ensemble moves on the 2-D shared
   coordinates, each walker's density its own (its scales and frames), every
   facet's log s and every frame's log a and log b carried along their joint
   least-squares profile (a shift with unit Jacobian, so the move is exact;
   without the scales carried, a change of gamma, which changes every
   facet's level, was refused and the walkers jammed: acceptance 0.02 on a
   simulated overcast day; carrying the frames too raised the effective
   sample size of gamma per sweep 3.6 times on a clear day and 4 times on a
   broken-cloud one);
2. **the one sigma given the rest**, drawn and later discarded (partially collapsed
   Gibbs, as in the joint sampler);
3. **each facet's log s given sigma, m and tau**: random-walk Metropolis,
   facets independent, steps from the Fisher information at the data;
4. **m and log tau given the scales**: exact draws (m normal; tau^-2 a
   gamma variable truncated to the prior's range); likewise, where the
   exposure is unknown, **the day's exposure mean and spread given the
   frames' log exposures** (:func:`bayesgloss.illumination.hyper_size`);
5. **the day's sun weights** (clear, dimmed, hidden; Dirichlet(1, 1, 1)):
   random-walk Metropolis in log-ratio coordinates. One day-level weight
   for all frames: with each frame's sun clear with a fixed probability
   0.8, an overcast day (every sun hidden) was so improbable a priori that a
   mirror-like material, whose sun no facet sees, won: gamma 0.96-1.00 on
   every overcast day, simulated or rendered;
6. the frames' latents given sigma, the exposure ridge and the collective
   moves along adapted directions, as in :mod:`bayesgloss.sampling.joint`,
   and **the sun's jumps**: each frame's log a proposed afresh from its
   prior mixture, accepted by the frame's likelihood ratio (under the prior
   alone the random walk gave each frame's log a an ESS of 170-340 in 1200
   sweeps, the jumps 6200-7400); with the exposure unknown, each frame's
   exposure ridge is drawn on a lattice as the scale ridge is;
7. **the scale ridge**: every log s_f and m - c, every frame's brightness
   + c (the likelihood and the albedo population unchanged), c drawn from
   the conditional that the priors of m and of the frames make on a lattice
   (:mod:`bayesgloss.sampling.ridge`: that conditional is bimodal where the
   sun is hazy, and a random walk did not cross between its modes); where
   the exposures are drawn about the day's, the day's mean moves with them.

Where entries clipped at the top code are kept (``clipped="likelihood"``,
:mod:`bayesgloss.sampling.censored`), each sweep first completes them and
draws sigma given the completed data, and every block then takes that
sigma as given (the shared and collective moves too), the clipped entries
by their survival term.
"""

from __future__ import annotations

import numpy as np

from .. import fresnel as fr
from .. import illumination as il
from . import censored, exposure_moves, populations, ridge, schedule
from .joint import _JointChain, starting_frames
from .moves import DEFAULT_MOVES, move_named
from .schedule import JointSamples, run_chain
from .starts import _reflect, _robust_scales, start_theta, starting_material

__all__ = ["sample_material", "first_check"]

#: The one-material sampler's schedule (stop 37): burn-in rounds of 100
#: sweeps, then the stopping rule checked every 100 sweeps from 400 on. The
#: rule and the cap are the joint sampler's, so a run stops earlier only where
#: the rule already holds: on the benchmark bundle it held at 400-600 sweeps
#: after burn-in, where the old schedule (rounds of 200, every 200 from 800)
#: ran on to 800 (``studies/README.md``, "The sampler's schedule and speed").
MATERIAL_BURN_ROUNDS = (100, 100, 100)
MATERIAL_CHUNK = 100
MATERIAL_MIN_SWEEPS = 400
#: The reach of the ridge moves' lattices, in steps
#: (:func:`~bayesgloss.sampling.ridge.lattice_shift`).
RIDGE_REACH = 4


class _MaterialChain(_JointChain):
    """E ensembles of W walkers of the one-material model, and one sweep."""

    def __init__(self, data: il.JointData, n_ensembles, n_walkers, rng):
        self._setup(data, n_ensembles, n_walkers, rng)
        lam0 = starting_frames(data)
        gamma0, log_n0, log_s0, fresnel0 = starting_material(data, lam0)
        e, f, w = self.e, self.f, self.w
        dx = data.log_n_grid[1] - data.log_n_grid[0]
        lo, hi = data.priors.log_n
        # the shared coordinates: gamma, log n (and the Fresnel k, log A)
        self.shared = [0, 1] + (list(fr.FRESNEL_COLUMNS) if data.fresnel is not None else [])
        th = np.zeros((e, f, w, 3 if data.fresnel is None else 6))
        g = _reflect(gamma0 + 0.02 * rng.standard_normal((e, 1, w)), 0.0, 1.0)
        n = _reflect(log_n0 + 0.3 * dx * rng.standard_normal((e, 1, w)), lo, hi)
        th[..., 0], th[..., 1] = g, n
        th[..., 2] = log_s0[None, :, None] + 0.02 * rng.standard_normal((e, f, w))
        if data.fresnel is not None:  # k and A about the start's (column 3 unused)
            k_col, a_col = fr.FRESNEL_COLUMNS
            a_lo, a_hi = np.log(fr.NORMAL_ALBEDO_RANGE)
            k0, a0 = fresnel0
            th[..., k_col] = _reflect(k0 + 0.1 * rng.standard_normal((e, 1, w)), 0.0, 1.0)
            log_a = np.log(a0) + 0.3 * rng.standard_normal((e, 1, w))
            th[..., a_col] = _reflect(log_a, a_lo, a_hi)
        self.th = th
        # clipped entries: each walker's completed values and its sigma (censored)
        self.y_complete = censored.starting_completion(data, (e, f, w))
        self.log_sigma = None
        # each facet's residual sd at the start (relative), fixed: the profile's weights
        th0 = start_theta(f, 1, fresnel0)
        th0[..., 0], th0[..., 1], th0[..., 2] = gamma0, log_n0, log_s0[None, :, None]
        z, _ = il._residuals(il.predict(th0, lam0[None, None], data), data)
        rms = np.sqrt(np.sum(z[0, :, 0] ** 2, -1) / np.maximum(data.valid.sum(1), 1))
        self.profile_weights = data.relative_weights / np.maximum(rms, 0.003)[:, None] ** 2
        self.lam = lam0 + 0.05 * rng.standard_normal((e, w, *lam0.shape)) * self.free
        # m, log tau, the day's sun weights v1, v2 (and the day's exposure mu_e, log sd_e)
        self.hyper = np.zeros((e, w, il.hyper_size(data)))
        self.hyper[..., 0] = th[..., 2].mean(1)
        lt = np.log(np.clip(th[..., 2].std(1), 0.02, 2.0))
        self.hyper[..., 1] = lt
        if self.hyper.shape[-1] > 4:  # the frames' exposures' mean and spread
            self.hyper[..., 4] = self.lam[..., 0].mean(-1)
            self.hyper[..., 5] = np.log(np.clip(self.lam[..., 0].std(-1), 0.02, 1.0))
        self._moves = [move_named(name) for name, _ in DEFAULT_MOVES]
        self._cdf = np.cumsum([x for _, x in DEFAULT_MOVES])
        self._cdf /= self._cdf[-1]
        # the Fisher information of log s per unit of (sigma^-2 + 2), at the data
        self.info_unit = np.sum(np.where(data.valid, data.relative_weights * data.y**2, 0.0), 1)
        fp = data.frame_priors
        if data.exposure_known:
            precision = 1 / il.MATERIAL_M_SD**2 + self.t * (
                1 / fp.sun_clear_sd**2 + 1 / fp.sky_sd**2
            )
        elif self.hyper.shape[-1] > 4:  # the ridge carries the day's exposure mean too
            precision = 1 / il.MATERIAL_M_SD**2 + 1 / fp.exposure_sd**2
        else:
            precision = 1 / il.MATERIAL_M_SD**2 + self.t / fp.exposure_sd**2
        self.scale_step = 1.0 / np.sqrt(precision)
        self.accepted = {"shared": 0.0, "scales": 0.0, "frames": 0.0, "scale": 0.0}
        self.accepted["collective"] = 0.0
        self.accepted["sun jump"] = 0.0

    # -- the blocks --------------------------------------------------------------

    def _profile(self, parts, lam, rounds: int = 4):
        """The joint weighted least-squares fit of every facet's log s and every
        frame's log a and log b at theta's gamma and n (``parts``, E, F, H, T
        each), each frame's exposure and sky shape those of ``lam``: (log s
        (E, F, H), (log a, log b) (E, H, T, 2)).

        Alternating least squares from the sky model's brightness (a = b =
        1), ``rounds`` times: each facet's scale given the frames, then each
        frame's (a, b) given the scales (a 2 x 2 solve, each kept above 1 %
        of the model's, so a sun hidden from every facet stays there); the
        weights those of relative noise of each facet's sd at the start
        (``profile_weights``); the scales' mean log fixed at 0 (the level is
        the frames'). A function of gamma, n and coordinates the shared move
        leaves alone, as the move's shift must be. (Carrying each sky
        model's weight too, by non-negative least squares, cost twice the
        time for no better mixing on a broken-cloud day.)
        """
        data = self.data
        wts = il.frame_weights(lam, data)  # e a, then e b w_k at the walkers' lam
        sun = wts[0] * np.exp(-lam[..., 1])[:, None] * parts[0]  # e S at a = 1
        sky = sum(wk * pk for wk, pk in zip(wts[1:], parts[1:], strict=True))
        sky = sky * np.exp(-lam[..., 2])[:, None]  # e sum_k w_k K^k at b = 1
        w = self.profile_weights[None, :, None, :]
        y = self.data.y[None, :, None, :]

        def scales(a, b):  # each facet's least-squares scale given the frames
            unit = a[:, None] * sun + b[:, None] * sky
            s = np.sum(w * y * unit, -1) / np.maximum(np.sum(w * unit * unit, -1), 1e-300)
            return _robust_scales(s, axis=1)

        a = np.ones(lam.shape[:-1])
        b = np.ones(lam.shape[:-1])
        for _ in range(rounds):
            s = scales(a, b)[..., None]
            x1, x2 = s * sun, s * sky
            h11, h12, h22 = (np.sum(w * u * v, 1) for u, v in ((x1, x1), (x1, x2), (x2, x2)))
            g1, g2 = np.sum(w * y * x1, 1), np.sum(w * y * x2, 1)
            ridge = 1e-9 * (h11 + h22) + 1e-300
            det = (h11 + ridge) * (h22 + ridge) - h12 * h12
            with np.errstate(invalid="ignore", divide="ignore"):
                a = ((h22 + ridge) * g1 - h12 * g2) / det
                b = ((h11 + ridge) * g2 - h12 * g1) / det
            # a frame no facet sees stays at the model's brightness
            a = np.maximum(np.where(np.isfinite(a), a, 1.0), 0.01)
            b = np.maximum(np.where(np.isfinite(b), b, 1.0), 0.01)
        log_s = np.log(scales(a, b))
        level = log_s.mean(1)  # (E, H)
        frames = np.stack([np.log(a), np.log(b)], -1) + level[..., None, None]
        return log_s - level[:, None], frames

    def _likelihood(self, th, lam, parts=None, walkers=slice(None)):
        """The likelihood of the shared and collective moves, (E, H): sigma
        integrated out, or with clipped entries, given the sweep's sigma."""
        if self.y_complete is None:
            return il.log_likelihood_shared_sigma(th, lam, self.data, parts)
        log_sigma = self.log_sigma[:, :, walkers]
        return il.entry_log_likelihood(th, lam, log_sigma, self.data, parts).sum((1, 3))

    def _conditional(self, th, hyper, lam, parts, walkers=slice(None)) -> np.ndarray:
        """log p(gamma, n, s, frames | m, tau, sun weights), (E, H), for
        theta's :func:`~bayesgloss.illumination.unit_parts` ``parts`` and the
        state of ``walkers``; sigma integrated out (given, with clipped
        entries: :meth:`_likelihood`)."""
        lp = il.log_prior_material(th, hyper, self.data)
        ll = self._likelihood(th, lam, parts, walkers)
        frames = self._frame_prior(lam, hyper=hyper).sum(-1)
        # summed as :meth:`_full_density` sums: the same number for the same state
        return np.where(np.isfinite(lp), lp + ll, -np.inf) + frames

    def _shared_step(self) -> tuple:
        """The ensemble moves on (gamma, log n), half the sweeps with every
        facet's log s and every frame's log a and log b carried along their
        joint least-squares profile (:meth:`_profile`): x' = x + x^(gamma', n') - x^(gamma, n)
        (a shift fixed by the two points, so the map has unit Jacobian and
        reverses itself; in the coordinates (gamma, n, x - x^) the move is
        the ensemble's plain move of (gamma, n) given the rest). Without the
        scales carried, a change of gamma, which changes every facet's level,
        was refused (acceptance 0.02 on a simulated overcast day); without
        the frames, the walkers' spread in gamma, which is the marginal's,
        was wider than its conditional given the frames. Returns the new
        state's :func:`~bayesgloss.illumination.unit_parts`."""
        rng, p, data = self.rng, self.data.priors, self.data
        move = self._moves[int(self._cdf.searchsorted(rng.random(), side="right"))]
        # carried along the profile or not, at even odds fixed before the move
        # (a mixture of two exact kernels): where the data are mostly noise,
        # the profile's least-squares fit is noise too, and the carried move
        # alone was refused (acceptance 0.03 on a 24-facet prior draw at
        # sigma 0.57, its walkers' R-hat 5.7)
        carry = rng.random() < 0.5
        # the state's density, where the last sweep's collective move left it
        known, self._density = self._density, None
        order = rng.permutation(self.w)
        halves = (order[: self.w // 2], order[self.w // 2 :])
        out = None
        for k in (0, 1):
            idx, cidx = halves[k], halves[1 - k]
            lam, hyper = self.lam[:, idx], self.hyper[:, idx]
            old = self.th[:, :, idx]
            shared = self.shared
            q, factor = move.propose(
                old[:, 0][..., shared], self.th[:, 0][:, cidx][..., shared], rng, None
            )
            inside = (q[..., 0] >= 0) & (q[..., 0] <= 1) & (q[..., 1] >= p.log_n[0])
            inside &= q[..., 1] <= p.log_n[1]
            new = old.copy()
            new[..., 0] = np.clip(q[:, None, :, 0], 0.0, 1.0)
            new[..., 1] = np.clip(q[:, None, :, 1], *p.log_n)
            if len(shared) > 2:  # the Fresnel k and log A
                inside &= np.isfinite(fr.log_prior_fresnel(q[..., 2], q[..., 3]))
                new[..., shared[2]] = q[:, None, :, 2]
                new[..., shared[3]] = q[:, None, :, 3]
            parts_old = il.unit_parts(old, data, self.tables)
            parts_new = il.unit_parts(new, data, self.tables)
            lam_new = lam.copy()
            if carry:
                # both ends' profiles in one call on the ensembles' axis doubled
                # (the same numbers as two calls at half the calls' overhead)
                e = lam.shape[0]
                both = tuple(np.concatenate(x) for x in zip(parts_old, parts_new, strict=True))
                s_both, f_both = self._profile(both, np.concatenate([lam, lam]))
                s_old, s_new, f_old, f_new = s_both[:e], s_both[e:], f_both[:e], f_both[e:]
                new[..., 2] += s_new - s_old
                lam_new[..., 1 : 1 + f_new.shape[-1]] += f_new - f_old
            lp_new = self._conditional(new, hyper, lam_new, parts_new, idx)
            lp_new = np.where(inside, lp_new, -np.inf)
            if known is None:
                lp_old = self._conditional(old, hyper, lam, parts_old, idx)
            else:  # each walker's density is its own: the other half's move left it
                lp_old = known[:, idx]
            with np.errstate(invalid="ignore"):
                ok = np.log(rng.random(lp_new.shape)) < factor + lp_new - lp_old
            self.th[:, :, idx] = np.where(ok[:, None, :, None], new, old)
            self.lam[:, idx] = np.where(ok[:, :, None, None], lam_new, lam)
            self.accepted["shared"] += ok.mean() / 2
            if out is None:
                out = [np.empty(self.th.shape[:3] + (data.shape[1],)) for _ in parts_old]
            for whole, x_new, x_old in zip(out, parts_new, parts_old, strict=True):
                whole[:, :, idx] = np.where(ok[:, None, :, None], x_new, x_old)
        return tuple(out)

    def _scale_step(self, parts, log_sigma, tries: int = 2) -> None:
        """Random-walk Metropolis on every facet's log s given sigma, m and
        tau (facets independent then), proposal sd 2.38 / sqrt(I): I the
        Fisher information of log s at the data (fixed by sigma and tau)."""
        rng, data = self.rng, self.data
        tau = np.exp(self.hyper[..., 1])[:, None, :]  # (E, 1, W)
        m = self.hyper[..., 0][:, None, :]
        inv_var = np.exp(-2 * log_sigma)  # (E, F, W)
        info = (inv_var + 2.0) * self.info_unit[None, :, None] + 1.0 / tau**2
        step = 2.38 / np.sqrt(info)

        def density(th):
            if self.y_complete is not None:
                ll = il.entry_log_likelihood(th, self.lam, log_sigma, data, parts).sum(-1)
                return ll - 0.5 * ((th[..., 2] - m) / tau) ** 2
            z, sum_log_v = il._residuals(il.predict(th, self.lam, data, parts), data, axis=-1)
            ll = np.sum(-0.5 * z * z, -1) * inv_var - sum_log_v
            return ll - 0.5 * ((th[..., 2] - m) / tau) ** 2

        cur = density(self.th)
        for _ in range(tries):
            prop = self.th.copy()
            prop[..., 2] += step * rng.standard_normal(step.shape)
            new = density(prop)
            ok = np.log(rng.random(new.shape)) < new - cur
            self.th[..., 2] = np.where(ok, prop[..., 2], self.th[..., 2])
            cur = np.where(ok, new, cur)
            self.accepted["scales"] += ok.mean() / tries

    # -- the sweep -------------------------------------------------------------

    def sweep(self) -> None:
        data = self.data
        if self.y_complete is not None:  # clipped entries completed, then sigma drawn
            self.log_sigma = censored.completion_and_sigma(self)
            self._density = None  # the collective move's density was at the old sigma
        parts = self._shared_step()
        if self.y_complete is None:
            _, q = il.log_likelihood_shared_sigma(self.th, self.lam, data, parts, with_q=True)
            log_sigma = self._draw_log_sigma(q)
        else:
            log_sigma = self.log_sigma
        self._scale_step(parts, log_sigma)
        self._hyper_draw()
        self._sun_weight_step()
        self._frame_moves(self.th, parts, log_sigma)
        self._sun_jump(self.th, parts, log_sigma)
        if not data.exposure_known:
            self._exposure_ridge()
            if self.hyper.shape[-1] > 4:  # the day's exposure level and spread
                exposure_moves.level_ridge(self)
                exposure_moves.spread_move(self)
        self._scale_ridge()
        self.collective_moves()
        self.sweeps += 1

    def _draw_log_sigma(self, q, data=None):
        return il.draw_shared_log_sigma(q, self.data if data is None else data, self.rng)

    def _frame_density(self, th, lam, parts, log_sigma, walkers=slice(None)):
        if self.y_complete is None:
            return super()._frame_density(th, lam, parts, log_sigma, walkers)
        ll = il.entry_log_likelihood(th, lam, log_sigma, self.data, parts).sum(1)
        return ll + self._frame_prior(lam, walkers)

    def _frame_prior(self, lam, walkers=slice(None), hyper=None):
        hyper = self.hyper[:, walkers] if hyper is None else hyper
        return il.log_prior_frames(
            lam, self.data, il.log_sun_weights(hyper), exposure=il.exposure_day(hyper)
        )

    def _frame_prior_along(self, offsets, direction, hyper=None) -> np.ndarray:
        """:meth:`_frame_prior` of every walker's frames moved by each of the
        offsets (K, E, W, T) or broadcastable, along ``direction`` (L,), at the
        day's exposure of ``hyper`` (it may carry the offsets' axis): (K, E,
        W, T), by :func:`~bayesgloss.illumination.log_prior_frames_along`.
        The ridges leave the day's sun weights alone, so they are the
        walkers' own."""
        hyper = self.hyper if hyper is None else hyper
        return il.log_prior_frames_along(
            self.lam,
            offsets,
            direction,
            self.data,
            il.log_sun_weights(self.hyper),
            exposure=il.exposure_day(hyper),
        )

    def _prior_precisions(self, walkers=slice(None)) -> np.ndarray:
        """As the joint sampler's, with each walker's own precision of log
        e_t about the day's where the exposure is day-level, (E, H, 1, L)."""
        prior = super()._prior_precisions(walkers)
        if self.hyper.shape[-1] <= 4:
            return prior
        out = np.broadcast_to(prior, (*self.hyper[:, walkers].shape[:2], 1, len(prior))).copy()
        out[..., 0, 0] = np.exp(-2 * self.hyper[:, walkers, 5])
        return out

    def _sun_weight_step(self, tries: int = 3) -> None:
        """Random-walk Metropolis on the day's sun weights (v_1, v_2) given the
        frames' log a (Dirichlet(1, 1, 1) prior in the log-ratio coordinates)."""
        rng = self.rng

        def density(hyper):
            return self._frame_prior(self.lam, hyper=hyper).sum(-1) + il.log_sun_weights(hyper).sum(
                -1
            )

        cur = density(self.hyper)
        for _ in range(tries):
            prop = self.hyper.copy()
            prop[..., 2:4] += rng.standard_normal(prop[..., 2:4].shape)
            new = density(prop)
            ok = np.log(rng.random(new.shape)) < new - cur
            self.hyper = np.where(ok[..., None], prop, self.hyper)
            cur = np.where(ok, new, cur)

    def _hyper_draw(self) -> None:
        """m and log tau from their exact conditionals given the scales (module
        docstring); where the exposure is day-level, mu_e and log sd_e given
        the frames' log exposures alike (mu_e's prior N(0, exposure_sd^2))."""
        rng, log_s = self.rng, self.th[..., 2]  # (E, F, W)
        c0 = il.material_m_center(self.data)
        m = populations.draw_mean(log_s, 1, self.hyper[..., 1], c0, il.MATERIAL_M_SD, rng)
        self.hyper[..., 0] = m
        ss = np.sum((log_s - m[:, None]) ** 2, axis=1)
        self.hyper[..., 1] = populations.draw_log_spread(ss, self.f, rng, il.MATERIAL_LOG_TAU)
        if self.hyper.shape[-1] > 4:  # the frames' log exposures, (E, W, T)
            log_e, s0 = self.lam[..., 0], self.data.frame_priors.exposure_sd
            mu = populations.draw_mean(log_e, -1, self.hyper[..., 5], 0.0, s0, rng)
            ss = np.sum((log_e - mu[..., None]) ** 2, axis=-1)
            self.hyper[..., 4] = mu
            self.hyper[..., 5] = populations.draw_log_spread(
                ss, self.t, rng, il.EXPOSURE_LOG_SPREAD
            )

    def _scale_ridge(self) -> None:
        """Block 7: every log s_f and m down by c, every frame's brightness up
        by c (the likelihood and the albedo population unchanged), c drawn by
        :func:`~bayesgloss.sampling.ridge.lattice_shift` from the conditional
        that the priors of m and of the frames (at the day's sun weights)
        make, on a lattice of spacing h = u x the ridge's Gaussian width, u
        uniform on [0.2, 0.6] and fresh each sweep. A random-walk step of that
        width (accepted 0.74) left the ridge's two modes unmixed: the
        ensembles' m 1.3 apart on a hazy Mitsuba render (``studies/README.md``,
        "Stop 41: why most answers on renders say `not-converged`")."""
        shift = np.zeros(self.data.n_latents)
        shift[[1, 2] if self.data.exposure_known else [0]] = 1.0
        c0, sd = il.material_m_center(self.data), il.MATERIAL_M_SD
        h = self.scale_step * self.rng.uniform(0.2, 0.6)
        c = ridge.lattice_offsets(RIDGE_REACH)[:, None, None] * h  # (K, E, W)
        m = self.hyper[..., 0]
        # where the frames' exposures are drawn about the day's, its mean moves with them
        day = self.hyper.shape[-1] > 4
        hyper = exposure_moves.mean_shifted(self.hyper, c) if day else self.hyper
        frames = self._frame_prior_along(c[..., None], shift, hyper)
        lp = -0.5 * ((m - c - c0) / sd) ** 2 + frames.sum(-1)
        if day:
            lp = lp + il.log_prior_exposure_mean(hyper, self.data)
        moved = ridge.lattice_shift(lp, RIDGE_REACH, self.rng) * h  # (E, W)
        self.th[..., 2] -= moved[:, None, :]
        self.hyper[..., 0] -= moved
        if day:
            self.hyper[..., 4] += moved
        self.lam = self.lam + moved[:, :, None, None] * shift
        self.accepted["scale"] += np.mean(moved != 0)

    def _sun_jump(self, th, parts, log_sigma) -> None:
        """Each frame's log a drawn afresh from the sun's prior (the mixture
        of clear, dimmed and hidden at the day's weights), accepted by the
        frame's likelihood ratio (an independence proposal from the prior:
        the priors cancel). Where the data pin the sun it is refused; where
        they hardly see it (a low sun, a sun most facets face away from) its
        posterior is the prior's mixture cut by the likelihood, whose modes
        the random walk of the frame moves crossed rarely: without data each
        frame's log a had an ESS of 170-340 in 1200 sweeps, with the jumps
        6200-7400. Where a frame's sun is cut off by very precise data the
        prior's draws are mostly refused and it stays slow (ESS 90-210;
        ``studies/README.md``, stop 41)."""
        rng, w = self.rng, np.exp(il.log_sun_weights(self.hyper))  # (E, W, 3)
        prop = self.lam.copy()
        prop[..., 1] = il.draw_log_sun(w, self.t, self.data.frame_priors, rng)
        if self.y_complete is None:
            cur = il.frame_log_likelihood(th, self.lam, log_sigma, self.data, parts)
            new = il.frame_log_likelihood(th, prop, log_sigma, self.data, parts)
        else:
            cur = il.entry_log_likelihood(th, self.lam, log_sigma, self.data, parts).sum(1)
            new = il.entry_log_likelihood(th, prop, log_sigma, self.data, parts).sum(1)
        ok = np.log(rng.random(new.shape)) < new - cur
        self.lam = np.where(ok[..., None], prop, self.lam)
        self.accepted["sun jump"] += ok.mean()

    def _exposure_ridge(self) -> None:
        """Each frame's exposure up by c and its sun and sky down by c (the
        likelihood unchanged), c drawn frame by frame as in
        :meth:`_scale_ridge`, on a lattice of spacing u x 0.5, u uniform on
        [0.2, 0.6]: the frame's conditional along it is its prior's, as
        bimodal as the scale ridge's where the sun is hazy."""
        direction = self.data.exposure_direction
        h = 0.5 * self.rng.uniform(0.2, 0.6)
        c = ridge.lattice_offsets(RIDGE_REACH) * h
        lp = self._frame_prior_along(c[:, None, None, None], direction)  # (K, E, W, T)
        moved = ridge.lattice_shift(lp, RIDGE_REACH, self.rng) * h  # (E, W, T)
        self.lam = self.lam + moved[..., None] * direction

    # -- collective moves: the whole state as a vector ---------------------------

    def state(self) -> np.ndarray:
        """Every walker's state, (E, W, D): gamma, log n (the Fresnel k and
        log A), each facet's log s, m, log tau, then each frame's free latents."""
        shared = self.th[:, 0][..., self.shared]
        log_s = self.th[..., 2].transpose(0, 2, 1)
        lam = self.lam[..., self.free].reshape(self.e, self.w, -1)
        return np.concatenate([shared, log_s, self.hyper, lam], axis=-1)

    def _split(self, x):
        f, ns = self.f, len(self.shared)
        th = np.zeros((self.e, f, self.w, self.th.shape[-1]))
        for i, col in enumerate(self.shared):
            th[..., col] = x[:, None, :, i]
        th[..., 2] = x[..., ns : ns + f].transpose(0, 2, 1)
        nh = self.hyper.shape[-1]
        hyper = x[..., ns + f : ns + f + nh]
        lam = self.lam.copy()
        lam[..., self.free] = x[..., ns + f + nh :].reshape(self.e, self.w, self.t, -1)
        return th, hyper, lam

    def _full_density(self, th, hyper, lam) -> np.ndarray:
        """The joint log posterior of every walker, (E, W): sigma integrated
        out, or with clipped entries given the sweep's (:meth:`_likelihood`)."""
        lp = il.log_prior_material(th, hyper, self.data)
        ll = self._likelihood(np.where(np.isfinite(lp)[:, None, :, None], th, self.th), lam)
        frames = self._frame_prior(lam, hyper=hyper).sum(-1)
        return np.where(np.isfinite(lp), lp + ll, -np.inf) + frames

    def _blocks(self) -> list[slice]:
        f, k, ns = self.f, int(self.free.sum()), len(self.shared)
        blocks = [slice(0, ns)] + [slice(ns + i, ns + 1 + i) for i in range(f)]
        nh = self.hyper.shape[-1]
        blocks += [slice(ns + f, ns + 2 + f), slice(ns + 2 + f, ns + f + min(nh, 4))]
        if nh > 4:  # the day's exposure mean and spread
            blocks.append(slice(ns + f + 4, ns + f + nh))
        o = ns + f + nh
        blocks += [slice(o + k * i, o + k * (i + 1)) for i in range(self.t)]
        return blocks

    def _parts(self) -> tuple:
        return self.th, self.hyper, self.lam

    def _assign(self, parts) -> None:
        self.th, self.hyper, self.lam = parts


def sample_material(
    data: il.JointData,
    *,
    n_ensembles: int = 4,
    n_walkers: int = 16,
    chunk: int = MATERIAL_CHUNK,
    min_sweeps: int = MATERIAL_MIN_SWEEPS,
    max_sweeps: int = 8000,
    draws_per_ensemble: int = 1000,
    seed: int | None = 0,
    progress=None,
    burn_rounds: tuple[int, ...] = MATERIAL_BURN_ROUNDS,
    resume=None,
    jobs: int = 1,
) -> JointSamples:
    """Sample the one-material model (module docstring).

    Parameters as :func:`bayesgloss.sampling.sample_joint`; the stopping
    rule is checked every ``chunk`` sweeps from ``min_sweeps`` on, once the
    kept half holds ``draws_per_ensemble`` draws (:data:`MATERIAL_CHUNK`,
    :data:`MATERIAL_MIN_SWEEPS`; the SBC of ``tests/test_material.py`` runs
    with these defaults); ``burn_rounds`` the burn-in's rounds
    (:data:`MATERIAL_BURN_ROUNDS`); ``resume`` a run stopped at its cap
    (:attr:`JointSamples.run`) to run on to ``max_sweeps``
    (:func:`~bayesgloss.sampling.schedule.run_chain`); ``jobs`` worker
    processes for the ensembles' groups (the draws do not depend on it).

    Returns
    -------
    JointSamples
        ``draws`` (F, E, S, 4) with every facet's gamma and log n the shared
        ones; ``material`` (E, S, H): the day-level coordinates
        (:data:`bayesgloss.illumination.HYPER`); diagnostics of gamma
        (first) and of every frame's log a and log b.
    """
    return run_chain(
        _MaterialChain,
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
        diagnosed_facets=1,
        burn_rounds=burn_rounds,
        resume=resume,
    )


def first_check(
    *,
    chunk: int = MATERIAL_CHUNK,
    min_sweeps: int = MATERIAL_MIN_SWEEPS,
    burn_rounds: tuple[int, ...] = MATERIAL_BURN_ROUNDS,
    draws_per_ensemble: int = 1000,
    n_walkers: int = 16,
    **_,
) -> int:
    """The sweeps after burn-in at which :func:`sample_material` with these
    options first checks its stopping rule (:func:`.schedule.first_check`
    with this sampler's defaults; other options ignored)."""
    return schedule.first_check(
        burn_rounds=burn_rounds,
        chunk=chunk,
        min_sweeps=min_sweeps,
        draws_per_ensemble=draws_per_ensemble,
        n_walkers=n_walkers,
    )
