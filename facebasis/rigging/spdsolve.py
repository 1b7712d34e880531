"""Many small symmetric positive definite solves, one LAPACK ``dposv`` each, with the GIL released.

The basis step (:mod:`facebasis.rigging.basis`) solves one k x k system per triangle (28,068 on
ICT, k = 53). NumPy has no batched Cholesky solve (``np.linalg.solve`` is LU: twice the flops),
and SciPy's ``scipy.linalg.lapack.dposv`` keeps the GIL for the whole call, so worker threads
gain almost nothing from it. SciPy also publishes its LAPACK as
C function pointers for compiled code (``scipy.linalg.cython_lapack``, the table NumBa uses);
calling that pointer through :mod:`ctypes` releases the GIL for the solve itself, so blocks of
triangles on two threads run in parallel (``python -m problems.bench basis`` measures one whole
basis step both ways).

When the pointer is not available (another SciPy build) :func:`posv_rows` falls back to SciPy's
wrapper: same LAPACK routine, same answers, serial speed.
"""

from __future__ import annotations

import ctypes
import re

import numpy as np

from ..errors import InputError, SolverError

#: the C signature scipy.linalg.cython_lapack declares for dposv (the ABI the ctypes call assumes;
#: its double type is Cython's mangled name for ``d``, e.g. ``__pyx_t_5scipy_6linalg_13cython_lapack_d``)
_DPOSV_SIGNATURE = re.compile(r"void \(char \*, int \*, int \*, (?P<d>(\w+_d|double)) \*, int \*, "
                              r"(?P=d) \*, int \*, int \*\)")

_KERNEL: list = []  # [ctypes function or None], filled once


def _cython_dposv():
    """ctypes function of scipy.linalg.cython_lapack's dposv, or None where it is not published."""
    try:
        from scipy.linalg import cython_lapack

        capsule = cython_lapack.__pyx_capi__["dposv"]
        get_name = ctypes.PYFUNCTYPE(ctypes.c_char_p, ctypes.py_object)(("PyCapsule_GetName", ctypes.pythonapi))
        get_pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_char_p)(
            ("PyCapsule_GetPointer", ctypes.pythonapi))
        name = get_name(capsule)
        if name is None or not _DPOSV_SIGNATURE.fullmatch(name.decode()):
            return None
        pointer = get_pointer(capsule, name)
    except (ImportError, AttributeError, KeyError, ValueError, TypeError):  # pragma: no cover - other SciPy builds
        return None
    if not pointer:  # pragma: no cover
        return None
    return ctypes.CFUNCTYPE(None)(pointer)  # arguments passed as ctypes objects; the GIL is released per call


def kernel():
    """The GIL-free ``dposv`` (a ctypes function) or None; looked up once."""
    if not _KERNEL:
        _KERNEL.append(_cython_dposv())
    return _KERNEL[0]


def _check(A, B):
    if (not isinstance(A, np.ndarray) or A.dtype != np.float64 or A.ndim != 3 or A.shape[1] != A.shape[2]
            or not A.flags.c_contiguous or not A.flags.writeable):
        found = f"{type(A).__name__} {getattr(A, 'dtype', '')} {getattr(A, 'shape', '')}"
        raise InputError(f"posv_rows: A: expected a writeable C-contiguous float64 array (n, k, k), found {found}")
    n, k = A.shape[:2]
    if (not isinstance(B, np.ndarray) or B.dtype != np.float64 or B.ndim != 3 or B.shape[0] != n or B.shape[2] != k
            or not B.flags.c_contiguous or not B.flags.writeable):
        found = f"{type(B).__name__} {getattr(B, 'dtype', '')} {getattr(B, 'shape', '')}"
        raise InputError(f"posv_rows: B: expected a writeable C-contiguous float64 array ({n}, r, {k}), found {found}")


def _failure(t: int, n: int, info: int) -> str:
    what = ("not positive definite" if info > 0 else f"argument {-info} illegal")
    return f"Cholesky solve failed on system {t} of {n}: {what} (LAPACK dposv info {info})"


def posv_rows(A: np.ndarray, B: np.ndarray, *, use_kernel: bool = True) -> None:
    """Solve ``A_t Y_t^T = B_t^T`` for every t in place (Cholesky, LAPACK ``dposv``).

    Parameters
    ----------
    A : (n, k, k) float64, C-contiguous: symmetric positive definite matrices; overwritten by
        their Cholesky factors
    B : (n, r, k) float64, C-contiguous: the r right-hand sides of system t as rows; overwritten
        by the solutions (row-major (r, k) is LAPACK's column-major (k, r))
    use_kernel : use the GIL-free pointer when available (False: SciPy's wrapper, for tests)

    Raises
    ------
    SolverError
        a matrix that is not positive definite, with LAPACK's ``info`` (the order of the leading
        minor that is not positive) and the index of the system.
    InputError
        arrays of another type, shape or layout, or B sharing memory with A (before any solve).
    """
    _check(A, B)
    n, k = A.shape[:2]
    r = B.shape[1]
    if n == 0 or k == 0 or r == 0:
        return
    if np.may_share_memory(A, B):
        raise InputError("posv_rows: B: expected an array apart from A, found one sharing its memory")
    f = kernel() if use_kernel else None
    if f is None:
        from scipy.linalg import lapack

        for t in range(n):  # one LAPACK call per system; A symmetric, so its transpose is itself
            _, _, info = lapack.dposv(A[t].T, B[t].T, lower=1, overwrite_a=1, overwrite_b=1)
            if info != 0:
                raise SolverError(_failure(t, n, info), str(info))
        return
    order, nrhs, info = ctypes.c_int(k), ctypes.c_int(r), ctypes.c_int(0)
    p_order, p_nrhs, p_info = ctypes.byref(order), ctypes.byref(nrhs), ctypes.byref(info)
    uplo = ctypes.c_char_p(b"L")
    a0, b0 = A.ctypes.data, B.ctypes.data
    sa, sb = A.strides[0], B.strides[0]
    c_void_p = ctypes.c_void_p
    for t in range(n):  # one LAPACK call per system, without the GIL
        f(uplo, p_order, p_nrhs, c_void_p(a0 + t * sa), p_order, c_void_p(b0 + t * sb), p_order, p_info)
        if info.value != 0:
            raise SolverError(_failure(t, n, info.value), str(info.value))
