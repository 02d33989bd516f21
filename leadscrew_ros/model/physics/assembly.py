# SPDX-License-Identifier: Apache-2.0
"""Matrices of the linearised equations of motion (27), precomputed once per geometry.

    qdd + (C + G + W3 + W4 + W5qdot) qd + ([omega^2] - Omega^2 I + W1 + W2 + W5q) q = 0   (27)

`Geometry` holds everything that depends on geometry and material only; an operating point
(speed, load, friction and damping values) only rescales its matrices. What does not depend on
the nut (modal basis, kernels, gyroscopic matrix) is cached per screw, so a new nut position
costs only the closed-form contact integrals.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import cached_property, lru_cache
from types import SimpleNamespace
from typing import cast

import numpy as np
from numpy.typing import ArrayLike

from .contact import ContactIntegrals, HelixContact, helix_contact
from .friction import SteadyFriction
from .kernels import MATRICES, coefficients, level_slope, scales
from .modes import KIND_X, KIND_Y, ModalBasis, modal_basis
from .parameters import GEOMETRY_FIELDS, ScrewParameters, field_names


def gyroscopic_unit(basis: ModalBasis) -> np.ndarray:
    """G / Omega (A.2): rho * integral over the section of r dr dtheta = rho A (the section integral
    of (A.2) is the area), so with mass-normalised shapes G couples B_nx and B_ny by -+2 Omega."""
    same_order = basis.order[:, None] == basis.order[None, :]
    xy = (basis.kind[:, None] == KIND_X) & (basis.kind[None, :] == KIND_Y) & same_order
    return 2.0 * (xy.T.astype(float) - xy.astype(float))


@dataclass(frozen=True)
class SystemMatrices:
    """N x N matrices of (27) at one operating point; `stiffness` and `damping` are the sums.

    Attributes
    ----------
    C : ndarray
        Modal damping (A.1).
    G : ndarray
        Gyroscopic coupling at the speed (A.2).
    W : dict of str to ndarray
        The friction-contact matrices W1..W5 at the operating point, by name.
    stiffness : ndarray
        K = [omega^2 - Omega^2] + W1 + W2 + W5q.
    damping : ndarray
        D = C + G + W3 + W4 + W5qdot.
    """

    C: np.ndarray
    G: np.ndarray
    W: dict[str, np.ndarray]
    stiffness: np.ndarray
    damping: np.ndarray


@dataclass(frozen=True)
class Geometry:
    """Everything of (27) that depends on the geometry only, precomputed once
    (`build_geometry`): the matrices at an operating point are a rescaling of its parts.

    Attributes
    ----------
    params : ScrewParameters
        The parameters it was built for.
    basis : ModalBasis
        The assumed modes.
    contact : ContactIntegrals
        The contact integrals over the nut.
    G_unit : ndarray
        Gyroscopic matrix per unit speed.
    lower_half_units : ndarray
        (5, N*2N) lower half [K | D] of the state matrix per scale factor: W1+W2, W5q,
        W3+W4, W5qdot, G (pairs share a scale).
    """

    params: ScrewParameters
    basis: ModalBasis
    contact: ContactIntegrals
    G_unit: np.ndarray
    lower_half_units: np.ndarray

    @property
    def n(self) -> int:
        """Number of modes N."""
        return self.basis.n

    def matrices(self, speed_rad_s: float, load_n: float) -> SystemMatrices:
        """The N x N matrices of (27) at one operating point.

        Parameters
        ----------
        speed_rad_s : float
            Rotation speed Omega [rad/s].
        load_n : float
            Axial load F_z [N].

        Returns
        -------
        SystemMatrices
            C, G, the W matrices and their sums.
        """
        s = scales(self.params, speed_rad_s, load_n, self.contact.alpha)
        W = {k: float(s[k]) * v for k, v in self.contact.unit.items()}
        om = self.basis.omega_rad_s
        C = np.diag(2 * self.params.modal_damping * om)  # (A.1)
        G = speed_rad_s * self.G_unit  # (A.2)
        K = np.diag(om**2 - speed_rad_s**2) + W["W1"] + W["W2"] + W["W5q"]
        D = C + G + W["W3"] + W["W4"] + W["W5qdot"]
        return SystemMatrices(C=C, G=G, W=W, stiffness=K, damping=D)

    @cached_property
    def _template(self) -> np.ndarray:
        """State matrix at zero speed and load: [[0, I], [-[omega^2], -C]]."""
        n, om = self.n, self.basis.omega_rad_s
        a = np.zeros((2 * n, 2 * n))
        a[np.arange(n), n + np.arange(n)] = 1.0
        a[n + np.arange(n), np.arange(n)] = -(om**2)
        a[n + np.arange(n), n + np.arange(n)] = -2 * self.params.modal_damping * om  # (A.1)
        return a

    def state_matrices(
        self,
        speed_rad_s: ArrayLike,
        load_n: ArrayLike,
        scattered: Mapping[str, np.ndarray] | None = None,
        units: np.ndarray | None = None,
        rows: np.ndarray | None = None,
    ) -> np.ndarray:
        """First-order state matrices [[0, I], [-K, -D]] of (27) for arrays of operating points
        (broadcast). One matrix product rescales all precomputed parts.

        Parameters
        ----------
        speed_rad_s : float or array_like
            Rotation speeds Omega [rad/s].
        load_n : float or array_like
            Axial loads F_z [N], broadcast with the speeds.
        scattered : mapping of str to ndarray, optional
            Arrays of non-geometry parameters (friction, damping; broadcast with the operating
            points) that replace the nominal values: they enter only through the scale
            factors and the damping diagonal, so samples of them cost one product each.
        units : ndarray, optional
            `lower_half_units` of each point's own contact, shape (..., 5, N * 2N) broadcast
            with the points (`lower_half_units_at`: other nut positions), instead of these;
            with `rows`, those of D contacts (D, 5, N * 2N).
        rows : ndarray, optional
            Of one-dimensional points: each point's contact, a row of `units` (the points of
            one contact rescale it in one product, no copy per point).

        Returns
        -------
        ndarray
            Shape (..., 2N, 2N).
        """
        if (
            not scattered
            and units is None
            and (
                type(speed_rad_s) is float
                and type(load_n) is float
                or np.ndim(speed_rad_s) == 0
                and np.ndim(load_n) == 0
            )
        ):
            return self._state_matrix(float(cast(float, speed_rad_s)), float(cast(float, load_n)))
        speed = np.asarray(speed_rad_s, float)
        if scattered:  # one matrix per sample, whatever varies
            speed = np.broadcast_to(
                speed, np.broadcast_shapes(speed.shape, *(np.shape(v) for v in scattered.values()))
            )
        params = (
            self.params
            if not scattered
            else SimpleNamespace(**{**self.params.as_dict(), **scattered})
        )
        s = scales(params, speed, load_n, self.contact.alpha)
        parts = (s["W1"], s["W5q"], s["W3"], s["W5qdot"], speed)
        coef = (
            np.array(parts)
            if all(np.ndim(x) == 0 for x in parts)
            else np.stack(np.broadcast_arrays(*parts), axis=-1)
        )
        n = self.n
        # einsum, not @: a BLAS matmul here wakes OpenBLAS threads that keep spinning on the
        # other core through the following eigen-solve (measured: 1.8 CPU-s per wall-s).
        if units is None:
            lower = np.einsum("...k,kj->...j", coef, self.lower_half_units)
        elif rows is None:
            lower = np.einsum("...k,...kj->...j", coef, units)
        else:
            lower = np.empty(coef.shape[:-1] + units.shape[-1:])
            for row in np.unique(rows).tolist():
                at = rows == row
                lower[at] = np.einsum("...k,kj->...j", coef[at], units[row])
        lower = lower.reshape(coef.shape[:-1] + (n, 2 * n))
        out = np.empty(lower.shape[:-2] + (2 * n, 2 * n))
        out[...] = self._template
        out[..., n:, :] -= lower
        flat = out.reshape(out.shape[:-2] + (4 * n * n,))  # a view
        flat[..., self._k_diagonal] += (speed**2)[..., None]  # -Omega^2 I in K
        if scattered and "modal_damping" in scattered:  # (A.1)
            extra = np.asarray(scattered["modal_damping"], float) - self.params.modal_damping
            flat[..., self._d_diagonal] -= 2 * extra[..., None] * self.basis.omega_rad_s
        return out

    def _state_matrix(self, speed: float, load: float) -> np.ndarray:
        """`state_matrices` at one operating point: the same operations without broadcasting
        (a live prediction's share of the cost)."""
        level, slope = level_slope(self.params, speed, load, self.contact.alpha, self._friction)
        w1, w3, w5q, w5qdot = coefficients(speed, level, slope)
        coef = np.array((w1, w5q, w3, w5qdot, speed))
        n = self.n
        out = self._template.copy()
        out[n:, :] -= np.einsum("k,kj->j", coef, self.lower_half_units).reshape(n, 2 * n)
        out.reshape(-1)[self._k_diagonal] += speed * speed  # -Omega^2 I in K
        return out

    @cached_property
    def _friction(self) -> SteadyFriction:
        """The friction law of `params`, its speed-free factors computed once."""
        return SteadyFriction(self.params)

    @cached_property
    def _d_diagonal(self) -> np.ndarray:
        """Flat indices of the diagonal of the D block of a 2N x 2N state matrix."""
        n = self.n
        return (n + np.arange(n)) * (2 * n) + n + np.arange(n)

    @cached_property
    def _k_diagonal(self) -> np.ndarray:
        """Flat indices of the diagonal of the K block of a 2N x 2N state matrix."""
        n = self.n
        return (n + np.arange(n)) * (2 * n) + np.arange(n)


_GEOMETRY_FIELDS = tuple(n for n in field_names() if n in GEOMETRY_FIELDS)
_SCREW_FIELDS = tuple(n for n in _GEOMETRY_FIELDS if n not in ("nut_position_m", "nut_length_m"))


class _Key:
    """Cache key: `params`, hashed and compared by some of its fields only."""

    __slots__ = ("params", "_values", "_hash")

    def __init__(self, params: ScrewParameters, names: tuple[str, ...]):
        self.params = params
        self._values = tuple([getattr(params, n) for n in names])
        self._hash = hash(self._values)

    def __hash__(self) -> int:
        return self._hash

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Key) and self._values == other._values


# The contact rows of lower_half_units: [W1 + W2 | 0], [W5q | 0], [0 | W3 + W4], [0 | W5qdot]
# (sums of the matrices of MATRICES that share a scale factor), then [0 | G].
_HALVES = np.array(
    [[w in ("W1", "W2"), w == "W5q", w in ("W3", "W4"), w == "W5qdot"] for w in MATRICES], float
).T  # (4, len(MATRICES))
_DAMPING_ROW = np.array([False, False, True, True])


@dataclass(frozen=True, eq=False)
class _Screw:
    """The part of a geometry that does not depend on the nut."""

    basis: ModalBasis
    helix: HelixContact
    G_unit: np.ndarray
    kernels: np.ndarray  # helix kernels of the four contact rows of lower_half_units
    index: np.ndarray  # (4, N * 2N) their entries in the helix table; 0 at the end
    G_half: np.ndarray  # (N * 2N,) the last row of lower_half_units


def build_geometry(params: ScrewParameters) -> Geometry:
    """The `Geometry` of these parameters; cached per geometry (sweeps revisit them), and the
    modal basis and kernels per screw (a new nut position only integrates the contact).

    Parameters
    ----------
    params : ScrewParameters
        The screw, nut and friction parameters.

    Returns
    -------
    Geometry
        With `params` as given (the cached parts shared).
    """
    geometry = _geometry_of(_Key(params, _GEOMETRY_FIELDS))
    return geometry if geometry.params is params else replace(geometry, params=params)


def lower_half_units_at(params: ScrewParameters, nut_positions_m: ArrayLike) -> np.ndarray:
    """`Geometry.lower_half_units` of `params` with the nut at each of `nut_positions_m` (D,)
    [m] instead: shape (D, 5, N * 2N), in one vectorised step (the modal basis and kernels are
    the screw's, cached; the positions are not checked against the parameters' rules).

    Parameters
    ----------
    params : ScrewParameters
        The screw, nut length and formulation.
    nut_positions_m : array_like
        Nut positions z_o [m].

    Returns
    -------
    numpy.ndarray
        The state-matrix parts of each nut position, as `Geometry.state_matrices` takes them.
    """
    screw = _screw_of(_Key(params, _SCREW_FIELDS))
    nuts = np.asarray(nut_positions_m, float).ravel()
    return _halves(screw, screw.helix.exponentials(nuts, params.nut_length_m))


def _halves(screw: _Screw, exponentials: np.ndarray) -> np.ndarray:
    """lower_half_units of the contact `exponentials` (D, 4M, P) of D nut positions: each
    nut's table of kind blocks (`HelixContact.table`), then the entries of each."""
    d, rows, pairs = len(exponentials), len(screw.kernels), exponentials.shape[2]
    table = np.empty((d, rows * pairs + 1))
    table[:, -1] = 0.0  # where `index` points outside the contact rows
    screw.helix.table(exponentials, screw.kernels, out=table[:, :-1].reshape(d, rows, pairs))
    halves = np.empty((d, 5, screw.G_half.size))
    np.take(table, screw.index, axis=1, out=halves[:, :4])
    halves[:, 4] = screw.G_half
    return halves


@lru_cache(maxsize=256)
def _geometry_of(key: _Key) -> Geometry:
    params = key.params
    screw = _screw_of(_Key(params, _SCREW_FIELDS))
    contact = screw.helix.integrals(params.nut_position_m, params.nut_length_m)
    return Geometry(
        params=params,
        basis=screw.basis,
        contact=contact,
        G_unit=screw.G_unit,
        lower_half_units=_halves(screw, contact.exponentials[None])[0],
    )


@lru_cache(maxsize=32)
def _screw_of(key: _Key) -> _Screw:
    basis = modal_basis(key.params)
    helix = helix_contact(key.params, basis)
    n, w = basis.n, len(MATRICES)
    kernels = (_HALVES @ helix.kernels.reshape(w, -1)).reshape(4 * 9, -1)
    size = 9 * len(helix.wavenumber) ** 2  # one matrix's table
    rows = np.arange(4)[:, None, None] * size + helix.index  # (4, N, N)
    index = np.full((4, n, 2 * n), 4 * size)  # the 0 at the end of the table
    index[~_DAMPING_ROW, :, :n] = rows[~_DAMPING_ROW]
    index[_DAMPING_ROW, :, n:] = rows[_DAMPING_ROW]
    G_unit = gyroscopic_unit(basis)
    return _Screw(
        basis=basis,
        helix=helix,
        G_unit=G_unit,
        kernels=kernels,
        index=index.reshape(4, -1),
        G_half=np.hstack((np.zeros_like(G_unit), G_unit)).ravel(),
    )
