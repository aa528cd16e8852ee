"""LM with a sparse Jacobian (the multiple-shooting residual's): the same iterates as with the dense one.

Oracle: the dense run of the same problem (NIST Misra1a, with a block-diagonal copy so that the sparse matrix
has structural zeros), in both damping schemes and with bounds; a sparse Jacobian with a non-finite entry is
rejected like a dense one."""

from __future__ import annotations

import nist_misra1a as misra
import numpy as np
import pytest
from scipy import sparse

from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt


def _twice(c):
    """Misra1a twice, the second copy in its own two quantities: J is block diagonal."""
    e1, j1 = misra.fun(c[:2])
    e2, j2 = misra.fun(c[2:] * [1.0, 0.5])
    return np.concatenate([e1, e2]), np.block([[j1, np.zeros_like(j2)], [np.zeros_like(j1), j2 * [1.0, 0.5]]])


def _sparse(c):
    e, j = _twice(c)
    return e, sparse.csr_matrix(j)


START = np.concatenate([misra.START_1, misra.START_1 * [1.0, 2.0]])


@pytest.mark.parametrize("options", [LMOptions(max_iter=500), LMOptions(max_iter=500, scale="jac", tau=1e-3),
                                     LMOptions(max_iter=500, scale="jac", tau=1e-3, scale_groups=(0, 1, 0, 1))])
@pytest.mark.parametrize("lower", [None, np.zeros(4)])
def test_sparse_jacobian_gives_the_dense_iterates(options, lower):
    names = ["a1", "b1", "a2", "b2"]
    dense = levenberg_marquardt(_twice, START, names, lower, None, options)
    thin = levenberg_marquardt(_sparse, START, names, lower, None, options)
    # the products are summed in another order: the paths agree to rounding until the last steps, which
    # move at rounding level and may end one or two iterations apart
    assert thin.converged and dense.converged and abs(thin.iterations - dense.iterations) <= 3
    np.testing.assert_allclose(thin.cost_history[:12], dense.cost_history[:12], rtol=1e-8)
    np.testing.assert_allclose(thin.x, dense.x, rtol=1e-8)
    assert sparse.issparse(thin.jac)
    np.testing.assert_allclose(thin.jac.toarray(), dense.jac, rtol=1e-6)
    # and the fit is right: both copies reach NIST's certified values
    np.testing.assert_allclose(thin.x[:2], misra.CERTIFIED, rtol=1e-6)
    np.testing.assert_allclose(thin.x[2:] * [1.0, 0.5], misra.CERTIFIED, rtol=1e-6)


def test_a_sparse_jacobian_with_nan_is_a_divergence():
    def fun(c):
        e, j = _sparse(c)
        j.data[0] = np.nan
        return e, j
    r = levenberg_marquardt(fun, START, ["a1", "b1", "a2", "b2"], options=LMOptions(max_iter=5))
    assert r.status == "diverged_at_start"


@pytest.mark.parametrize("order", ["wide first", "shuffled"])
def test_the_gram_of_a_partly_wide_sparse_jacobian_is_numpys(order):
    """fit.steps.gram splits a CSR Jacobian into its wide columns (nonzero in most rows: a multiple-shooting fit's
    parameters) and the rest (one short block per segment's free start); oracle: numpy's JᵀJ of the dense
    matrix, with the wide columns first (slices) or scattered among the others (index lists)."""
    from flowchart2sdnn.fit.steps import gram

    rng = np.random.default_rng(4)
    rows, wide, blocks = 600, 3, 20
    dense = np.zeros((rows, wide + blocks))
    dense[:, :wide] = rng.normal(size=(rows, wide))
    for b in range(blocks):  # block b's rows only see its own column (and the wide ones)
        dense[b * 30:(b + 1) * 30, wide + b] = rng.normal(size=30)
    if order == "shuffled":
        dense = dense[:, rng.permutation(dense.shape[1])]
    np.testing.assert_allclose(gram(sparse.csr_matrix(dense)), dense.T @ dense, rtol=1e-12, atol=1e-12)


def test_a_wide_first_csr_gives_the_gram_of_its_blocks():
    """A WideFirstCSR hands its first columns over dense and the rest as CSR (a multiple-shooting Jacobian:
    theta's columns in every row); fit.steps.gram builds JᵀJ from them. Oracle: numpy's JᵀJ of the dense matrix;
    blocks of the wrong shape are not used (the matrix's own columns are)."""
    from flowchart2sdnn.fit.steps import WideFirstCSR, gram

    rng = np.random.default_rng(5)
    rows, wide, blocks = 400, 3, 16
    dense = np.zeros((rows, wide + blocks))
    dense[:, :wide] = rng.normal(size=(rows, wide))
    for b in range(blocks):
        dense[b * 25:(b + 1) * 25, wide + b] = rng.normal(size=25)
    J = WideFirstCSR(dense)
    J.wide, J.rest = dense[:, :wide].copy(), sparse.csr_matrix(dense[:, wide:])
    np.testing.assert_allclose(gram(J), dense.T @ dense, rtol=1e-12, atol=1e-12)
    # the blocks are what the products see: a changed block changes JᵀJ (they are not recomputed from J)
    J.wide = 2.0 * dense[:, :wide]
    assert not np.allclose(gram(J)[:wide, :wide], dense[:, :wide].T @ dense[:, :wide])
    J.wide = dense[:, :wide + 1].copy()  # a block of the wrong shape: J's own columns instead
    np.testing.assert_allclose(gram(J), dense.T @ dense, rtol=1e-12, atol=1e-12)
