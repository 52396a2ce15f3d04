"""Bond-orientational order (Steinhardt q6): has a dense packing ordered, bin by bin?

Used for the plug of the vertical channel (the unsheared centre, phi up to 0.65): is its high
volume fraction crystallisation (against the flat walls) or a dense amorphous packing?

* Bonds: particles i, j closer than ``cutoff * (d_i + d_j) / 2`` (:data:`CUTOFF` = 1.2, between
  the first shell at ~1 and the second at sqrt(2) (fcc) or ~1.6-2 (random) of a dense packing
  of spheres of diameters 0.8-1.2), with per-axis periodicity (:func:`find_bonds`).
* Per particle, q6m(i) = mean over its bonds of Y_6m(r_ij / |r_ij|), m = -6..6
  (Steinhardt, Nelson & Ronchetti 1983; :func:`q6_vectors`).
* Two order parameters, because they answer different questions:

  - :func:`global_q6`, the region-averaged Q6 = sqrt(4 pi / 13 sum_m |<Y_6m>|^2), <.> over all
    bonds of a set of particles: 0.5745 for a perfect fcc crystal of one orientation, ~1/sqrt
    (bonds) for a random packing. It measures *common* orientational order: grains of different
    orientations average their Y_6m towards zero, so Q6 drops for a polycrystal and cannot tell
    one from an amorphous packing;
  - :func:`crystal_like` (ten Wolde, Ruiz-Montero & Frenkel 1996), a local test: particle i is
    crystal-like when at least :data:`MIN_CONNECTIONS` of its bonds connect it to a neighbour
    with a similar environment, Re(q6(i) . q6(j)*) / (|q6(i)| |q6(j)|) > :data:`CONNECTION`.
    The fraction of crystal-like particles is 1 for fcc of any orientation, polycrystals
    included, and small for a random packing.

  A bin whose crystal-like fraction is high while Q6 is low holds misoriented grains.
* :func:`bin_profile`: both, with the coordination number, per bin of a set of edges along one
  axis (the channel's bins across x), particles assigned to bins by their centres.

Positions, diameters and box lengths in any one unit (the channel's d). The box is
[lo, lo + L) per axis; lo does not matter (periodic axes are wrapped, the others are not).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from math import factorial, pi, sqrt

import numpy as np
import polars as pl
from numpy.polynomial import legendre, polynomial
from scipy.spatial import cKDTree

from granflow.errors import ParameterError

L = 6
"""The harmonic order: l = 6 (sixfold, fcc / hcp / icosahedral order)."""

CUTOFF = 1.2
"""Default bond cutoff, in units of the pair's mean diameter (d_i + d_j) / 2."""

CONNECTION = 0.7
"""A bond i-j is connected when the normalised Re(q6(i) . q6(j)*) exceeds this. The criterion is
ten Wolde, Ruiz-Montero & Frenkel (J. Chem. Phys. 104, 9932, 1996); the thresholds 0.7 and 7
are those used for hard spheres (Auer & Frenkel, J. Chem. Phys. 120, 3015, 2004; Filion et
al., J. Chem. Phys. 133, 244115, 2010)."""

MIN_CONNECTIONS = 7
"""A particle with at least this many connected bonds is crystal-like (source:
:data:`CONNECTION`)."""

_AXES = "xyz"


@dataclass(frozen=True)
class Bonds:
    """The bonds of a set of particles, each once (i < j).

    Attributes:
        i: First particle of each bond (int64).
        j: Second particle of each bond (int64).
        r: The bond vectors x_j - x_i, (bonds, 3), minimum image along periodic axes.
        n: The number of particles.
    """

    i: np.ndarray
    j: np.ndarray
    r: np.ndarray
    n: int

    def coordination(self) -> np.ndarray:
        """Bonds per particle, (n,) int64."""
        return (np.bincount(self.i, minlength=self.n)
                + np.bincount(self.j, minlength=self.n)).astype(np.int64)


def _check_cutoff(cutoff: float) -> float:
    if not (np.isfinite(cutoff) and 1.0 < cutoff <= 2.0):
        raise ParameterError(f"invalid cutoff = {cutoff}: allowed 1 < cutoff <= 2 (in units "
                             "of the pair's mean diameter; 1.2 sits between the first and "
                             "second shells of a dense packing)")
    return float(cutoff)


def _check_inputs(positions: np.ndarray, diameters: np.ndarray, box_lengths: Sequence[float],
                  periodic: Sequence[bool], cutoff: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    x = np.asarray(positions, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ParameterError(f"invalid positions of shape {x.shape}: allowed (n, 3)")
    if not np.all(np.isfinite(x)):
        raise ParameterError("invalid positions: allowed finite values only")
    d = np.asarray(diameters, dtype=float)
    if d.shape != (len(x),):
        raise ParameterError(f"invalid diameters of shape {d.shape}: allowed ({len(x)},), "
                             "one per row of positions")
    if not np.all(np.isfinite(d) & (d > 0)):
        raise ParameterError("invalid diameters: allowed finite values > 0")
    box = np.asarray(box_lengths, dtype=float)
    if box.shape != (3,) or not np.all(np.isfinite(box) & (box > 0)):
        raise ParameterError(f"invalid box_lengths = {box_lengths!r}: allowed three finite "
                             "lengths > 0")
    per = np.asarray(periodic)
    if per.shape != (3,) or per.dtype != bool:
        raise ParameterError(f"invalid periodic = {periodic!r}: allowed three booleans "
                             "(one per axis)")
    cutoff = _check_cutoff(cutoff)
    rmax = cutoff * float(d.max()) if len(d) else 0.0
    for k in range(3):
        if per[k] and box[k] <= 2 * rmax:
            raise ParameterError(
                f"invalid box_lengths[{k}] = {box[k]:g} along a periodic axis: allowed "
                f"> 2 cutoff d_max = {2 * rmax:g} (a bond must have one nearest image)")
    return x, d, box, per, cutoff


def find_bonds(positions: np.ndarray, diameters: np.ndarray, box_lengths: Sequence[float],
               periodic: Sequence[bool], cutoff: float = CUTOFF) -> Bonds:
    """The bonds between particles closer than ``cutoff * (d_i + d_j) / 2``.

    Args:
        positions: Particle centres, (n, 3).
        diameters: Particle diameters, (n,).
        box_lengths: The box's length per axis (used along periodic axes).
        periodic: Whether each axis is periodic (the channel: (False, True, True)). Along a
            non-periodic axis no bond crosses the box.
        cutoff: The bond cutoff in units of the pair's mean diameter, 1 < cutoff <= 2.
    """
    x, d, box, per, cutoff = _check_inputs(positions, diameters, box_lengths, periodic, cutoff)
    n = len(x)
    empty = Bonds(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), n)
    if n < 2:
        return empty
    rmax = cutoff * float(d.max())
    # the tree's box: periodic axes wrapped into [0, L); the others shifted to start at 0 and
    # padded by 2 rmax so that their wrap-around distance exceeds any bond (no bond across)
    xt = np.empty_like(x)
    size = np.empty(3)
    for k in range(3):
        if per[k]:
            w = np.mod(x[:, k], box[k])
            xt[:, k] = np.where(w >= box[k], 0.0, w)  # np.mod(-tiny, L) rounds to L
            size[k] = box[k]
        else:
            lo = x[:, k].min()
            xt[:, k] = x[:, k] - lo
            size[k] = xt[:, k].max() + 2 * rmax
    pairs = cKDTree(xt, boxsize=size).query_pairs(rmax, output_type="ndarray")
    if len(pairs) == 0:
        return empty
    i = pairs[:, 0].astype(np.int64)
    j = pairs[:, 1].astype(np.int64)
    swap = i > j
    i, j = np.where(swap, j, i), np.where(swap, i, j)
    r = xt[j] - xt[i]
    for k in range(3):
        if per[k]:
            r[:, k] -= box[k] * np.round(r[:, k] / box[k])
    dist = np.sqrt(np.einsum("ij,ij->i", r, r))
    keep = dist < cutoff * 0.5 * (d[i] + d[j])
    i, j, r, dist = i[keep], j[keep], r[keep], dist[keep]
    if np.any(dist == 0):
        k = int(np.argmax(dist == 0))
        raise ParameterError(f"invalid positions: particles {i[k]} and {j[k]} coincide "
                             "(allowed: distinct centres)")
    order = np.lexsort((j, i))
    return Bonds(i[order], j[order], r[order], n)


def _ylm6_nonneg(u: np.ndarray) -> list[np.ndarray]:
    """Y_6m(u) for m = 0..6 (Condon-Shortley phase, orthonormal on the sphere) of unit vectors
    u, (bonds, 3). Polynomial in (x, y, z): for a unit vector, sin^m(theta) e^{i m phi} =
    (x + i y)^m and P_l^m(cos theta) = (-1)^m sin^m(theta) d^m P_l / dz^m, so
    Y_lm = N_lm (-1)^m (x + i y)^m (d^m P_l / dz^m)(z); Y_l,-m = (-1)^m conj(Y_lm)."""
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    p_l = legendre.leg2poly([0.0] * L + [1.0])
    w = x + 1j * y
    wm = np.ones(len(u), dtype=complex)
    out = []
    for m in range(L + 1):
        norm = (-1) ** m * sqrt((2 * L + 1) / (4 * pi) * factorial(L - m) / factorial(L + m))
        out.append(norm * polynomial.polyval(z, polynomial.polyder(p_l, m)) * wm)
        wm = wm * w
    return out


def _q6_nonneg(bonds: Bonds) -> tuple[np.ndarray, np.ndarray]:
    """Per particle, the sums over its bonds of Y_6m, m = 0..6, (n, 7) complex, and the
    coordination. Y_6m(-u) = Y_6m(u) (l even): both ends of a bond get the same value."""
    z = bonds.coordination()
    s = np.zeros((bonds.n, L + 1), dtype=complex)
    if len(bonds.i):
        u = bonds.r / np.linalg.norm(bonds.r, axis=1)[:, None]
        ends = np.concatenate([bonds.i, bonds.j])
        for m, y in enumerate(_ylm6_nonneg(u)):
            yy = np.concatenate([y, y])
            s[:, m] = (np.bincount(ends, yy.real, minlength=bonds.n)
                       + 1j * np.bincount(ends, yy.imag, minlength=bonds.n))
    return s, z


def _full(q_nonneg: np.ndarray) -> np.ndarray:
    """(…, 7) components m = 0..6 to (…, 13) components m = -6..6."""
    m = np.arange(1, L + 1)
    neg = ((-1.0) ** m) * np.conj(q_nonneg[..., 1:])
    return np.concatenate([neg[..., ::-1], q_nonneg], axis=-1)


# weights of m = 0..6 in a sum over m = -6..6 of a product a_m b_m* whose real part is even in m
_W = np.array([1.0] + [2.0] * L)


def q6_vectors(bonds: Bonds) -> np.ndarray:
    """Per particle, q6m(i) = the mean over its bonds of Y_6m(r_ij / |r_ij|), (n, 13) complex,
    columns m = -6..6 (zeros for a particle without bonds)."""
    s, z = _q6_nonneg(bonds)
    return _full(s / np.maximum(z, 1)[:, None])


def _select(n: int, particles: np.ndarray | None) -> np.ndarray:
    if particles is None:
        return np.ones(n, dtype=bool)
    p = np.asarray(particles)
    if p.dtype == bool:
        if p.shape != (n,):
            raise ParameterError(f"invalid particles mask of shape {p.shape}: allowed ({n},)")
        return p
    if p.size and (p.min() < 0 or p.max() >= n or not np.issubdtype(p.dtype, np.integer)):
        raise ParameterError(f"invalid particles: allowed integer indices in [0, {n})")
    mask = np.zeros(n, dtype=bool)
    mask[p.astype(np.int64)] = True
    return mask


def _global_q6(s: np.ndarray, z: np.ndarray, mask: np.ndarray) -> float:
    nb = int(z[mask].sum())
    if nb == 0:
        return float("nan")
    q = s[mask].sum(axis=0) / nb
    return float(np.sqrt(4 * pi / (2 * L + 1) * np.sum(_W * np.abs(q) ** 2)))


def global_q6(bonds: Bonds, particles: np.ndarray | None = None) -> float:
    """The region-averaged Q6 = sqrt(4 pi / 13 sum_m |<Y_6m>|^2) over the bonds of
    ``particles`` (a boolean mask or indices; all by default), each bond counted once per end
    in the set. 0.5745 for fcc of one orientation; without order, a noise floor of order
    1/sqrt(bonds) (bonds counted once; a random packing's 1000-bond slabs read 0.04-0.065);
    lower for misoriented grains (module docstring). NaN without bonds."""
    s, z = _q6_nonneg(bonds)
    return _global_q6(s, z, _select(bonds.n, particles))


def _crystal_like(bonds: Bonds, s: np.ndarray, z: np.ndarray, connection: float,
                  min_connections: int) -> tuple[np.ndarray, np.ndarray]:
    norm = np.sqrt(np.sum(_W * np.abs(s) ** 2, axis=1))
    qh = s / np.where(norm > 0, norm, 1.0)[:, None]  # the mean's norm: the sum's, scaled
    dot = np.sum(_W * (qh[bonds.i] * np.conj(qh[bonds.j])).real, axis=1)
    c = dot > connection
    nc = (np.bincount(bonds.i[c], minlength=bonds.n)
          + np.bincount(bonds.j[c], minlength=bonds.n))
    return nc >= min_connections, nc


def crystal_like(bonds: Bonds, connection: float = CONNECTION,
                 min_connections: int = MIN_CONNECTIONS) -> np.ndarray:
    """Per particle, whether it is crystal-like (ten Wolde, Ruiz-Montero & Frenkel 1996): at
    least ``min_connections`` bonds i-j with Re(q6(i) . q6(j)*) / (|q6(i)| |q6(j)|) >
    ``connection``; (n,) bool. Independent of the crystal's orientation."""
    if not (-1.0 <= connection < 1.0):
        raise ParameterError(f"invalid connection = {connection}: allowed -1 <= connection < 1")
    if min_connections < 1:
        raise ParameterError(f"invalid min_connections = {min_connections}: allowed >= 1")
    s, z = _q6_nonneg(bonds)
    return _crystal_like(bonds, s, z, connection, min_connections)[0]


def bin_profile(positions: np.ndarray, diameters: np.ndarray, edges: Sequence[float] | np.ndarray,
                box_lengths: Sequence[float], periodic: Sequence[bool], axis: int = 0,
                cutoff: float = CUTOFF) -> pl.DataFrame:
    """Order per bin of ``edges`` along ``axis``, particles assigned by their centres (those
    outside the edges in no bin; their bonds still count for the particles inside).

    Args:
        positions: Particle centres, (n, 3).
        diameters: Particle diameters, (n,).
        edges: Increasing bin edges along ``axis`` (the channel's ``Channel.bin_edges()``).
        box_lengths: The box's length per axis.
        periodic: Whether each axis is periodic (the channel: (False, True, True)).
        axis: The axis across which to bin, 0, 1 or 2.
        cutoff: The bond cutoff in units of the pair's mean diameter, 1 < cutoff <= 2.

    Returns:
        One row per bin: ``bin`` (index), ``<a>_lo``, ``<a>_hi``, ``<a>`` (edges and centre;
        ``<a>`` the axis' name, x, y or z), ``particles`` (centres in the bin), ``bonds`` (bond
        ends of those particles, what Q6 averages over), ``Q6`` (:func:`global_q6` over the
        bin's particles), ``crystal_fraction`` (fraction of the bin's particles that are
        :func:`crystal_like`, their neighbours anywhere) and ``Z`` (mean bonds per particle);
        NaN where a bin has no particles (Q6: no bonds).
    """
    if axis not in (0, 1, 2):
        raise ParameterError(f"invalid axis = {axis!r}: allowed 0, 1 or 2")
    e = np.asarray(edges, dtype=float)
    if e.ndim != 1 or len(e) < 2 or not np.all(np.isfinite(e)) or not np.all(np.diff(e) > 0):
        raise ParameterError("invalid edges: allowed at least two finite, strictly increasing "
                             "values")
    bonds = find_bonds(positions, diameters, box_lengths, periodic, cutoff)
    x = np.asarray(positions, dtype=float)[:, axis]
    s, z = _q6_nonneg(bonds)
    xtal = _crystal_like(bonds, s, z, CONNECTION, MIN_CONNECTIONS)[0]
    which = np.searchsorted(e, x, side="right") - 1
    which[x == e[-1]] = len(e) - 2  # the last bin is closed
    nbin = len(e) - 1
    rows: dict[str, list[float]] = {"q6": [], "frac": [], "z": []}
    count = np.zeros(nbin, dtype=np.int64)
    nbonds = np.zeros(nbin, dtype=np.int64)
    for b in range(nbin):
        mask = which == b
        count[b] = int(mask.sum())
        nbonds[b] = int(z[mask].sum())
        rows["q6"].append(_global_q6(s, z, mask))
        rows["frac"].append(float(xtal[mask].mean()) if count[b] else float("nan"))
        rows["z"].append(float(z[mask].mean()) if count[b] else float("nan"))
    a = _AXES[axis]
    return pl.DataFrame({
        "bin": np.arange(nbin, dtype=np.int64),
        f"{a}_lo": e[:-1],
        f"{a}_hi": e[1:],
        a: 0.5 * (e[:-1] + e[1:]),
        "particles": count,
        "bonds": nbonds,
        "Q6": np.array(rows["q6"]),
        "crystal_fraction": np.array(rows["frac"]),
        "Z": np.array(rows["z"]),
    })


__all__ = [
    "CONNECTION",
    "CUTOFF",
    "L",
    "MIN_CONNECTIONS",
    "Bonds",
    "bin_profile",
    "crystal_like",
    "find_bonds",
    "global_q6",
    "q6_vectors",
]
