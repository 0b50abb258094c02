"""Posterior sampling: emcee's ensemble moves, batched over many facets at once.

The paper's study alone needs thousands of facet posteriors; stock emcee
runs one problem at a time and its per-step overhead dominates for a
19-frame likelihood. The package follows emcee's layout, one stage a module:

- :mod:`~bayesgloss.sampling.ensemble`: :class:`BatchedEnsemble`, B
  independent affine-invariant ensembles in lockstep, one vectorised
  log-density call per half-step;
- :mod:`~bayesgloss.sampling.moves`: the moves as small classes (stretch,
  differential evolution, and independence jumps in log n) and the mixes
  :data:`DEFAULT_MOVES` and :data:`FACET_MOVES`;
- :mod:`~bayesgloss.sampling.coordinates`: least-squares fits on the
  exponent table and :class:`RidgeCoordinates`, which straighten a facet's
  posterior ridge;
- :mod:`~bayesgloss.sampling.jumps`: :class:`ExponentJump`, each facet's
  proposal density of log n;
- :mod:`~bayesgloss.sampling.starts`: :func:`initial_ensemble`;
- :mod:`~bayesgloss.sampling.streams`: :class:`FacetStream`, the scheduler
  of facets through vectorised places (fill, advance, measure, retire);
- :mod:`~bayesgloss.sampling.posterior`: :func:`sample_posterior`, which
  deals facets into streams and runs them, in this process or on a pool;
- :mod:`~bayesgloss.sampling.joint`: :func:`sample_joint`, the facets and
  each frame's sun, sky and exposure together (Metropolis within Gibbs,
  every walker a whole state), for :mod:`bayesgloss.illumination`;
- :mod:`~bayesgloss.sampling.material`: :func:`sample_material`, the same
  scheme for the one-material model (shared gamma and n, hierarchical
  albedo: the object's answer), with :mod:`~bayesgloss.sampling.populations`
  (exact draws of its populations' means and spreads) and
  :mod:`~bayesgloss.sampling.exposure_moves` (the day-level exposure's level
  and spread moved with the likelihood unchanged);
- :mod:`~bayesgloss.sampling.facet_answers`: :func:`facets_given_frames`,
  each facet's own posterior given the object's illumination;
- :mod:`~bayesgloss.sampling.ridge`: :func:`lattice_shift`, an exact move
  along a ridge whose conditional only the priors shape (the one-material
  sampler's scale and exposure ridges);
- :mod:`~bayesgloss.sampling.material_density` and
  :mod:`~bayesgloss.sampling.hamiltonian`: the one-material model's density
  and gradient in unconstrained coordinates, and Hamiltonian Monte Carlo of
  it (:func:`sample_material_hmc`; not yet the default, see its module).

Autocorrelation times, R-hat, ESS and the convergence rule live in
:mod:`bayesgloss.diagnostics`. On the paper's facets the median integrated
autocorrelation time was 62 steps with the stretch move alone, 29 with
(stretch 0.5, DE 0.4, DE-jump 0.1) and 21-23 with DE-dominated mixes; with
the ridge-jump, the mean run of the paper's facets fell from 1230 to 430
steps.
"""

from .coordinates import RIDGE_MAX_RMS, RidgeCoordinates
from .ensemble import BatchedEnsemble
from .facet_answers import facets_given_frames
from .joint import JointSamples, sample_joint
from .jumps import ExponentJump
from .material import first_check, sample_material
from .moves import DEFAULT_MOVES, FACET_MOVES, PLAIN_JUMP
from .posterior import PosteriorSamples, sample_posterior
from .starts import initial_ensemble
from .streams import FIRST_CHECK_TAUS, FacetStream

__all__ = [
    "first_check",
    "BatchedEnsemble",
    "sample_material",
    "facets_given_frames",
    "DEFAULT_MOVES",
    "FACET_MOVES",
    "PLAIN_JUMP",
    "RidgeCoordinates",
    "RIDGE_MAX_RMS",
    "ExponentJump",
    "initial_ensemble",
    "FacetStream",
    "FIRST_CHECK_TAUS",
    "PosteriorSamples",
    "sample_posterior",
    "JointSamples",
    "sample_joint",
]
