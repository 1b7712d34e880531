"""The batched Cholesky solves of the basis step (facebasis.rigging.spdsolve)."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from facebasis.errors import InputError, SolverError
from facebasis.rigging import spdsolve
from facebasis.rigging.spdsolve import posv_rows


def _systems(n=40, k=7, r=3, seed=0):
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((n, k, k))
    A = M @ M.transpose(0, 2, 1) + k * np.eye(k)
    B = rng.standard_normal((n, r, k))
    return A, B


@pytest.mark.parametrize("use_kernel", [True, False])
def test_posv_rows_solves_every_system(use_kernel):
    A, B = _systems()
    Y = B.copy()
    posv_rows(A.copy(), Y, use_kernel=use_kernel)
    expected = np.linalg.solve(A, B.transpose(0, 2, 1)).transpose(0, 2, 1)
    np.testing.assert_allclose(Y, expected, rtol=1e-12, atol=1e-12)


def test_kernel_and_scipy_wrapper_agree_bitwise_and_factors_are_cholesky():
    if spdsolve.kernel() is None:
        pytest.skip("this SciPy build publishes no dposv pointer")
    A, B = _systems(n=25, k=11, r=6, seed=1)
    A1, Y1, A2, Y2 = A.copy(), B.copy(), A.copy(), B.copy()
    posv_rows(A1, Y1)
    posv_rows(A2, Y2, use_kernel=False)
    np.testing.assert_array_equal(Y1, Y2)
    # LAPACK's column-major lower triangle is the row-major upper one: U^T U = A
    U = np.triu(A1)
    np.testing.assert_allclose(U.transpose(0, 2, 1) @ U, A, rtol=1e-12, atol=1e-10)


def test_posv_rows_on_threads_equals_serial():
    A, B = _systems(n=64, k=9, r=6, seed=2)
    Y_serial = B.copy()
    posv_rows(A.copy(), Y_serial)
    A2, Y2 = A.copy(), B.copy()
    with ThreadPoolExecutor(2) as pool:
        list(pool.map(lambda s: posv_rows(A2[s], Y2[s]), [slice(0, 30), slice(30, 64)]))
    np.testing.assert_array_equal(Y2, Y_serial)


@pytest.mark.parametrize("use_kernel", [True, False])
def test_not_positive_definite_names_the_system_and_lapack_info(use_kernel):
    A, B = _systems(n=5, k=4)
    A[3] = -np.eye(4)  # leading minor of order 1 is negative
    with pytest.raises(SolverError, match=r"system 3 of 5: not positive definite \(LAPACK dposv info 1\)") as err:
        posv_rows(A, B, use_kernel=use_kernel)
    assert err.value.status == "1"


def test_bad_layouts_are_rejected_before_any_call():
    A, B = _systems(n=4, k=5, r=2)
    with pytest.raises(InputError, match=r"A: expected a writeable C-contiguous float64 array \(n, k, k\), found"):
        posv_rows(np.asfortranarray(A), B)
    with pytest.raises(InputError, match=r"A: expected .*found ndarray float32"):
        posv_rows(A.astype(np.float32), B)
    with pytest.raises(InputError, match=r"B: expected a writeable C-contiguous float64 array \(4, r, 5\), found"):
        posv_rows(A, B[:, :, :4].copy())
    with pytest.raises(InputError, match=r"B: expected .*found ndarray float64 \(4, 5, 2\)"):
        posv_rows(A, B.transpose(0, 2, 1))
    ro = B.copy()
    ro.flags.writeable = False
    with pytest.raises(InputError, match="B: expected a writeable"):
        posv_rows(A, ro)


def test_only_the_expected_dposv_signature_is_called_through_ctypes():
    sig = spdsolve._DPOSV_SIGNATURE
    d = "__pyx_t_5scipy_6linalg_13cython_lapack_d"
    assert sig.fullmatch(f"void (char *, int *, int *, {d} *, int *, {d} *, int *, int *)")
    assert sig.fullmatch("void (char *, int *, int *, double *, int *, double *, int *, int *)")
    # single precision, a missing argument, another return type: not the ABI the call assumes
    assert not sig.fullmatch("void (char *, int *, int *, __pyx_t_5scipy_6linalg_13cython_lapack_s *, int *, "
                             "__pyx_t_5scipy_6linalg_13cython_lapack_s *, int *, int *)")
    assert not sig.fullmatch(f"void (char *, int *, int *, {d} *, int *, {d} *, int *)")
    assert not sig.fullmatch(f"int (char *, int *, int *, {d} *, int *, {d} *, int *, int *)")


@pytest.mark.parametrize("use_kernel", [True, False])
def test_empty_systems_are_a_no_op_and_aliasing_is_refused(use_kernel):
    A, B = _systems(n=3, k=4, r=2)
    posv_rows(np.empty((0, 4, 4)), np.empty((0, 2, 4)), use_kernel=use_kernel)
    posv_rows(np.empty((3, 0, 0)), np.empty((3, 2, 0)), use_kernel=use_kernel)
    posv_rows(A.copy(), np.empty((3, 0, 4)), use_kernel=use_kernel)
    with pytest.raises(InputError, match="B: expected an array apart from A, found one sharing its memory"):
        posv_rows(A, A, use_kernel=use_kernel)


def test_basis_rows_accepts_any_layout_of_its_inputs():
    """A non-contiguous prior (a transposed view) gives the same blendshape frames as a C-ordered one."""
    from facebasis.rigging.basis import basis_rows

    rng = np.random.default_rng(3)
    k, m, t = 6, 8, 40  # m >= 0.6 k: the direct Cholesky path
    X = rng.uniform(0, 1, (k, m))
    RT = rng.standard_normal((t, 6, m))
    A_km = rng.standard_normal((k, 6, t))
    w = rng.uniform(1, 10, (t, k))
    ref, ef, er = basis_rows(X, RT, np.ascontiguousarray(A_km.transpose(2, 1, 0)), w, 0.3)
    out, ef2, er2 = basis_rows(X, RT, A_km.transpose(2, 1, 0), w, 0.3)
    np.testing.assert_array_equal(out, ref)
    assert (ef2, er2) == (ef, er)


def test_basis_rows_writes_into_a_given_buffer_and_checks_it():
    from facebasis.rigging.basis import basis_rows

    rng = np.random.default_rng(4)
    k, m, t = 5, 6, 30
    args = (rng.uniform(0, 1, (k, m)), rng.standard_normal((t, 6, m)), rng.standard_normal((t, 6, k)),
            rng.uniform(1, 10, (t, k)), 0.2)
    ref, ef, er = basis_rows(*args)
    buf = np.full((2, t, 3, k), np.nan)
    out, ef2, er2 = basis_rows(*args, out=buf)
    assert out is buf and (ef2, er2) == (ef, er)
    np.testing.assert_array_equal(buf, ref)
    with pytest.raises(InputError, match=r"basis_rows: out: expected a C-contiguous float64 array of shape "
                                         r"\(2, 30, 3, 5\), found float32 \(2, 30, 3, 5\)"):
        basis_rows(*args, out=buf.astype(np.float32))
