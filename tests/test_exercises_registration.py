"""The checks of notebook 3's exercises say "correct" for a right answer and "not yet" otherwise."""

import numpy as np

from helpers.exercises.registration import check_least_share, check_msac_cost


def _pair(seed=0):
    """Matched points of a known motion: 60 correct matches (1 cm of noise) and 140 wrong ones."""
    rng = np.random.default_rng(seed)
    a = np.radians(5.0)
    T_true = np.eye(4)
    T_true[:3, :3] = [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]]
    T_true[:3, 3] = [6.0, 0.5, 0.0]
    moving = rng.uniform(-100, 100, (200, 3)) * [1, 1, 0.05]
    fixed = moving @ T_true[:3, :3].T + T_true[:3, 3] + rng.normal(scale=0.01, size=moving.shape)
    fixed[60:] = rng.uniform(-100, 100, (140, 3)) * [1, 1, 0.05]
    return moving, fixed, T_true


def test_msac_cost(capsys):
    moving, fixed, T_true = _pair()

    def cost(T, square=True, truncate=True):
        r = np.linalg.norm(moving @ T[:3, :3].T + T[:3, 3] - fixed, axis=1)
        r = r**2 if square else r
        return np.minimum(r, 1.0).sum() if truncate else r.sum()

    shifted = T_true.copy()
    shifted[0, 3] += 0.5
    motions = {"the true motion": T_true, "half a metre off": shifted, "no motion": np.eye(4)}
    check_msac_cost(cost, moving, fixed, 1.0, motions)
    check_msac_cost(lambda T: cost(T, truncate=False), moving, fixed, 1.0, motions)  # not truncated
    check_msac_cost(lambda T: cost(T, square=False), moving, fixed, 1.0, motions)  # distances, not squared
    check_msac_cost(lambda T: 1 / 0, moving, fixed, 1.0, motions)  # raises
    check_msac_cost(None, moving, fixed, 1.0, motions)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["correct"] + ["not yet"] * 4
    assert "the true motion costs least" in lines[0] and "less than" not in lines[0]
    assert "costs max_distance squared" in lines[1] and "square the residuals" in lines[2]
    assert "ZeroDivisionError" in lines[3]
    cheaper_than_truth = {"the true motion": T_true, "the best fit": _fitted(moving[:60], fixed[:60])}
    check_msac_cost(cost, moving, fixed, 1.0, cheaper_than_truth)
    assert "the best fit costs least, less than the true motion" in capsys.readouterr().out


def _fitted(moving, fixed):
    """The least-squares rigid motion of moving onto fixed (Kabsch)."""
    m_bar, f_bar = moving.mean(axis=0), fixed.mean(axis=0)
    U, _, Vt = np.linalg.svd((moving - m_bar).T @ (fixed - f_bar))
    R = Vt.T @ np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))]) @ U.T
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, f_bar - R @ m_bar
    return T


def test_least_share(capsys):
    w = least_share = (1 - 0.01 ** (1 / 3000)) ** (1 / 3)  # (1 - w^3)^3000 = 1 - 0.99
    assert abs((1 - least_share**3) ** 3000 - 0.01) < 1e-12
    check_least_share(w, 3000, 0.99, w_pair=0.104)
    check_least_share(w, 3000, 0.99)
    check_least_share(w**3, 3000, 0.99)  # the share of all-correct samples, not of matches
    check_least_share((1 - 0.001 ** (1 / 3000)) ** (1 / 3), 3000, 0.99)  # the wrong confidence
    check_least_share(100 * w, 3000, 0.99)  # a percentage
    check_least_share(None, 3000, 0.99)
    check_least_share("a lot", 3000, 0.99)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["correct"] * 2 + ["not yet"] * 5
    assert "below it" in lines[0] and "0.115" in lines[0]
    assert "0 and 1" in lines[4]
