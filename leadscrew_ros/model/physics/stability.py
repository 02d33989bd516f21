# SPDX-License-Identifier: Apache-2.0
"""Eigen-analysis of (27): squeak (flutter) modes, divergence, labels (README
"Sign conventions, validity, risk")."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from functools import lru_cache
from itertools import repeat
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


class Solves(NamedTuple):
    """G eigen-solves with the same number M of oscillatory modes, stacked for array steps
    (`solves_of`).

    Attributes
    ----------
    eigvals : numpy.ndarray
        (G, 2N) all eigenvalues [1/s].
    osc : numpy.ndarray
        (G, M) indices of the oscillatory ones (`Eigen.osc`).
    lam : numpy.ndarray
        (G, M) the oscillatory eigenvalues [1/s].
    vr : numpy.ndarray
        (G, 2N, 2N) LAPACK's packed right vectors.
    q : numpy.ndarray
        (G, N, M) the displacement halves of the oscillatory right vectors (x = [q; lam q]).
    """

    eigvals: np.ndarray
    osc: np.ndarray
    lam: np.ndarray
    vr: np.ndarray
    q: np.ndarray


def solves_of(eigens: Sequence[Eigen], n: int) -> list[tuple[list[int], Solves]]:
    """`eigens` grouped by their number of oscillatory modes and stacked: (indices into
    `eigens`, their `Solves`) per group; `n` = N, the displacement entries. One solve is
    taken as it is (views, no copies: a live prediction)."""
    if len(eigens) == 1:
        e = eigens[0]
        osc, vr = e.osc, e.vr
        q = vr[:n, osc] + 1j * vr[:n, osc + 1]
        return [([0], Solves(e.lam[None], osc[None], e.lam[osc][None], vr[None], q[None]))]
    lam = np.array([e.lam for e in eigens])
    mask = np.zeros(lam.shape, bool)
    for i, e in enumerate(eigens):
        mask[i, e.osc] = True
    vt = np.array([e.vr.T for e in eigens])
    return _grouped(lam, mask, vt, n, range(len(eigens)))


def eig_right_many(
    a: np.ndarray, n: int
) -> tuple[list[tuple[list[int], Solves]], dict[int, np.linalg.LinAlgError]]:
    """`eig_both` without left vectors of each state matrix of `a` (J, 2N, 2N), one LAPACK
    call each, straight into stacked arrays: the solves grouped as `solves_of` groups them
    (`n` = N), and the matrices LAPACK gave up on (index -> error)."""
    j, m = a.shape[0], a.shape[-1]
    wr, wi = np.zeros((j, m)), np.zeros((j, m))
    vt = np.empty((j, m, m))  # transposed: each solve's vectors stay Fortran-ordered
    failed: dict[int, np.linalg.LinAlgError] = {}
    for k in range(j):
        if not math.isfinite(a[k].sum()):  # NaN or inf anywhere
            failed[k] = np.linalg.LinAlgError("the state matrix is not finite")
            continue
        wr[k], wi[k], _, vr, info = lapack.dgeev(a[k], compute_vl=0, compute_vr=1)
        if info != 0:
            failed[k] = np.linalg.LinAlgError(f"LAPACK dgeev did not converge (info {info})")
            continue
        vt[k] = vr.T
    lam = wr + 1j * wi
    mask = wi > _IMAG_TOL * np.abs(lam)  # oscillatory_mask: the first of each pair
    return _grouped(lam, mask, vt, n, [k for k in range(j) if k not in failed]), failed


def _grouped(
    lam: np.ndarray, mask: np.ndarray, vt: np.ndarray, n: int, rows: Iterable[int]
) -> list[tuple[list[int], Solves]]:
    """The solves `rows` of the stacks (eigenvalues `lam`, oscillatory `mask`, transposed
    right vectors `vt`) by their number of oscillatory modes."""
    counts = mask.sum(axis=1).tolist()
    groups: dict[int, list[int]] = {}
    for i in rows:
        groups.setdefault(counts[i], []).append(i)
    out = []
    for count, index in groups.items():
        eigvals, osc = lam[index], np.nonzero(mask[index])[1].reshape(len(index), count)
        vr = vt[index].transpose(0, 2, 1)
        top, cols = vr[:, :n], osc[:, None, :]
        q = np.take_along_axis(top, cols, 2) + 1j * np.take_along_axis(top, cols + 1, 2)
        out.append((index, Solves(eigvals, osc, np.take_along_axis(eigvals, osc, 1), vr, q)))
    return out


def left_rows(vr: np.ndarray, osc: np.ndarray, start: int = 0) -> np.ndarray:
    """Left eigenvectors y_i^H (rows) of the oscillatory modes `osc` of one eigen-solve,
    normalised so that y_i^H x_i = 1 for their right vectors x_i (`Eigen.right`), the entries
    from `start` on (e.g. the lower half of the state vector): (M, 2N - start), from LAPACK's
    packed right vectors `vr` (2N, 2N). The rows of X^-1, X the matrix of all right vectors:
    LAPACK packs a complex pair x, conj(x) as its real and imaginary parts, V = X S, so
    X^-1 = S V^-1 and the row of x is (V^-1[i] - 1j V^-1[i + 1]) / 2: one real solve with V,
    no complex arithmetic (measured: 0.08x a bare `numpy.linalg.eig`; LAPACK's own left
    vectors cost 0.19x).

    Raises
    ------
    numpy.linalg.LinAlgError
        V is singular (a defective matrix: no basis of eigenvectors).
    """
    _, _, inverse, info = lapack.dgesv(vr, _unit_columns(len(vr), start))
    if info != 0:
        raise np.linalg.LinAlgError("the right eigenvectors are not a basis (defective matrix)")
    rows = np.empty((len(osc), inverse.shape[1]), complex)
    np.multiply(inverse[osc], 0.5, out=rows.real)
    np.multiply(inverse[osc + 1], -0.5, out=rows.imag)
    return rows


def left_rows_many(vr: np.ndarray, osc: np.ndarray, start: int = 0) -> np.ndarray:
    """`left_rows` of G stacked solves: `vr` (G, 2N, 2N), `osc` (G, M); (G, M, 2N - start)
    from one stacked real solve.

    Raises
    ------
    numpy.linalg.LinAlgError
        Some V is singular (then `left_rows` one at a time tells which).
    """
    units = _unit_columns(vr.shape[-1], start)
    inverse = np.linalg.solve(vr, np.broadcast_to(units, vr.shape[:-1] + units.shape[-1:]))
    rows = np.empty(osc.shape + inverse.shape[-1:], complex)
    cols = osc[..., None]
    np.multiply(np.take_along_axis(inverse, cols, -2), 0.5, out=rows.real)
    np.multiply(np.take_along_axis(inverse, cols + 1, -2), -0.5, out=rows.imag)
    return rows


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
    osc, vr, n = eigen.osc, eigen.vr, len(labels)
    lam = eigen.lam[osc]
    order = np.argsort(-lam.real, kind="stable")
    re, im = vr[:n, osc], vr[:n, osc + 1]  # |q|^2 from the packed parts: no complex copy
    dominant = (re * re + im * im).argmax(axis=0)[order]
    return _modes(lam[order][None], dominant[None], eigen.lam[None], labels)[0]


def classify_solves(
    solves: Solves, labels: tuple[str, ...]
) -> list[tuple[tuple[ModeResult, ...], tuple[float, ...]]]:
    """`classify` of stacked solves: sort, labels, frequencies and damping ratios in one array
    step each, the same IEEE operations per mode as one at a time."""
    order = np.argsort(-solves.lam.real, axis=1, kind="stable")
    rows = np.arange(len(order))[:, None]
    q = solves.q
    dominant = (q.real * q.real + q.imag * q.imag).argmax(axis=1)[rows, order]
    return _modes(solves.lam[rows, order], dominant, solves.eigvals, labels)


def _modes(
    lam: np.ndarray, dominant: np.ndarray, eigvals: np.ndarray, labels: tuple[str, ...]
) -> list[tuple[tuple[ModeResult, ...], tuple[float, ...]]]:
    """Per solve its ModeResults and divergence rates, from the sorted oscillatory eigenvalues
    `lam` (G, M), the rows of their largest displacement `dominant` (G, M) and all
    eigenvalues `eigvals` (G, 2N)."""
    re, mag = lam.real, np.abs(lam)
    columns = zip(
        dominant.tolist(),
        (lam.imag / (2 * math.pi)).tolist(),
        re.tolist(),
        (-re / mag).tolist(),
        (re > GROWTH_TOL * mag).tolist(),
        (eigvals.real.max(axis=1) > 0).tolist(),  # a divergence to look for
        strict=True,
    )
    return [
        (
            # ModeResult._make without its Python-level check of the five fields
            tuple(
                map(
                    tuple.__new__,
                    repeat(ModeResult),
                    zip(map(labels.__getitem__, d), f, r, z, u, strict=True),
                )
            ),
            _divergence(values) if grows else (),
        )
        for (d, f, r, z, u, grows), values in zip(columns, eigvals, strict=True)
    ]


def _divergence(eigvals: np.ndarray) -> tuple[float, ...]:
    """Real eigenvalues > 0 (non-oscillatory growth), descending."""
    mag = np.abs(eigvals)
    real = eigvals.real[
        (np.abs(eigvals.imag) <= _IMAG_TOL * mag) & (eigvals.real > GROWTH_TOL * mag)
    ]
    return tuple(sorted(real.tolist(), reverse=True))
