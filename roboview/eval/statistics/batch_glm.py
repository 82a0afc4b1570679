"""The split test's likelihood-ratio statistic for many tables at once.

A split's test is the binomial GLM `value + context` against `context` (`significance.factor_lrt`). Calibrating a
sequential design on its own look sequence means that statistic for thousands of simulated tables per look, where
one statsmodels fit per table would take minutes. The tables of a split share their layout (a value × context
grid), so Newton's method runs on all of them together, and the two-way structure makes each step cheap: the value
block of the Hessian is diagonal, so a step solves only the contexts' Schur complement (η_vc = a_v + b_c,
b_0 = 0). The context-only fit has a closed form (each context's success rate).

Contexts with only successes or only failures carry no information about the value and are left out, as
`factor_lrt` leaves them out: their cells get weight zero. A value that never fails (or never succeeds) sends
its coefficient to ±∞ and fits its cells exactly: it adds nothing to the maximised log-likelihood and is left out
of the fit; the statistic is the limit statsmodels' iterations approach. `tests/eval/statistics/test_batch_glm.py` checks the statistic against `factor_lrt`'s.

`design_llf` is the same idea for any one design (the factorial split's A + B and A×B fits, each parametric-bootstrap
table a row): iteratively reweighted least squares on all tables together, from statsmodels' start, on the columns
that span the design (QR with pivoting: missing combinations make dummies dependent, and the fit depends only on
their span).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.linalg
from scipy.special import xlogy

ITERATIONS = 60  # Newton steps at most (a table typically needs 4–8)
RIDGE = 1e-9  # keeps the Hessian of a drifting (separated) coefficient invertible
MAX_STEP = 5.0  # per coefficient and step: a near-singular Hessian cannot throw a fit far off
CHUNK = 1024  # tables per Newton solve
HALVINGS = 30  # step halvings at most per Newton step


def _own_rate_llf(k: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Σ k log(k/n) + (n − k) log(1 − k/n) over the last axis: the log-likelihood of cells at their own rate."""
    p = k / np.where(n > 0, n, 1)
    return (xlogy(k, p) + xlogy(n - k, 1 - p)).sum(axis=-1)


def _softplus(eta: np.ndarray) -> np.ndarray:
    """log(1 + e^η), stably (np.logaddexp(0, η)'s value, at a fifth of its cost here)."""
    return np.maximum(eta, 0.0) + np.log1p(np.exp(-np.abs(eta)))


def _expit(eta: np.ndarray) -> np.ndarray:
    """1 / (1 + e^−η), stably (scipy.special.expit's value, at a third of its cost here)."""
    e = np.exp(-np.abs(eta))
    return np.where(eta >= 0, 1.0, e) / (1.0 + e)


def _loglik(k: np.ndarray, n: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Σ k η − n log(1 + e^η) per table (the first axis): the binomial log-likelihood without Σ log C(n, k)."""
    terms = k * eta - n * _softplus(eta)
    return np.einsum("tc->t", terms.reshape(len(terms), -1))


def _llf(k: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return _loglik(k, n, a[:, :, None] + b[:, None, :])


def _newton_direction(
    k: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton's direction for the additive fit η = a_v + b_c (b_0 = 0) on grids (tables, values, contexts), and
    each table's largest score component (0 at its maximum)."""
    mu = _expit(a[:, :, None] + b[:, None, :])
    w = n * mu * (1 - mu)
    r = k - n * mu
    # Sums over one axis as einsum: numpy's reduce over a short axis is 4–5× slower here.
    ga, gb = np.einsum("tvc->tv", r), np.einsum("tvc->tc", r)[:, 1:]
    wv = np.einsum("tvc->tv", w) + RIDGE
    x = w[:, :, 1:]
    xt = x.transpose(0, 2, 1)
    schur = -(xt @ (x / wv[:, :, None]))
    idx = np.arange(x.shape[2])
    schur[:, idx, idx] += np.einsum("tvc->tc", w)[:, 1:] + RIDGE
    rhs = gb - (xt @ (ga / wv)[:, :, None])[..., 0]
    db = np.linalg.solve(schur, rhs[..., None])[..., 0] if x.shape[2] else np.zeros_like(gb)
    da = (ga - (x @ db[:, :, None])[..., 0]) / wv
    return (
        np.clip(da, -MAX_STEP, MAX_STEP),
        np.clip(db, -MAX_STEP, MAX_STEP),
        np.maximum(np.abs(ga).max(axis=1, initial=0), np.abs(gb).max(axis=1, initial=0)),
    )


def _fit(k: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Maximised log-likelihood of the additive fit from (a, b): Newton steps, each halved for a table until its
    log-likelihood does not fall (Newton alone can oscillate on a logistic likelihood from a poor start). A table
    leaves the iteration once its score vanishes, so the slowest tables do not hold the rest."""
    current = _llf(k, n, a, b)
    live = np.arange(len(k))
    for _ in range(ITERATIONS):
        kl, nl, al, bl = k[live], n[live], a[live], b[live]
        da, db, score = _newton_direction(kl, nl, al, bl)
        moving = score >= 1e-9
        if not moving.any():
            break
        live, kl, nl, al, bl = live[moving], kl[moving], nl[moving], al[moving], bl[moving]
        da, db, now = da[moving], db[moving], current[live]
        scale, trial = _halved(now, _additive_at, kl, nl, al, bl, da, db)
        a[live] = al + scale[:, None] * da
        b[live, 1:] = bl[:, 1:] + scale[:, None] * db
        current[live] = trial
    return current


def _additive_at(scale, k, n, a, b, da, db) -> np.ndarray:
    return _llf(k, n, a + scale[:, None] * da, b + scale[:, None] * np.pad(db, ((0, 0), (1, 0))))


def _halved(
    now: np.ndarray, loglik: Callable[..., np.ndarray], *args: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per-table step scales, halved until the log-likelihood `loglik(scale, *args)` does not fall below `now` (0
    for a table still worse after HALVINGS: it keeps its coefficients), and the log-likelihoods there."""
    scale = np.ones(len(now))
    for _ in range(HALVINGS):
        trial = loglik(scale, *args)
        worse = trial < now - 1e-12 * np.abs(now)
        if not worse.any():
            return scale, trial
        scale[worse] /= 2
    scale[worse] = 0.0
    return scale, np.where(worse, now, trial)


def _grid_lrt(k: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The statistic for grids (tables, values, contexts) of successes k in n episodes."""
    ks, ns = k.sum(axis=1), n.sum(axis=1)
    informative = (ks > 0) & (ks < ns)
    n = np.where(informative[:, None, :], n, 0.0)
    k = np.where(informative[:, None, :], k, 0.0)
    # A value that always succeeds (or always fails) in the informative contexts fits its cells exactly at
    # a_v = ±∞: they add nothing to the maximised log-likelihood, and leaving them out spares the slow drift.
    kv, nv = k.sum(axis=2), n.sum(axis=2)
    separated = ((kv == 0) | (kv == nv))[:, :, None]
    n_fit, k_fit = np.where(separated, 0.0, n), np.where(separated, 0.0, k)
    rate = np.clip(np.where(ns > 0, ks / np.where(ns > 0, ns, 1), 0.5), 1e-3, 1 - 1e-3)
    b = np.log(rate / (1 - rate))
    a = np.repeat(b[:, :1], k.shape[1], axis=1)
    full = _fit(k_fit, n_fit, a, b - b[:, :1])
    reduced = _own_rate_llf(ks, ns)  # the context-only fit (an uninformative context adds 0)
    return np.where(informative.any(axis=1), np.maximum(0.0, 2 * (full - reduced)), 0.0)


def value_lrt(k: np.ndarray, n: np.ndarray, value: np.ndarray, context: np.ndarray) -> np.ndarray:
    """2 (ℓ(value + context) − ℓ(context)) for each row of `k` (tables × cells), clipped at 0.

    Cells are distinct (value, context) pairs with codes 0..V−1 and 0..C−1; `n`: episodes per cell, shape
    (cells,) or like `k`. 0 for a table with no informative context.
    """
    k = np.atleast_2d(np.asarray(k, float))
    n = np.broadcast_to(np.asarray(n, float), k.shape)
    n_values, n_contexts = int(value.max()) + 1, int(context.max()) + 1
    flat = value * n_contexts + context
    if len(np.unique(flat)) != len(flat):
        raise ValueError("value_lrt needs one cell per (value, context) pair")
    out = np.empty(len(k))
    for lo in range(0, len(k), CHUNK):
        kg = np.zeros((min(CHUNK, len(k) - lo), n_values * n_contexts))
        ng = np.zeros_like(kg)
        kg[:, flat], ng[:, flat] = k[lo : lo + CHUNK], n[lo : lo + CHUNK]
        shape = (len(kg), n_values, n_contexts)
        out[lo : lo + CHUNK] = _grid_lrt(kg.reshape(shape), ng.reshape(shape))
    return out


def spanning_columns(exog: np.ndarray) -> np.ndarray:
    """The columns of `exog` that span its column space, in their order (scipy's QR with column pivoting)."""
    _, r, pivot = scipy.linalg.qr(exog, mode="economic", pivoting=True)
    diag = np.abs(np.diag(r))
    rank = int(np.sum(diag > diag[0] * max(exog.shape) * np.finfo(float).eps)) if len(diag) else 0
    return exog[:, np.sort(pivot[:rank])]


def design_llf(k: np.ndarray, n: np.ndarray, exog: np.ndarray) -> np.ndarray:
    """Maximised log-likelihood of the binomial GLM (logit link) with design `exog` (cells × columns) for each row
    of `k` (tables × cells; `n` episodes per cell, shape (cells,) or like `k`), without the Σ log C(n, k) term
    (statsmodels' llf includes it; a likelihood ratio cancels it). A separated table's coefficients drift towards
    ±∞ and its log-likelihood to its supremum, as statsmodels' iterations do."""
    k = np.atleast_2d(np.asarray(k, float))
    n = np.broadcast_to(np.asarray(n, float), k.shape)
    x = spanning_columns(np.asarray(exog, float))
    out = np.empty(len(k))
    for lo in range(0, len(k), CHUNK):
        out[lo : lo + CHUNK] = _irls(k[lo : lo + CHUNK], n[lo : lo + CHUNK], x)
    return out


def _design_direction(
    k: np.ndarray, n: np.ndarray, x: np.ndarray, beta: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Newton's step for coefficients `beta` (tables × columns), at most MAX_STEP in any coefficient (scaled, so it
    keeps its direction), and each table's largest score component."""
    mu = _expit(beta @ x.T)
    w = n * mu * (1 - mu)
    score = (k - n * mu) @ x
    hessian = (x.T[None] * w[:, None, :]) @ x
    idx = np.arange(x.shape[1])
    hessian[:, idx, idx] += RIDGE
    step = np.linalg.solve(hessian, score[..., None])[..., 0]
    step *= np.minimum(1.0, MAX_STEP / np.maximum(np.abs(step).max(axis=1), 1e-300))[:, None]
    return step, np.abs(score).max(axis=1)


def _design_at(scale, k, n, x, beta, step) -> np.ndarray:
    return _loglik(k, n, (beta + scale[:, None] * step) @ x.T)


def _irls(k: np.ndarray, n: np.ndarray, x: np.ndarray) -> np.ndarray:
    """`design_llf` for one chunk: statsmodels' start (the weighted least-squares fit of logit((k + ½) / (n + 1))),
    then Newton steps, halved for a table until its log-likelihood does not fall; a table leaves once its score
    vanishes."""
    mu = (k + 0.5) / (n + 1)
    xw = x.T[None] * (n * mu * (1 - mu))[:, None, :]
    idx = np.arange(x.shape[1])
    gram = xw @ x
    gram[:, idx, idx] += RIDGE
    beta = np.linalg.solve(gram, (xw @ np.log(mu / (1 - mu))[..., None]))[..., 0]
    current = _loglik(k, n, beta @ x.T)
    live = np.arange(len(k))
    for _ in range(ITERATIONS):
        kl, nl, bl = k[live], n[live], beta[live]
        step, score = _design_direction(kl, nl, x, bl)
        moving = score >= 1e-9
        if not moving.any():
            break
        live, kl, nl, bl, step = live[moving], kl[moving], nl[moving], bl[moving], step[moving]
        scale, trial = _halved(current[live], _design_at, kl, nl, x, bl, step)
        beta[live] = bl + scale[:, None] * step
        current[live] = trial
    return current
