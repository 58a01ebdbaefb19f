import numpy as np

from fppo_jax.core.normalization import RunningStats


def test_running_stats_match_the_whole_data():
    rng = np.random.default_rng(0)
    batches = [rng.normal(3.0, 2.0, size=(n, 4)).astype(np.float32) for n in (7, 50, 1, 300)]
    stats = RunningStats.create((4,))
    for batch in batches:
        stats = stats.update(batch)
    data = np.concatenate(batches)
    np.testing.assert_allclose(stats.mean, data.mean(0), rtol=1e-4)
    np.testing.assert_allclose(stats.var, data.var(0), rtol=1e-3)
    np.testing.assert_allclose(float(stats.count), len(data), rtol=1e-6)
    normalized = np.asarray(stats.normalize(data))
    np.testing.assert_allclose(normalized.mean(0), 0.0, atol=1e-3)
    np.testing.assert_allclose(normalized.std(0), 1.0, rtol=1e-3)


def test_normalize_clips():
    stats = RunningStats.create((1,)).update(np.array([[0.0], [1.0]], np.float32))
    assert float(stats.normalize(np.array([1e6], np.float32))[0]) == 10.0
    assert float(stats.scale(np.array([-1e6], np.float32), clip=5.0)[0]) == -5.0
