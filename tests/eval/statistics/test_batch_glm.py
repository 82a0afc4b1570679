"""The batched fits equal statsmodels' table by table: the split statistic (significance.factor_lrt) and any one
design's log-likelihood (the factorial split's additive and A×B fits)."""

import numpy as np
import pytest
from scipy.special import gammaln

from roboview.eval.statistics.batch_glm import design_llf, spanning_columns, value_lrt
from roboview.eval.statistics.significance import (
    binomial_llf,
    design_matrix,
    factor_lrt,
    interaction_codes,
    interaction_lrt,
)

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


def factorial_tables(rng: np.random.Generator, shape: tuple[int, int, int], sr: float, drop: float):
    """Bootstrap-like tables of a factorial split (A × B × context, some combinations missing, 1–4 episodes per
    cell, separated cells among them), with its additive and A×B designs and the cells' (context, A, B) codes."""
    n_a, n_b, n_c = shape
    a, b, c = (x.ravel() for x in np.meshgrid(*(np.arange(m) for m in shape), indexing="ij"))
    keep = rng.random(len(a)) > drop
    a, b, c = a[keep], b[keep], c[keep]
    n = rng.integers(1, 5, len(a))
    logit = np.log(sr / (1 - sr)) + rng.normal(0, 1, n_a)[a] + rng.normal(0, 1, n_b)[b]
    k = rng.binomial(n, 1 / (1 + np.exp(-logit)), size=(30, len(a)))
    codes = [np.unique(x, return_inverse=True)[1] for x in (c, a, b)]
    full = design_matrix([*codes, interaction_codes(codes[1], codes[2])])
    return k, n, design_matrix(codes), full, codes


@pytest.mark.parametrize(
    ("shape", "sr", "drop"), [((4, 6, 3), 0.6, 0.1), ((3, 3, 5), 0.9, 0.2), ((2, 2, 2), 0.5, 0.0)]
)
def test_any_design_matches_statsmodels_table_by_table(shape, sr, drop):
    k, n, additive, full, _ = factorial_tables(np.random.default_rng(sum(shape)), shape, sr, drop)
    spanning = spanning_columns(full)
    assert spanning.shape[1] == np.linalg.matrix_rank(full) < full.shape[1]  # the A×B design is redundant
    # statsmodels' llf includes Σ log C(n, k)
    constant = (gammaln(n + 1) - gammaln(k + 1) - gammaln(n - k + 1)).sum(axis=1)
    for design in (additive, spanning):
        one_by_one = np.array([binomial_llf(row, n, design)[0] for row in k])
        np.testing.assert_allclose(design_llf(k, n, design) + constant, one_by_one, atol=1e-6)
    # The redundant design gives the fit of the space it spans; the nested fit is never better.
    np.testing.assert_allclose(design_llf(k, n, full), design_llf(k, n, spanning), atol=1e-9)
    assert (design_llf(k, n, full) >= design_llf(k, n, additive) - 1e-9).all()


def test_the_interaction_test_fits_the_redundant_design_on_the_space_it_spans():
    # statsmodels' fit of the redundant A×B design itself stops thousands of log-likelihood units below the
    # additive fit on such tables, which clipped the statistic to 0 (p = 1).
    k, n, additive, full, (context, a, b) = factorial_tables(np.random.default_rng(13), (4, 6, 3), 0.6, 0.1)
    expected = 2 * (design_llf(k, n, full) - design_llf(k, n, additive))
    for row, statistic in zip(k[:6], expected[:6]):
        test, _ = interaction_lrt(row, n, a, b, context, 20, np.random.default_rng(0))
        assert statistic > 5 and test.statistic == pytest.approx(statistic, abs=1e-6)
        assert test.df == np.linalg.matrix_rank(full) - np.linalg.matrix_rank(additive)
