"""What a joint run reports of its own convergence (bayesgloss.joint_estimate)."""

from types import SimpleNamespace

import numpy as np

from bayesgloss import cli
from bayesgloss.joint_estimate import frame_convergence, object_convergence


def _run(t: int, bad_sun=(), bad_sky=(), gamma_rhat=1.002):
    # the run's statistics: gamma's first, then each frame's log a, then log b
    rhat = np.full(1 + 2 * t, 1.001)
    ess = np.full(1 + 2 * t, 2000.0)
    rhat[0] = gamma_rhat
    for k in bad_sun:
        ess[1 + k] = 150.0  # bulk ESS short of 400
    for k in bad_sky:
        rhat[1 + t + k] = 1.03
    return SimpleNamespace(rhat=rhat, ess_bulk=ess, ess_tail=ess.copy())


def test_frames_short_of_the_rule_are_named_by_their_index_in_the_bundle():
    # 4 frames used of a bundle of 6 (frames 0 and 5 before sunrise, after
    # sunset); the run's frame 1 (bundle frame 2) fails on its sun, its frame
    # 3 (bundle frame 4) on its sky. Reading the statistics in the wrong order
    # (sky before sun, or gamma taken for a frame) names other frames
    used = np.array([False, True, True, True, True, False])
    run = _run(4, bad_sun=[1], bad_sky=[3])
    np.testing.assert_array_equal(frame_convergence(run, 4), [True, False, True, False])
    c = object_convergence(run, used)
    assert c["frames_not_converged"] == [2, 4]
    assert c["gamma"]["meets_rule"] and c["gamma"]["rhat"] == 1.002
    line = cli._convergence_line(c)
    assert "meets the rule" in line and "frames 2, 4" in line


def test_gloss_short_of_the_rule_is_said_so():
    used = np.ones(3, bool)
    c = object_convergence(_run(3, gamma_rhat=1.02), used)
    assert not c["gamma"]["meets_rule"] and c["frames_not_converged"] == []
    line = cli._convergence_line(c)
    assert "short of the rule" in line and "frame" not in line
