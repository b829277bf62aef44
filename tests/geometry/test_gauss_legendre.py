"""The written-out Gauss-Legendre tables are numpy's and integrate what they must exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.geometry import gauss_legendre as gl


@pytest.mark.parametrize("order,x,w", [(10, gl.X10, gl.W10), (64, gl.X64, gl.W64)])
def test_the_tables_are_leggauss_to_an_ulp_or_two(order: int, x: np.ndarray, w: np.ndarray) -> None:
    # numpy solves an eigenvalue problem for them: another machine's LAPACK may differ by an
    # ulp, which is why they are written out (every machine plans with the same numbers).
    want_x, want_w = np.polynomial.legendre.leggauss(order)
    np.testing.assert_array_max_ulp(x, want_x, maxulp=4)
    np.testing.assert_array_max_ulp(w, want_w, maxulp=4)


@pytest.mark.parametrize("order,x,w", [(10, gl.X10, gl.W10), (64, gl.X64, gl.W64)])
def test_they_integrate_polynomials_up_to_degree_2n_minus_1(order: int, x: np.ndarray,
                                                            w: np.ndarray) -> None:
    assert len(x) == len(w) == order and np.all(np.diff(x) > 0.0)
    for k in range(2 * order):
        exact = 0.0 if k % 2 else 2.0 / (k + 1)
        assert math.isclose(float(w @ x**k), exact, rel_tol=1e-12, abs_tol=1e-13), k


def test_they_cannot_be_written() -> None:
    with pytest.raises(ValueError):
        gl.X10[0] = 0.0
