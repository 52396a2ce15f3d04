"""The channel's wall layer with laws of its own: a local power law per distance from the
wall, fitted once on some DEM runs, and the bulk's nonlocal model beyond it.

Within :data:`granflow.continuum.cooperativity.X_BULK` of the wall the DEM's fluidity does
not follow the bulk's nonlocal law (its amplitude there is a fraction of the bulk's), yet
this layer carries most of u_max - u_slip. At a given distance from the wall, though, the
layer's shear rate is a function of the local stress ratio alone across widths and
fillings: between bin centres x_k and x_(k+1),
``(u_(k+1) - u_k) / (x_(k+1) - x_k) = sqrt(sigma_xx/rho_p)/d * c_k mu^n_k`` with mu the
stress ratio at the interval's midpoint, and at the first bulk bin ``|du/dx| = sqrt(...)/d
c_K mu^n_K``, which gives the bulk's boundary fluidity; the layer's bins pack as
``phi_k = a_k + b_k mu`` (mu at the bin centre). The stress comes from the run's phi
profile through (B2) (as granflow.continuum.given_phi), the wall velocity u_slip is the
run's (the boundary datum every model here takes), and the bulk is the nonlocal model with
its phi given and its amplitude held.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl

from granflow.errors import ParameterError

from ._checks import FloatArray
from .calibration import Calibration
from .channel_model import ChannelCase, law_for
from .cooperativity import X_BULK
from .given_phi import _phi_on, _stress, solve_nonlocal_given_phi
from .laws import LocalLaw
from .problem import ChannelProblem


@dataclass(frozen=True)
class LayerLaws:
    """The wall layer's laws: the bin centres ``x`` (the layer's and the first bulk bin's),
    per interval k between them ``I = c[k] mu^n[k]`` (the interval's mean shear rate), and
    at the first bulk bin ``I = c[-1] mu^n[-1]`` (its shear rate); ``runs``: what they were
    fitted on."""

    x: tuple[float, ...]
    c: tuple[float, ...]
    n: tuple[float, ...]
    runs: str
    #: the layer bins' packing, phi = phi_a[k] + phi_b[k] mu at bin centre x[k] (k < K)
    phi_a: tuple[float, ...] = ()
    phi_b: tuple[float, ...] = ()

    def table(self) -> pl.DataFrame:
        """One row per law: where it applies, c and n (and the packing law at the interval's
        wall-side bin centre, where there is one)."""
        k = len(self.x) - 1
        where = [f"{self.x[i]:g}-{self.x[i + 1]:g} d" for i in range(k)] + [f"{self.x[-1]:g} d"]
        out = pl.DataFrame({"x": where, "c": list(self.c), "n": list(self.n)})
        if len(self.phi_a) == k:
            nan = [math.nan]
            out = out.with_columns(pl.Series("phi_a", [*self.phi_a, *nan]),
                                   pl.Series("phi_b", [*self.phi_b, *nan]))
        return out


@dataclass(frozen=True)
class LayeredPrediction:
    """The layered model at a run's bins: u, and phi (the layer's packing laws in the layer,
    the cell's phi(I) at the model's I beyond; the stress is the run's either way)."""

    u: FloatArray
    phi: FloatArray


def _layer_bins(case: ChannelCase) -> int:
    """The index of the first bulk bin (x >= X_BULK); refused where the run has no bulk."""
    xi = case.profile["xi"].to_numpy()
    k = int(np.searchsorted(xi, X_BULK))
    if k == 0 or k >= xi.size - 1:
        raise ParameterError(f"invalid case {case.name}: no wall layer and bulk at x = "
                             f"{X_BULK:g} d in its bins ({xi.size} bins)")
    return k


def _mu_at(case: ChannelCase, x: FloatArray) -> FloatArray:
    """The stress ratio at ``x`` from the run's phi profile, (B2) integrated from the
    centre (granflow.continuum.given_phi's stress)."""
    t = case.profile
    prob = ChannelProblem(W=case.W, sigma_xx=case.sigma_xx, u_wall=0.0)
    grid = np.linspace(0.0, case.W / 2, 4001)
    s = _stress(prob, grid, _phi_on(grid, t["xi"].to_numpy(), t["phi"].to_numpy()))
    return np.asarray(np.interp(x, grid, s) / case.sigma_xx)


def _observed(case: ChannelCase, K: int) -> tuple[FloatArray, FloatArray]:
    """Per law: the stress ratio and the inertial number the run shows there."""
    t = case.profile
    x, u = t["xi"].to_numpy(), t["u"].to_numpy()
    c = math.sqrt(case.sigma_xx)
    # the intervals' midpoints, then the first bulk bin
    mu = _mu_at(case, np.append(0.5 * (x[:K] + x[1:K + 1]), x[K]))
    rate = np.concatenate([np.diff(u[:K + 1]) / np.diff(x[:K + 1]),
                           [abs(float(t["gamma_dot"][K]))]])
    return mu, rate / c


def fit_layer_laws(cases: Sequence[ChannelCase]) -> LayerLaws:
    """The wall layer's laws by least squares of ln I on ln mu over ``cases`` (at least 2,
    with the same bin centres up to the first bulk bin)."""
    if len(cases) < 2:
        raise ParameterError(f"invalid cases: {len(cases)} run(s), allowed >= 2 to fit the "
                             "wall layer's laws")
    K = _layer_bins(cases[0])
    x0 = cases[0].profile["xi"].to_numpy()[:K + 1]
    obs = []
    for case in cases:
        x = case.profile["xi"].to_numpy()[:K + 1]
        if _layer_bins(case) != K or not np.allclose(x, x0, rtol=0, atol=1e-9):
            raise ParameterError(f"invalid case {case.name}: its wall layer's bins {x} differ "
                                 f"from {cases[0].name}'s {x0}; allowed runs binned alike")
        obs.append(_observed(case, K))
    mu = np.array([m for m, _ in obs])
    i = np.array([r for _, r in obs])
    if np.any(i <= 0) or np.any(mu <= 0):
        raise ParameterError("invalid cases: a wall-layer shear rate or stress ratio is not "
                             "positive (a run that does not shear at its wall)")
    fits = [np.polyfit(np.log(mu[:, k]), np.log(i[:, k]), 1) for k in range(K + 1)]
    mu_c = np.array([_mu_at(c, x0[:K]) for c in cases])
    phi_c = np.array([c.profile["phi"].to_numpy()[:K] for c in cases])
    packing = [np.polyfit(mu_c[:, k], phi_c[:, k], 1) for k in range(K)]
    return LayerLaws(tuple(float(v) for v in x0), tuple(float(math.exp(f[1])) for f in fits),
                     tuple(float(f[0]) for f in fits), "; ".join(c.name for c in cases),
                     tuple(float(f[1]) for f in packing), tuple(float(f[0]) for f in packing))


def predict_layered(case: ChannelCase, laws: LayerLaws, law: LocalLaw, A: float
                    ) -> LayeredPrediction:
    """u and phi at ``case``'s bins: u_slip from the run, the layer's velocity (and, with
    packing laws, its phi) from ``laws``, the bulk from the nonlocal model (``law``,
    amplitude ``A``, the run's phi for the stress) with boundary data at the first bulk bin
    from the layer (its velocity, and its fluidity from the last law); the bulk's phi the
    cell's phi(I) at the model's I (NaN in the layer without packing laws)."""
    K = _layer_bins(case)
    t = case.profile
    x = t["xi"].to_numpy()
    if len(laws.x) != K + 1 or not np.allclose(x[:K + 1], laws.x, rtol=0, atol=1e-9):
        raise ParameterError(f"invalid case {case.name}: its wall layer's bins "
                             f"{x[:K + 1]} are not the laws' {laws.x}")
    c = math.sqrt(case.sigma_xx)
    # the stress ratio at the intervals' midpoints, the first bulk bin and the layer's bins
    mu_all = _mu_at(case, np.concatenate([0.5 * (x[:K] + x[1:K + 1]), x[:K + 1]]))
    mu, mu_b, mu_bins = mu_all[:K], float(mu_all[2 * K]), mu_all[K:2 * K]
    rate = c * np.asarray(laws.c[:K]) * mu ** np.asarray(laws.n[:K])
    u = float(t["u"][0]) + np.concatenate([[0.0], np.cumsum(rate * np.diff(x[:K + 1]))])
    g_b = c * laws.c[K] * mu_b ** laws.n[K] / mu_b
    prob = ChannelProblem(W=case.W, sigma_xx=case.sigma_xx, u_wall=float(u[-1]), x0=float(x[K]),
                          g_wall=g_b)
    bulk = solve_nonlocal_given_phi(law, A, prob, x, t["phi"].to_numpy())
    at = bulk.at(x[K:])
    phi_layer = (np.asarray(laws.phi_a) + np.asarray(laws.phi_b) * mu_bins
                 if len(laws.phi_a) == K else np.full(K, math.nan))
    return LayeredPrediction(np.concatenate([u[:-1], at["u"]]),
                             np.concatenate([phi_layer, law.phi(at["I"])]))


def layered_table(cases: Sequence[ChannelCase], cal: Mapping[float, Calibration],
                  laws: LayerLaws, A: float) -> pl.DataFrame:
    """Per run: the layered model's whole-channel misfit of u - u_slip (relative to the DEM's
    u_max - u_slip, over the bins past the wall bin), its misfit in the layer and in the
    bulk, and its u_max - u_slip over the DEM's."""
    rows = []
    for case in cases:
        t = case.profile
        u = t["u"].to_numpy()
        um = predict_layered(case, laws, law_for(case, cal).law, A).u
        r = (um - u)[1:] / (u[-1] - u[0])
        K = _layer_bins(case)
        rows.append({"W": case.W, "phi_bar": case.phi_bar, "seed": case.seed,
                     "u_rel": float(np.sqrt(np.mean(r**2))),
                     "u_rel_layer": float(np.sqrt(np.mean(r[:K] ** 2))),
                     "u_rel_bulk": float(np.sqrt(np.mean(r[K:] ** 2))),
                     "du_ratio": float((um[-1] - um[0]) / (u[-1] - u[0]))})
    return pl.DataFrame(rows)
