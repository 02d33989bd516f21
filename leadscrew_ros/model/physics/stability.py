# SPDX-License-Identifier: Apache-2.0
"""Eigen-analysis of (27): squeak (flutter) modes, divergence, labels (README
"Sign conventions, validity, risk")."""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from scipy.linalg import lapack

# Relative thresholds against round-off of a 2N eigenproblem whose eigenvalues reach ~1e5 1/s.
_IMAG_TOL = 1e-9
GROWTH_TOL = 1e-10


class ModeResult(NamedTuple):
    """One oscillatory eigenpair (a NamedTuple: built per mode on the live path, so cheap).

    Attributes
    ----------
    label : str
        Dominant modal coordinate, e.g. 'B1y'.
    frequency_hz : float
        Frequency |Im(lambda)| / 2 pi [Hz].
    growth_rate : float
        Re(lambda) [1/s]; > 0 grows (squeak).
    damping_ratio : float
        -Re(lambda) / |lambda| (dimensionless); < 0 when unstable.
    unstable : bool
        Squeak: Re(lambda) > 0 with Im(lambda) != 0.
    """

    label: str  # dominant modal coordinate, e.g. "B1y"
    frequency_hz: float  # |Im(lambda)| / 2 pi
    growth_rate: float  # Re(lambda), 1/s
    damping_ratio: float  # -Re(lambda) / |lambda|
    unstable: bool  # squeak: Re > 0 with Im != 0

    def as_dict(self) -> dict:
        """The fields as a dict.

        Returns
        -------
        dict
            Field name to value, units as in Attributes.
        """
        return self._asdict()


class Eigen(NamedTuple):
    """An eigen-solve of the state matrix with the vectors of its oscillatory modes.

    Attributes
    ----------
    lam : numpy.ndarray
        All eigenvalues [1/s].
    osc : numpy.ndarray
        Indices into `lam` of the oscillatory eigenvalues (`oscillatory_mask`, Im > 0).
    vr : numpy.ndarray
        LAPACK's packed right eigenvectors: the columns osc and osc + 1 are the real and
        imaginary parts of the vector of lam[osc] (`right` unpacks them).
    left : numpy.ndarray or None
        Columns u_i (u_i^H A = lam_i u_i^H) of lam[osc], unit 2-norm; None when not computed.
    """

    lam: np.ndarray
    osc: np.ndarray
    vr: np.ndarray
    left: np.ndarray | None

    @property
    def right(self) -> np.ndarray:
        """Columns x_i (A x_i = lam_i x_i) of lam[osc], unit 2-norm, as `numpy.linalg.eig`
        gives them (unpacked on demand: a prediction without scatter needs only `dominant`)."""
        return self.vr[:, self.osc] + 1j * self.vr[:, self.osc + 1]

    def dominant(self, n: int) -> np.ndarray:
        """Row of the largest |x_i| among the first `n` rows of each oscillatory vector
        (|x|^2 from the packed parts: no complex copy)."""
        re, im = self.vr[:n, self.osc], self.vr[:n, self.osc + 1]
        return (re * re + im * im).argmax(axis=0)


def eig_both(a: np.ndarray, left: bool = True) -> Eigen:
    """Eigenvalues with right and left eigenvectors of a real matrix (LAPACK dgeev). Only the
    oscillatory modes' left vectors are unpacked: the rest are never used. `left` False skips
    the left vectors (`Eigen.left` is then None): the eigenvalues and right vectors are the
    same to the bit (LAPACK computes them alike), and `left_rows` gives the left vectors from
    the right ones for less than LAPACK's own cost (measured: 0.08x against 0.19x a bare
    `numpy.linalg.eig`).

    Raises
    ------
    numpy.linalg.LinAlgError
        A is not finite or LAPACK did not converge.
    """
    if not math.isfinite(a.sum()):  # NaN or inf anywhere
        raise np.linalg.LinAlgError("the state matrix is not finite")
    wr, wi, vl, vr, info = lapack.dgeev(a, compute_vl=int(left), compute_vr=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"LAPACK dgeev did not converge (info {info})")
    lam = wr + 1j * wi
    osc = np.flatnonzero(wi > _IMAG_TOL * np.abs(lam))  # oscillatory_mask; the first of a
    #                                                     pair: re, im in two columns
    return Eigen(lam, osc, vr, vl[:, osc] + 1j * vl[:, osc + 1] if left else None)


def left_rows(eigen: Eigen, start: int = 0) -> np.ndarray:
    """Left eigenvectors y_i^H (rows) of the oscillatory modes of `eigen`, normalised so that
    y_i^H x_i = 1 for the right vectors x_i of `Eigen.right`, their entries from `start` on
    (e.g. the lower half of the state vector): `left_rows_many` of one solve.

    Raises
    ------
    numpy.linalg.LinAlgError
        The right vectors are not a basis (a defective matrix).
    """
    return left_rows_many(eigen.vr[None], eigen.osc[None], start)[0]


def left_rows_many(vr: np.ndarray, osc: np.ndarray, start: int = 0) -> np.ndarray:
    """`left_rows` of G eigen-solves with the same number M of oscillatory modes: LAPACK's
    packed right vectors `vr` (G, 2N, 2N) and the oscillatory indices `osc` (G, M); shape
    (G, M, 2N - start). The rows of X^-1, X the matrix of all right vectors: LAPACK packs a
    complex pair x, conj(x) as its real and imaginary parts, V = X S, so X^-1 = S V^-1 and the
    row of x is (V^-1[i] - 1j V^-1[i + 1]) / 2: one real solve with V each, no complex
    arithmetic (measured: 0.08x a bare `numpy.linalg.eig`, LAPACK's own left vectors 0.19x).

    Raises
    ------
    numpy.linalg.LinAlgError
        Some V is singular (a defective matrix: no basis of eigenvectors).
    """
    inverse = np.linalg.solve(vr, _unit_columns(vr.shape[-1], start))
    rows = osc[:, :, None]
    return (
        np.take_along_axis(inverse, rows, 1) - 1j * np.take_along_axis(inverse, rows + 1, 1)
    ) * 0.5


def displacements(vr: np.ndarray, osc: np.ndarray, n: int) -> np.ndarray:
    """The displacement halves q (first `n` entries) of the right vectors of the oscillatory
    modes, from G solves' packed `vr` (G, 2N, 2N) and indices `osc` (G, M): (G, n, M)."""
    top, cols = vr[:, :n], osc[:, None, :]
    return np.take_along_axis(top, cols, 2) + 1j * np.take_along_axis(top, cols + 1, 2)


@lru_cache(maxsize=16)
def _unit_columns(size: int, start: int) -> np.ndarray:
    """Columns `start`.. of the identity of `size` (read-only)."""
    out = np.eye(size)[:, start:]
    out.setflags(write=False)
    return out


def oscillatory_mask(eigvals: np.ndarray) -> np.ndarray:
    """One eigenvalue of each complex-conjugate pair (Im > 0)."""
    return eigvals.imag > _IMAG_TOL * np.abs(eigvals)


def unstable_mask(eigvals: np.ndarray) -> np.ndarray:
    """Squeak eigenvalues: oscillatory with Re(lambda) > 0, by the thresholds of `classify`."""
    return oscillatory_mask(eigvals) & (eigvals.real > GROWTH_TOL * np.abs(eigvals))


def max_growth_rate(eigvals: np.ndarray) -> np.ndarray:
    """Largest Re(lambda) over the oscillatory eigenvalues, along the last axis (1/s)."""
    return np.where(oscillatory_mask(eigvals), eigvals.real, -np.inf).max(axis=-1)


def max_divergence_rate(eigvals: np.ndarray) -> np.ndarray:
    """Largest real eigenvalue > 0 (non-oscillatory growth) along the last axis, else 0 (1/s)."""
    real = np.abs(eigvals.imag) <= _IMAG_TOL * np.abs(eigvals)
    growing = real & (eigvals.real > GROWTH_TOL * np.abs(eigvals))
    return np.where(growing, eigvals.real, 0.0).max(axis=-1)


def classify(
    eigen: Eigen, labels: tuple[str, ...]
) -> tuple[tuple[ModeResult, ...], tuple[float, ...]]:
    """Oscillatory modes sorted by growth rate (descending) and divergence rates (Re > 0, Im = 0).

    A mode is labelled by its dominant modal coordinate (largest |q_i| in the displacement half
    of the state eigenvector; the basis is mass-normalised so amplitudes are comparable).
    """
    return classify_many([eigen], labels)[0]


def classify_many(
    eigens: Sequence[Eigen], labels: tuple[str, ...]
) -> list[tuple[tuple[ModeResult, ...], tuple[float, ...]]]:
    """`classify` of many eigen-solves: the solves with the same number of oscillatory modes
    in one array step each (sort, frequencies, damping ratios, labels), the same IEEE
    operations per mode as one at a time."""
    out: list = [None] * len(eigens)
    n, two_pi = len(labels), 2 * math.pi
    for group in _by_mode_count(eigens):
        osc = np.array([eigens[i].osc for i in group]).reshape(len(group), -1)
        lam = np.array([eigens[i].lam for i in group])
        lam = np.take_along_axis(lam, osc, 1)
        order = np.argsort(-lam.real, axis=1, kind="stable")
        lam = np.take_along_axis(lam, order, 1)
        re, mag = lam.real, np.abs(lam)
        vr = np.array([eigens[i].vr for i in group])
        q = displacements(vr, osc, n)
        dominant = np.take_along_axis((q.real * q.real + q.imag * q.imag).argmax(axis=1), order, 1)
        columns = zip(
            dominant.tolist(),
            (lam.imag / two_pi).tolist(),
            re.tolist(),
            (-re / mag).tolist(),
            (re > GROWTH_TOL * mag).tolist(),
            strict=True,
        )
        for i, (d, f, r, z, u) in zip(group, columns, strict=True):
            rows = zip(map(labels.__getitem__, d), f, r, z, u, strict=True)
            out[i] = (tuple(map(_mode, rows)), _divergence(eigens[i].lam))
    return out


def _mode(fields: tuple) -> ModeResult:
    """A ModeResult of its five fields (what `ModeResult._make` does, without its Python-level
    length check: every row here has five)."""
    return tuple.__new__(ModeResult, fields)


def _by_mode_count(eigens: Sequence[Eigen]) -> list[list[int]]:
    """Indices of `eigens` grouped by their number of oscillatory modes (arrays stack)."""
    groups: dict[int, list[int]] = {}
    for i, e in enumerate(eigens):
        groups.setdefault(len(e.osc), []).append(i)
    return list(groups.values())


def _divergence(eigvals: np.ndarray) -> tuple[float, ...]:
    """Real eigenvalues > 0 (non-oscillatory growth), descending."""
    if eigvals.real.max() <= 0:  # the common case: nothing grows
        return ()
    mag = np.abs(eigvals)
    real = eigvals.real[
        (np.abs(eigvals.imag) <= _IMAG_TOL * mag) & (eigvals.real > GROWTH_TOL * mag)
    ]
    return tuple(sorted(real.tolist(), reverse=True))
