"""The batched split statistic equals the one statsmodels fits table by table (significance.factor_lrt)."""

import numpy as np
import pytest

from roboview.eval.statistics.batch_glm import value_lrt
from roboview.eval.statistics.significance import factor_lrt

pytestmark = pytest.mark.slow


def one_at_a_time(k: np.ndarray, n: np.ndarray, value: np.ndarray, context: np.ndarray) -> np.ndarray:
    tests = [factor_lrt(row.astype(float), n.astype(float), value, context, None) for row in k]
    return np.array([0.0 if t is None else t.statistic for t in tests])


@pytest.mark.parametrize(
    ("values", "contexts", "repeats", "sr"),
    [(9, 4, 2, 0.7), (6, 3, 8, 0.5), (21, 11, 2, 0.9), (5, 2, 3, 0.97)],
)
def test_the_statistic_matches_statsmodels_table_by_table(values, contexts, repeats, sr):
    rng = np.random.default_rng(values * contexts)
    value, context = np.repeat(np.arange(values), contexts), np.tile(np.arange(contexts), values)
    p = 1 / (1 + np.exp(-(np.log(sr / (1 - sr)) + rng.normal(0, 0.8, values)[value])))
    k = rng.binomial(repeats, p, size=(40, len(value)))
    n = np.full(len(value), repeats)
    fast = value_lrt(k, n, value, context)
    # Sparse tables: separated values and contexts with one outcome only are among them.
    assert (fast > 1).mean() > 0.5
    np.testing.assert_allclose(fast, one_at_a_time(k, n, value, context), atol=1e-6)


def test_uneven_cells_missing_cells_and_uninformative_contexts():
    rng = np.random.default_rng(0)
    value, context = np.repeat(np.arange(5), 3), np.tile(np.arange(3), 5)
    keep = np.ones(15, bool)
    keep[[4, 11]] = False  # two (value, context) cells never ran
    value, context = value[keep], context[keep]
    n = rng.integers(1, 6, len(value))
    k = rng.binomial(n, 0.6, size=(30, len(value)))
    k[:5, context == 2] = n[context == 2]  # context 2 all successes: carries no information
    k[5] = 0  # nothing succeeds anywhere: no test at all
    fast = value_lrt(k, n, value, context)
    assert fast[5] == 0.0
    np.testing.assert_allclose(fast, one_at_a_time(k, n, value, context), atol=1e-6)


def test_one_cell_per_value_and_context():
    with pytest.raises(ValueError, match="one cell per"):
        value_lrt(np.ones((1, 3)), np.ones(3), np.array([0, 0, 1]), np.array([0, 0, 1]))
