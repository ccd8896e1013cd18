"""The descriptor matcher: the threshold, ratio and mutual tests, the gate in space, and its threads."""

import numpy as np
import pytest

from helpers.errors import SlamError
from helpers.slam.registration.features import normalise_descriptors
from helpers.slam.registration.matching import match_features


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_matcher_honours_threshold_and_ratio():
    fixed = np.eye(4)  # four orthogonal unit descriptors: normalised distance 1 between any two
    # moving 0: close to fixed 0 (normalised distance 0.05), far from the rest -> kept
    # moving 1: close to fixed 1 but at normalised distance 0.2 -> fails threshold 0.1, passes 0.3
    # moving 2: halfway between fixed 2 and fixed 3 -> ratio 1, always rejected

    def towards(i, j, dist):  # unit vector at normalised distance `dist` from e_i, in the (e_i, e_j) plane
        chord = dist * np.sqrt(2)
        theta = 2 * np.arcsin(chord / 2)
        v = np.zeros(4)
        v[i], v[j] = np.cos(theta), np.sin(theta)
        return v

    moving = np.array([towards(0, 1, 0.05), towards(1, 0, 0.2), _unit([0, 0, 1, 1])])
    pairs = match_features(moving, fixed, threshold=0.1, ratio=0.97)
    np.testing.assert_array_equal(pairs, [[0, 0]])
    pairs = match_features(moving, fixed, threshold=0.3, ratio=0.97)
    np.testing.assert_array_equal(pairs, [[0, 0], [1, 1]])
    pairs = match_features(moving, fixed, threshold=1.0, ratio=1.0)  # equal distances never pass the ratio test
    np.testing.assert_array_equal(pairs, [[0, 0], [1, 1]])


def test_matcher_ratio_test_rejects_ambiguous_matches():
    fixed = _unit([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    # best 0.05, second about 0.07: ratio about 0.7
    moving = _unit([[1.0, 0.1, 0.0]])
    d = np.linalg.norm(moving[0] - fixed, axis=1) / np.sqrt(2)
    ratio = d.min() / d.max()
    assert len(match_features(moving, fixed, threshold=1.0, ratio=ratio + 1e-6)) == 1
    assert len(match_features(moving, fixed, threshold=1.0, ratio=ratio - 1e-6)) == 0
    assert len(match_features(moving, fixed, threshold=d.min() - 1e-6, ratio=1.0)) == 0


def test_matcher_keeps_only_mutual_matches():
    fixed = _unit([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    moving = _unit([[1.0, 0.05, 0.0], [1.0, 0.01, 0.0]])  # both prefer fixed 0; only the nearer one keeps it
    np.testing.assert_array_equal(match_features(moving, fixed, threshold=1.0, ratio=0.99), [[1, 0]])


def test_matcher_refuses_bad_descriptors():
    good = np.eye(3)
    with pytest.raises(SlamError, match="NaN"):
        match_features(np.full((2, 3), np.nan), good, 0.1, 0.9)
    with pytest.raises(SlamError, match="non-empty"):
        match_features(np.zeros((0, 3)), good, 0.1, 0.9)
    with pytest.raises(SlamError, match="differ in length"):
        match_features(np.eye(4), good, 0.1, 0.9)


def _reference_matches(moving, fixed, threshold, ratio):
    """The matcher's rules, written plainly in float64 (a slow but obvious reference)."""
    d = np.linalg.norm(moving[:, None] - fixed[None], axis=2) / np.sqrt(2)
    pairs = []
    for i, row in enumerate(d):
        order = np.argsort(row, kind="stable")
        best, second = row[order[0]], row[order[1]]
        j = order[0]
        if best <= threshold and best < ratio * second and np.argmin(d[:, j]) == i:
            pairs.append((i, j))
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matcher_agrees_with_a_plain_float64_reference(seed):
    rng = np.random.default_rng(seed)
    fixed = normalise_descriptors(rng.gamma(0.5, 1.0, (700, 33)))
    moving = fixed[rng.permutation(700)[:500]] + rng.normal(0, 0.01, (500, 33))  # noisy copies ...
    moving = np.vstack([moving, normalise_descriptors(rng.gamma(0.5, 1.0, (300, 33)))])  # ... and strangers
    moving /= np.linalg.norm(moving, axis=1, keepdims=True)
    for threshold, ratio in [(0.1, 0.97), (0.05, 0.8), (1.0, 1.0)]:
        expected = _reference_matches(moving, fixed, threshold, ratio)
        assert len(expected) > 0
        np.testing.assert_array_equal(match_features(moving, fixed, threshold, ratio), expected)


def _gated_reference_matches(moving, fixed, moving_xy, fixed_xy, cell, threshold, ratio):
    """The gated matcher's rules, plainly: a pair may be compared when the cells of their points
    (``cell`` metres wide) are the same or touch; a ratio needs a runner-up among those."""
    cm, cf = np.floor(moving_xy / cell), np.floor(fixed_xy / cell)
    allowed = (np.abs(cm[:, None] - cf[None]) <= 1).all(axis=2)
    d = np.where(allowed, np.linalg.norm(moving[:, None] - fixed[None], axis=2) / np.sqrt(2), np.inf)
    pairs = []
    for i, row in enumerate(d):
        order = np.argsort(row, kind="stable")
        best, second, j = row[order[0]], row[order[1]], order[0]
        if np.isfinite(second) and best <= threshold and best < ratio * second and np.argmin(d[:, j]) == i:
            pairs.append((i, j))
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


@pytest.mark.parametrize("seed", [0, 1])
def test_gated_matcher_agrees_with_a_plain_float64_reference(seed):
    """With a gate in space, each descriptor is compared only with those in its cell and the 8 around."""
    rng = np.random.default_rng(seed)
    fixed = normalise_descriptors(rng.gamma(0.5, 1.0, (900, 33)))
    fixed_xy = rng.uniform([-150, -30], [150, 30], (900, 2))
    pick = rng.permutation(900)[:600]
    moving = fixed[pick] + rng.normal(0, 0.01, (600, 33))
    moving /= np.linalg.norm(moving, axis=1, keepdims=True)
    moving_xy = fixed_xy[pick] + rng.normal(0, 8.0, (600, 2))  # where the last motion puts them, metres off
    for cell, threshold, ratio in [(15.0, 0.1, 0.97), (30.0, 0.05, 0.8), (6.0, 1.0, 1.0)]:
        expected = _gated_reference_matches(moving, fixed, moving_xy, fixed_xy, cell, threshold, ratio)
        assert len(expected) > 0
        got = match_features(moving, fixed, threshold, ratio, near=(moving_xy, fixed_xy, cell))
        np.testing.assert_array_equal(got, expected)
    everywhere = match_features(moving, fixed, 0.1, 0.97, near=(moving_xy, fixed_xy, 1e4))
    np.testing.assert_array_equal(everywhere, match_features(moving, fixed, 0.1, 0.97))  # one cell holds all


def test_the_gate_keeps_a_far_lookalike_from_making_a_match_ambiguous():
    """A descriptor repeated 100 m away ties with the true partner: without the gate the ratio
    test drops the match, with it the far copy is never compared."""
    a, b = normalise_descriptors(np.eye(33)[[0, 5]] + 0.1)
    fixed = np.array([a, a, b])
    fixed_xy = np.array([[0.0, 0.0], [100.0, 0.0], [1.0, 0.0]])
    moving, moving_xy = np.array([a]), np.array([[0.5, 0.0]])
    assert len(match_features(moving, fixed, 0.1, 0.97)) == 0
    np.testing.assert_array_equal(match_features(moving, fixed, 0.1, 0.97, near=(moving_xy, fixed_xy, 10.0)), [[0, 0]])
    lone = match_features(moving, fixed[:2], 0.1, 0.97, near=(moving_xy, fixed_xy[:2], 10.0))
    assert len(lone) == 0  # one candidate in reach: no runner-up, no ratio, no match


def test_the_gate_refuses_bad_positions():
    good = np.eye(4) + 0.1  # any finite descriptors: the gate is checked first
    with pytest.raises(SlamError, match="finite x, y"):
        match_features(good, good, 0.1, 0.9, near=(np.zeros((3, 2)), np.zeros((4, 2)), 5.0))
    with pytest.raises(SlamError, match="finite x, y"):
        match_features(good, good, 0.1, 0.9, near=(np.full((4, 2), np.nan), np.zeros((4, 2)), 5.0))
    with pytest.raises(SlamError, match="cell"):
        match_features(good, good, 0.1, 0.9, near=(np.zeros((4, 2)), np.zeros((4, 2)), 0.0))


@pytest.mark.parametrize(
    "near", ["", ", near=(xy + rng.normal(0, 3, (3000, 2)), xy, 12.0)"], ids=["every descriptor", "gated"]
)
def test_matcher_gives_the_same_pairs_on_any_number_of_threads(thread_outputs, near):
    script = (
        "import numpy as np; from helpers.slam.registration.features import normalise_descriptors;"
        "from helpers.slam.registration.matching import match_features;"
        "rng = np.random.default_rng(4); f = normalise_descriptors(rng.gamma(0.5, 1.0, (3000, 33)));"
        "m = f[rng.permutation(3000)] + rng.normal(0, 0.01, (3000, 33));"
        "xy = rng.uniform(-100, 100, (3000, 2));"
        f"print(match_features(m / np.linalg.norm(m, axis=1, keepdims=True), f, 0.1, 0.97{near}).tobytes().hex())"
    )
    outputs = thread_outputs(script)
    assert len(outputs) == 1 and len(outputs.pop()) > 0


def test_the_matcher_multiplies_on_one_blas_thread(monkeypatch):
    """The matcher's block products run with numpy's BLAS held to one thread (faster on blocks this
    small), and the limit is lifted afterwards."""
    from helpers.slam.registration import matching
    from helpers.threads import BLAS

    seen = []
    real = np.matmul

    def spy(*args, **kwargs):
        seen.append([m["num_threads"] for m in BLAS.info() if m["user_api"] == "blas"])
        return real(*args, **kwargs)

    before = [m["num_threads"] for m in BLAS.info() if m["user_api"] == "blas"]
    assert before  # numpy's BLAS is found
    rng = np.random.default_rng(3)
    a = np.abs(rng.normal(size=(300, 33)))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    monkeypatch.setattr(matching.np, "matmul", spy)
    pairs = matching.match_features(a, a, 0.1, 0.97)
    monkeypatch.undo()
    assert np.array_equal(pairs, np.column_stack([np.arange(300), np.arange(300)]))  # each its own match
    assert seen and all(threads == [1] * len(threads) for threads in seen)
    assert [m["num_threads"] for m in BLAS.info() if m["user_api"] == "blas"] == before


def test_the_matcher_shares_its_blocks_between_threads(monkeypatch):
    """With two threads allowed, the block loop runs on two threads at once (each on whole blocks),
    and the pairs are those of one thread."""
    import threading

    from helpers.slam.registration import matching

    rng = np.random.default_rng(5)
    fixed = normalise_descriptors(rng.gamma(0.5, 1.0, (1000, 33)))
    moving = fixed[rng.permutation(1000)] + rng.normal(0, 0.01, (1000, 33))
    moving /= np.linalg.norm(moving, axis=1, keepdims=True)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    alone = match_features(moving, fixed, 0.1, 0.97)
    names, real = [], matching._blocks
    together = threading.Barrier(2, timeout=10)  # passes only when two parts run at the same time

    def spy(q, *args):
        names.append((threading.current_thread().name, len(q)))
        together.wait()
        return real(q, *args)

    monkeypatch.setattr(matching, "_blocks", spy)
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    shared = match_features(moving, fixed, 0.1, 0.97)
    np.testing.assert_array_equal(shared, alone)
    assert len(alone) > 500
    # the nearest of every moving row in two parts of whole blocks, then the back check's rows in two
    assert len(names) == 4 and all(name.startswith("helpers") for name, _ in names)
    half = 4 * matching.MATCH_BLOCK_ROWS  # 1000 rows are 8 blocks of 128 (the last short): 4 each
    assert sorted(rows for _, rows in names[:2]) == [1000 - half, half]


def test_a_forked_child_matches_on_threads_of_its_own():
    """The thread pool is the process's own: a child forked after the parent matched on two
    threads matches too (the parent's pool threads are not in it; waiting on them would hang)."""
    import multiprocessing

    rng = np.random.default_rng(6)
    fixed = normalise_descriptors(rng.gamma(0.5, 1.0, (600, 33)))
    expected = match_features(fixed, fixed, 0.1, 0.97)  # the parent's pool is made here (two threads or more)
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_match_and_report, args=(fixed, queue))
    child.start()
    child.join(timeout=20)
    if child.is_alive():
        child.kill()
        pytest.fail("the forked child's matcher hung")
    assert child.exitcode == 0
    np.testing.assert_array_equal(queue.get(timeout=5), expected)


def _match_and_report(fixed, queue):
    queue.put(match_features(fixed, fixed, 0.1, 0.97))
