"""Independence proposals in log n: each facet's posterior of log n on cells.

With a few frames a day, the glossy peak of a sharp lobe can fall between
frames, and curves of quite different exponents fit almost equally well:
the posterior of log n then has separated modes, which moves built from
walker differences rarely cross. :class:`ExponentJump` tabulates, for every
facet, a proposal density of log n that follows its posterior (with a
uniform floor), and the fits of the other coordinates at each cell; the
moves ``"n-jump"`` and ``"ridge-jump"`` of :mod:`bayesgloss.sampling.moves`
draw from it. On 600 facets drawn from the prior the n-jump (with starts
reflected, not clipped, into bounded ranges) took the facets at the
8000-step cap from 14 to 1; the ridge-jump took the median autocorrelation
time of facets in ridge coordinates from 13.7 to 5.5 steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import likelihood as lk
from .coordinates import RidgeCoordinates, node_fits, nonnegative_pair

__all__ = ["ExponentJump"]


@dataclass(frozen=True)
class ExponentJump:
    """Independence proposals in log n, for posteriors with several modes in n
    or a ridge along it.

    With a few frames a day, the glossy peak of a sharp lobe can fall
    between frames, and curves of quite different exponents fit almost
    equally well: the posterior of log n then has separated modes, which
    the ensemble moves (built from differences of walkers) rarely cross.
    This move proposes each walker's log n afresh from a fixed density q
    built from the facet's posterior of log n approximated on cells:

        q(x) = (1 - eps) q_m / h + eps / (prior width of log n),

    for x in cell m of a window of M cells of width h, q_m proportional to
    exp(l_m), l_m the log posterior density at the cell centre with gamma
    and s (and sigma, where it is sampled) at their weighted least-squares
    values c_m there; in ridge coordinates l_m also carries the Laplace
    volume of (gamma, log s) at that exponent, log |L11 L22| - 2 log s
    (:class:`RidgeCoordinates`), so that q follows the marginal, not the
    profile, posterior. The window is found on M cells over the prior range
    of log n and then spans the cells with density above e^-25 of the
    highest, plus one cell each side, on which l is computed again: a
    posterior narrower than a cell of the prior range (log n to 0.005 with
    little noise) is then resolved. The floor eps keeps every exponent
    reachable.

    The walker's other coordinates follow the fit: z' = z + c(m') - c(m) for
    a move from cell m to m' (in ridge coordinates c = 0: they already are
    offsets from the ridge at n). Given the two exponents this is a
    translation, whose reverse is the reverse move's, so Metropolis-Hastings
    with the independence factor q(x_n) / q(y_n) leaves the posterior
    invariant (Tierney 1994, "Markov chains for exploring posterior
    distributions", Ann. Stat. 22, sec. 2.3.3). With ``fresh``, the ridge
    offsets (u1, u2) of ridge-coordinate walkers are drawn afresh too, from
    a bivariate t with ``nu`` degrees of freedom (their conditional
    posterior is close to standard normal there), which makes the move an
    independence sampler of the whole point.

    Attributes
    ----------
    bounds : tuple of float
        The prior range of log n.
    floor : float
        eps.
    lo, width : ndarray (B,)
        Left edge of each window and its cell width h [log n].
    log_q : ndarray (B, M)
        log((1 - eps) q_m / h), the window part of log q in each cell.
    cdf : ndarray (B, M)
        Cumulative cell probabilities q_m (last exactly 1).
    fit : ndarray (B, M, P)
        c_m in each row's sampling coordinates (the log n column unused):
        plain ones from :meth:`of`; :meth:`take` puts ``ridge_fit`` in the
        rows it marks as ridge coordinates.
    column : ndarray (B,) of int
        The sampling coordinate that holds log n (0 in ridge coordinates,
        1 in plain ones).
    ridge_fit : ndarray (B, M, 3) or None
        c_m in ridge coordinates, (log n, u1, u2) (from :meth:`of` with
        ``ridge``; None after :meth:`take`).
    spread : ndarray (B,) or None
        Scale of the fresh ridge offsets: the noise (rms) at the best fine
        cell over the best node's, at most 1 (None: 1).
    """

    bounds: tuple
    floor: float
    lo: np.ndarray
    width: np.ndarray
    log_q: np.ndarray
    cdf: np.ndarray
    fit: np.ndarray
    column: np.ndarray
    ridge_fit: np.ndarray | None = None
    spread: np.ndarray | None = None

    @classmethod
    def of(
        cls,
        data: lk.CurveData,
        marginal: bool,
        cells: int = 400,
        floor: float = 0.1,
        block: int = 64,
        ridge: RidgeCoordinates | None = None,
    ) -> ExponentJump:
        """The proposal of every facet of ``data`` (plain coordinates; see
        :meth:`take` for ridge ones; ``ridge`` adds the Laplace volume to
        the facets it samples in ridge coordinates)."""
        lo0, hi0 = data.priors.log_n
        b = len(data.y)
        w_nodes = node_fits(data, weights=True)[3]  # the fits' weights, once for both passes

        def on_cells(edges):
            """Cell width, relative posterior density (B, M), fits and Q at the
            centres of M cells between each row's edges."""
            width = (edges[:, 1] - edges[:, 0]) / cells
            centres = edges[:, :1] + width[:, None] * (np.arange(cells) + 0.5)
            parts = [
                _profile_log_posterior(
                    data.take(np.arange(i, min(i + block, b))), c, marginal, w_nodes[i : i + block]
                )
                for i, c in ((i, centres[i : i + block]) for i in range(0, b, block))
            ]
            log_post = np.concatenate([lp for (lp, _), _ in parts])
            fit = np.concatenate([th for _, th in parts])
            q = np.concatenate([q for (_, q), _ in parts]) if marginal else None
            if ridge is not None:  # the Laplace volume of (gamma, log s) at each n
                v = ridge._at(centres)
                with np.errstate(invalid="ignore", divide="ignore"):
                    volume = np.log(v[2] * v[4]) - 2.0 * fit[..., 2]
                log_post = np.where(ridge.active[:, None], log_post + volume, log_post)
            with np.errstate(invalid="ignore"):
                w = np.exp(log_post - np.max(log_post, axis=1, keepdims=True))
            return width, np.where(np.isfinite(w), w, 0.0), fit, q

        # the prior range first, then the cells above e^-25 of the peak and one each side
        width, w, _, _ = on_cells(np.tile([lo0, hi0], (b, 1)))
        keep = w > np.exp(-25.0)
        first = np.where(keep.any(1), np.argmax(keep, 1) - 1, 0)
        last = np.where(keep.any(1), cells - np.argmax(keep[:, ::-1], 1) + 1, cells)
        span = np.stack([np.maximum(first, 0), np.minimum(last, cells)], 1)
        edges = lo0 + width[:, None] * span
        width, w, fit, q = on_cells(edges)
        tot = w.sum(axis=1, keepdims=True)
        w = np.where(tot > 0, w / np.where(tot > 0, tot, 1.0), 1.0 / cells)
        cdf = np.cumsum(w, axis=1)
        cdf /= cdf[:, -1:]
        with np.errstate(divide="ignore"):
            log_q = np.log((1.0 - floor) * w / width[:, None])
        column = np.ones(b, dtype=int)
        ridge_fit = np.zeros(fit.shape[:2] + (3,))
        spread = np.ones(b)
        if ridge is not None and marginal:
            # the fits in ridge coordinates, and the scale of the offsets: the
            # noise at the best fine cell against the best node's, which the
            # node grid's interpolation error inflates
            with np.errstate(invalid="ignore", divide="ignore"):
                ridge_fit = ridge.from_theta(fit[..., :3])
                q_min = np.min(q, axis=1)
                n_valid = np.maximum(data.valid.sum(1), 1)
                spread = np.sqrt(q_min / n_valid) / ridge.rms
            ok = np.all(np.isfinite(ridge_fit), axis=(1, 2)) & np.isfinite(spread) & (spread > 0)
            ridge_fit = np.where(ok[:, None, None], ridge_fit, 0.0)
            spread = np.where(ok, np.clip(spread, 1e-3, 1.0), 1.0)
        return cls(
            (float(lo0), float(hi0)),
            float(floor),
            edges[:, 0],
            width,
            log_q,
            cdf,
            fit,
            column,
            ridge_fit,
            spread,
        )

    def take(self, index, ridge=None) -> ExponentJump:
        """Rows ``index``; ``ridge`` (bool per row) marks ridge coordinates."""
        idx = np.asarray(index)
        col = self.column[idx] if ridge is None else np.where(ridge, 0, 1)
        fit = self.fit[idx]
        spread = None if self.spread is None else self.spread[idx]
        if ridge is not None:
            r = np.asarray(ridge)[:, None, None]
            fit = np.where(r, 0.0 if self.ridge_fit is None else self.ridge_fit[idx], fit)
        return ExponentJump(
            self.bounds,
            self.floor,
            self.lo[idx],
            self.width[idx],
            self.log_q[idx],
            self.cdf[idx],
            fit,
            col,
            None,
            spread,
        )

    def _log_density(self, x):
        """log q at x (B, H) and the (clipped) cell of x in its row's window."""
        b, m = self.cdf.shape
        pos = np.floor((x - self.lo[:, None]) / self.width[:, None])
        inside = (pos >= 0) & (pos < m)
        cell = np.clip(pos, 0, m - 1).astype(np.intp) + (np.arange(b) * m)[:, None]
        window = np.where(inside, np.exp(np.take(self.log_q, cell)), 0.0)
        return np.log(window + self.floor / (self.bounds[1] - self.bounds[0])), cell

    def propose(self, s, rng, fresh: bool = False, nu: float = 4.0):
        """Proposals (B, H, P) for walkers s and the log factor log q(x) - log q(y)
        (``fresh``: ridge offsets drawn afresh, see the class docstring)."""
        b, h, p = s.shape
        m = self.cdf.shape[1]
        u = rng.random((3, b, h))
        row = np.arange(b)[:, None]
        # every row's cdf lifted by its row number: one sorted array to search
        cell = np.searchsorted((self.cdf + row).ravel(), u[0] + row, side="right") - row * m
        lo0, hi0 = self.bounds
        new = np.where(
            u[2] < self.floor,
            lo0 + u[1] * (hi0 - lo0),
            self.lo[:, None] + (np.minimum(cell, m - 1) + u[1]) * self.width[:, None],
        )
        old = np.take_along_axis(s, self.column[:, None, None], axis=2)[..., 0]
        log_q_old, cell_old = self._log_density(old)
        log_q_new, cell_new = self._log_density(new)
        factor = log_q_old - log_q_new
        fit = self.fit.reshape(b * m, -1)[:, :p]
        fit_old, fit_new = np.take(fit, cell_old, 0), np.take(fit, cell_new, 0)
        moved = s + fit_new - fit_old
        out = np.where((self.column[:, None, None] == np.arange(p)), new[..., None], moved)
        if fresh:  # ridge offsets from a bivariate t about the fit, in ridge rows
            ridge = (self.column == 0)[:, None]
            scale = (np.ones(b) if self.spread is None else self.spread)[:, None, None]
            t = rng.standard_normal((b, h, 2)) / np.sqrt(rng.chisquare(nu, (b, h, 1)) / nu)

            def log_t(v):
                return -0.5 * (nu + 2.0) * np.log1p(np.sum(v * v, -1) / nu)

            t_old = (s[..., 1:3] - fit_old[..., 1:3]) / scale
            factor += np.where(ridge, log_t(t_old) - log_t(t), 0.0)
            fresh_u = fit_new[..., 1:3] + scale * t
            out[..., 1:3] = np.where(ridge[..., None], fresh_u, out[..., 1:3])
        return out, factor


def _profile_log_posterior(data: lk.CurveData, log_n, marginal: bool, w_nodes):
    """Log posterior density at each log n (B, M), with gamma and s (and sigma)
    at their weighted least-squares values there, and those values (B, M, P)
    (see :class:`ExponentJump`); ``log_n`` (M,) or one row per facet (B, M);
    ``w_nodes`` the weights of :func:`node_fits` (B, N, T)."""
    log_n = np.broadcast_to(log_n, (len(data.y), np.shape(log_n)[-1]))
    j, frac = lk.grid_position(log_n, data.log_n_grid)
    rows = np.arange(len(data.y))[:, None]
    g = data.glossy[rows, j] + frac[..., None] * (data.glossy[rows, j + 1] - data.glossy[rows, j])
    w = w_nodes[rows, np.rint(j + frac).astype(np.intp)]  # weights of the nearest node
    y, d = data.y[:, None, :], data.diffuse[:, None, :]
    y = np.maximum(y, 0.0) if data.camera == "power" else y
    a, b = nonnegative_pair(y, d, g, w)
    s = a + b
    ok = s > 0
    th = np.empty(a.shape + (3 if marginal else data.n_params,))
    th[..., 0] = np.where(ok, b / np.where(ok, s, 1.0), 0.5)
    th[..., 1] = log_n
    th[..., 2] = np.where(ok, np.log(np.where(ok, s, 1.0)), data.log_s_center[:, None])
    if marginal:
        return lk.log_probability_sigma_marginal(th, data, with_q=True), th
    n_valid = np.maximum(data.valid.sum(1), 1)[:, None]
    mu = a[..., None] * d + b[..., None] * g
    rms = np.sqrt(np.sum(w * (y - mu) ** 2, -1) / n_valid)
    lo_s, hi_s = data.priors.log_sigma
    th[..., 3] = np.clip(np.log(np.maximum(rms, 1e-300)), lo_s + 1e-6, hi_s - 1e-6)
    if data.n_params == 5:
        th[..., 4] = 0.0  # g = 1
    return (lk.log_probability(th, data), None), th
