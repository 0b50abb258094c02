"""The chain's schedule (bayesgloss.sampling.schedule): where the stopping
rule is first checked, and a run stopped at its cap run on."""

import numpy as np

from bayesgloss import illumination as il
from bayesgloss.sampling import first_check, sample_material
from bayesgloss.sampling.schedule import group_sizes

#: A short schedule on a small problem: 2 ensembles of 8 walkers, 80 draws
#: per ensemble (10 kept states per walker, so the kept half must hold 20
#: states of every 4th sweep: the rule is first checked 80 sweeps after
#: burn-in, not at ``min_sweeps`` 40).
SHORT = dict(
    n_ensembles=2,
    n_walkers=8,
    draws_per_ensemble=80,
    burn_rounds=(20, 20),
    chunk=40,
    min_sweeps=40,
)


def _data(paper_three_skies):
    full, up = paper_three_skies
    bases = full.take(slice(0, 5), np.flatnonzero(up)[3:9])
    f, t = bases.diffuse.shape[1:]
    rng = np.random.default_rng(2)
    y = 1.0 + 0.1 * rng.random((f, t))
    return il.joint_data(y, np.ones((f, t), bool), bases, exposure=np.ones(t))


def test_first_check_is_where_the_run_first_keeps_its_draws(paper_three_skies):
    # capped at first_check the run keeps the full 80 draws per ensemble; one
    # chunk earlier it cannot (the kept half holds 5 states a walker, not 10),
    # which is what made fits of different lengths unmixable (stop 36's crash)
    data = _data(paper_three_skies)
    assert first_check(**SHORT) == 80
    assert first_check() == 500  # the default schedule: 300 sweeps of burn-in, checked from 400
    full = sample_material(data, seed=1, max_sweeps=80, **SHORT)
    short = sample_material(data, seed=1, max_sweeps=40, **SHORT)
    assert full.draws.shape[2] == 80 and short.draws.shape[2] < 80


def test_a_run_run_on_is_the_longer_run_sweep_for_sweep(paper_three_skies):
    # 80 sweeps and then 80 more must give the draws of one run of 160: the
    # chain, its random generator and its kept states all carried. Data of
    # pure noise about 1 do not converge in 80 sweeps (the rule asks for an
    # ESS of 400), so the first run stops at its cap with its state
    data = _data(paper_three_skies)
    first = sample_material(data, seed=1, max_sweeps=80, **SHORT)
    assert not first.converged and first.run is not None
    on = sample_material(data, seed=1, max_sweeps=160, resume=first.run, **SHORT)
    whole = sample_material(data, seed=1, max_sweeps=160, **SHORT)
    assert on.n_sweeps == whole.n_sweeps == 200  # 40 of burn-in
    np.testing.assert_array_equal(on.draws, whole.draws)
    np.testing.assert_array_equal(on.frames, whole.frames)
    np.testing.assert_array_equal(on.material, whole.material)


def test_groups_run_in_worker_processes_give_the_same_draws(paper_three_skies):
    # the ensembles run in two groups, each with its own generator spawned
    # from the seed; run at once in two worker processes they must give the
    # draws of the same groups run one after the other, bit for bit (the
    # chains travel to the workers and back between checks)
    data = _data(paper_three_skies)
    assert group_sizes(4) == [2, 2] and group_sizes(3) == [2, 1] and group_sizes(1) == [1]
    one = sample_material(data, seed=3, max_sweeps=80, **SHORT)
    two = sample_material(data, seed=3, max_sweeps=80, jobs=2, **SHORT)
    np.testing.assert_array_equal(one.draws, two.draws)
    np.testing.assert_array_equal(one.frames, two.frames)
    np.testing.assert_array_equal(one.material, two.material)
    assert one.acceptance == two.acceptance
    # and the groups are chains of their own: their draws differ
    assert not np.array_equal(one.draws[:, 0], one.draws[:, 1])
