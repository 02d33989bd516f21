# SPDX-License-Identifier: Apache-2.0
"""Issue 23's other alternative to LAPACK's `dgeev` vectors, for `bench_model.py --profile`:
the eigenvalues of the balanced Hessenberg form (`dgebal`, `dgehrd`, `dhseqr` without Schur
vectors), then only the selected modes' right vectors by LAPACK's selective inverse iteration
on that form (`dhsein`), back-transformed (`dormhr`, `dgebak`). scipy wraps none of `dhseqr`,
`dhsein`, `dormhr`, `dgebak` for Python, so they are called through the function pointers that
`scipy.linalg.cython_lapack` exports (the same LAPACK as `scipy.linalg.lapack`), with ctypes.
"""

from __future__ import annotations

import ctypes

import numpy as np
import scipy.linalg.cython_lapack as cython_lapack

_api = ctypes.pythonapi
_api.PyCapsule_GetName.restype = ctypes.c_char_p
_api.PyCapsule_GetName.argtypes = [ctypes.py_object]
_api.PyCapsule_GetPointer.restype = ctypes.c_void_p
_api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]


def _routine(name: str, nargs: int):
    """LAPACK routine `name` (all arguments by reference) from scipy's cython_lapack."""
    capsule = cython_lapack.__pyx_capi__[name]
    address = _api.PyCapsule_GetPointer(capsule, _api.PyCapsule_GetName(capsule))
    return ctypes.CFUNCTYPE(None, *([ctypes.c_void_p] * nargs))(address)


_GEBAL, _GEHRD = _routine("dgebal", 8), _routine("dgehrd", 9)
_HSEQR, _HSEIN = _routine("dhseqr", 14), _routine("dhsein", 19)
_ORMHR, _GEBAK = _routine("dormhr", 14), _routine("dgebak", 10)


class SelectiveSolver:
    """Eigenvalues and the oscillatory modes' right vectors of (size x size) matrices, the
    workspaces allocated once."""

    def __init__(self, size: int):
        n = self.n = size
        self.scale, self.tau = np.zeros(n), np.zeros(n)
        self.wr, self.wi = np.zeros(n), np.zeros(n)
        self.work, self.hwork = np.zeros(64 * n), np.zeros((n + 4) * n)
        self.h, self.vr = np.zeros((n, n), order="F"), np.zeros((n, n), order="F")
        self.select, self.ifail = np.zeros(n, np.int32), np.zeros(2 * n, np.int32)
        self._int = {k: ctypes.c_int(0) for k in ("n", "ilo", "ihi", "info", "lwork", "m", "mm")}
        self._int["n"].value, self._int["lwork"].value = n, 64 * n
        self._one = ctypes.c_int(1)
        self.unconverged = 0  # of the last solve

    def solve(self, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(all eigenvalues, indices of the oscillatory ones (Im > 0), their right vectors
        packed as LAPACK packs them: real and imaginary parts in adjacent columns).
        `unconverged` is then the number of vectors (columns) that `dhsein`'s convergence
        test did not accept: it returns the last iterate for them."""
        r, i, ch = ctypes.byref, self._int, ctypes.c_char_p
        n, ilo, ihi, info, lwork = (r(i[k]) for k in ("n", "ilo", "ihi", "info", "lwork"))
        one, m, mm = r(self._one), r(i["m"]), r(i["mm"])
        a = np.array(a, order="F")
        work, wr, wi = self.work.ctypes.data, self.wr.ctypes.data, self.wi.ctypes.data

        def call(routine, *args) -> None:
            routine(*args)
            if i["info"].value < 0 or i["info"].value > 0 and routine is not _HSEIN:
                raise np.linalg.LinAlgError(f"LAPACK info {i['info'].value}")

        call(_GEBAL, ch(b"B"), n, a.ctypes.data, n, ilo, ihi, self.scale.ctypes.data, info)
        call(_GEHRD, n, ilo, ihi, a.ctypes.data, n, self.tau.ctypes.data, work, lwork, info)
        h = np.asfortranarray(np.triu(a, -1))  # the Hessenberg form (self.h: dhseqr's copy)
        self.h[...] = h
        call(_HSEQR, ch(b"E"), ch(b"N"), n, ilo, ihi, self.h.ctypes.data, n, wr, wi, work, one,
             work, lwork, info)  # fmt: skip
        osc = np.flatnonzero(self.wi > 0)
        self.select[:] = self.wi > 0
        i["mm"].value = 2 * len(osc)
        call(_HSEIN, ch(b"R"), ch(b"Q"), ch(b"N"), self.select.ctypes.data, n, h.ctypes.data, n,
             wr, wi, work, one, self.vr.ctypes.data, n, mm, m, self.hwork.ctypes.data,
             self.ifail.ctypes.data, self.ifail[self.n :].ctypes.data, info)  # fmt: skip
        self.unconverged = i["info"].value  # vectors dhsein's own test did not accept
        call(_ORMHR, ch(b"L"), ch(b"N"), n, m, ilo, ihi, a.ctypes.data, n, self.tau.ctypes.data,
             self.vr.ctypes.data, n, work, lwork, info)  # fmt: skip
        call(_GEBAK, ch(b"B"), ch(b"R"), n, ilo, ihi, self.scale.ctypes.data, m,
             self.vr.ctypes.data, n, info)  # fmt: skip
        return self.wr + 1j * self.wi, osc, self.vr[:, : i["m"].value].copy()
