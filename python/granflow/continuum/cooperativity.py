"""The nonlocal amplitude measured in a DEM channel run, bin by bin, instead of fitted to its
whole velocity profile.

Below yield (``mu < mu_s``) the local fluidity is 0 and Henann & Kamrin's fluidity equation
(PNAS 110, 6730, 2013, their (3) with ``xi = A d / sqrt(|mu - mu_s|)``) reads
``g''/g = (mu_s - mu) / (A d)^2``: the fluidity's decay rate is linear in the stress ratio
with the single constant A. A DEM run's bins give ``g = |du/dx| / mu`` and hence
``g''/g = (ln g)'' + ((ln g)')^2`` by central differences, so A follows from each bin (and,
by least squares through the cell's mu_s, from a run's bulk) without solving the model. If
A is the material constant the model takes it for, the bulk values of all widths and
fillings agree; where they do not, the model's flow rule, not its boundary data, is what
fails there.

The window (:data:`X_BULK`, :data:`G_FLOOR`, ``mu < mu_s``): the bins past the wall layer
whose fluidity stands clear of the DEM's creep floor; chosen once, justified in the
cross-scene report from the bin-by-bin values (table by distance from the wall).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import polars as pl

from granflow.analysis.stats import weighted_mean
from granflow.errors import ParameterError

from ._checks import FloatArray
from .calibration import Calibration
from .channel_model import ChannelCase, law_for, solve, velocity_misfit
from .given_phi import solve_nonlocal_given_phi
from .laws import LocalLaw
from .problem import Profile

#: distance from the wall (d) where the bulk window starts: the wall bin and the two bins
#: beside it (000's wall zone, 2 d, and its loose bin) give amplitudes 2-6x below the
#: bulk's, so they are the wall layer, not the fluidity law's domain
X_BULK = 4.0
#: the smallest g d / sqrt(sigma_xx/rho_p) of a stencil's bins: 10x the creep floor
#: (~1e-4) where the DEM's shear rate is at its resolution
G_FLOOR = 1e-3
#: draws of the bins' shear rate and stress ratio within their SEs (the SE of A from them)
N_DRAWS = 200


def _decay(x: FloatArray, gamma_dot: FloatArray, mu: FloatArray) -> FloatArray:
    """``g''/g`` at the interior bins by central differences of ln g on the (non-uniform)
    bin centres; NaN where a stencil's g is not positive."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        lg = np.log(np.abs(gamma_dot) / np.abs(mu))
        h1, h2 = x[1:-1] - x[:-2], x[2:] - x[1:-1]
        d1 = (lg[2:] - lg[:-2]) / (h1 + h2)
        d2 = 2.0 * ((lg[2:] - lg[1:-1]) / h2 - (lg[1:-1] - lg[:-2]) / h1) / (h1 + h2)
        return np.asarray(d2 + d1 * d1)


def amplitude_profile(case: ChannelCase, law: LocalLaw) -> pl.DataFrame:
    """Per interior bin of ``case``'s half profile: the fluidity ``g_star`` = g d /
    sqrt(sigma_xx/rho_p), its decay rate ``decay`` = g''/g (d^-2) and the amplitude ``A`` =
    sqrt(|mu - mu_s| (1 - g_loc/g) / decay) it implies (NaN where the root is not real),
    ``g_min`` the smallest g_star of the bin's stencil, and ``bulk``: whether the bin is in
    the window (:data:`X_BULK`, :data:`G_FLOOR`, below yield)."""
    t = case.profile
    if t.height < 3:
        raise ParameterError(f"invalid case {case.name}: {t.height} bins, allowed >= 3")
    x, gd, mu = (t[c].to_numpy().astype(np.float64) for c in ("xi", "gamma_dot", "mu"))
    c = math.sqrt(case.sigma_xx)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        g_star = np.abs(gd) / np.abs(mu) / c
        r = _decay(x, gd, mu)
        m = np.abs(mu[1:-1])
        loc = law.I_of_mu(m) / m / g_star[1:-1]  # g_loc / g
        a2 = np.abs(m - law.mu_s) * (1.0 - loc) / r
    g_min = np.minimum(np.minimum(g_star[:-2], g_star[1:-1]), g_star[2:])
    inner = x[1:-1]
    return pl.DataFrame({
        "xi": inner, "zone": t["zone"].to_list()[1:-1], "mu": m, "g_star": g_star[1:-1],
        "decay": r, "A": np.where(a2 > 0, np.sqrt(np.abs(a2)), np.nan), "g_min": g_min,
        "bulk": (inner >= X_BULK) & (g_min >= G_FLOOR) & (m < law.mu_s)
                & np.isfinite(r)})


@dataclass(frozen=True)
class BulkAmplitude:
    """A run's bulk amplitude: ``A`` from least squares of g''/g = (mu_s - mu)/A^2 over the
    window's ``n`` bins (``x_lo``-``x_hi``, stress ratios ``mu_lo``-``mu_hi``), its SE the
    larger of the spread over draws of the bins within their SEs and the residuals' SE;
    ``mu_s_free``, the yield ratio where the straight line fitted with a free intercept
    reaches zero decay (NaN with fewer than 4 bins or a non-negative slope): a check of the
    cell's mu_s against the channel's own."""

    A: float
    se: float
    n: int
    x_lo: float
    x_hi: float
    mu_lo: float
    mu_hi: float
    mu_s_free: float


def _through_mu_s(dm: FloatArray, r: FloatArray) -> float:
    """1/A^2 by least squares of r = dm/A^2 (a line through zero decay at mu_s)."""
    return float(np.sum(dm * r) / np.sum(dm * dm))


def bulk_amplitude(case: ChannelCase, law: LocalLaw, seed: int = 0) -> BulkAmplitude:
    """The amplitude of ``case``'s bulk (:class:`BulkAmplitude`); refused, naming the run,
    where fewer than 3 bins are in the window."""
    prof = amplitude_profile(case, law)
    w = prof["bulk"].to_numpy()
    if w.sum() < 3:
        raise ParameterError(
            f"invalid case {case.name}: {int(w.sum())} bins in the bulk window (x >= "
            f"{X_BULK:g} d, g d/sqrt(sigma_xx/rho_p) >= {G_FLOOR:g}, mu < mu_s = "
            f"{law.mu_s:.3f}); allowed a run with >= 3 (a wider or faster channel)")
    mu, r = prof["mu"].to_numpy()[w], prof["decay"].to_numpy()[w]
    dm = law.mu_s - mu
    k = _through_mu_s(dm, r)
    if k <= 0:
        raise ParameterError(f"invalid case {case.name}: its bulk fluidity grows towards "
                             "the centre (no real amplitude)")
    a = k ** -0.5
    n = int(w.sum())
    res = r - k * dm
    se_k = math.sqrt(float(np.sum(res**2)) / (n - 1) / float(np.sum(dm * dm)))
    # draws of every bin's shear rate and stress ratio within its SE, the window held
    t = case.profile
    x = t["xi"].to_numpy().astype(np.float64)
    gd, mu_all = t["gamma_dot"].to_numpy(), t["mu"].to_numpy()
    gd_se = np.nan_to_num(t["gamma_dot_se"].to_numpy(), nan=0.0)
    mu_se = np.nan_to_num(t["mu_se"].to_numpy(), nan=0.0)
    rng = np.random.default_rng(seed)
    draws = []
    for _ in range(N_DRAWS):
        mu_d = mu_all + mu_se * rng.standard_normal(x.size)
        r_d = _decay(x, gd + gd_se * rng.standard_normal(x.size), mu_d)[w]
        kd = _through_mu_s(law.mu_s - np.abs(mu_d[1:-1][w]), r_d)
        if kd > 0 and math.isfinite(kd):
            draws.append(kd ** -0.5)
    se_draws = float(np.std(draws, ddof=1)) if len(draws) > 2 else math.nan
    se = float(np.fmax(se_draws, 0.5 * a * se_k / k))  # (fmax: a NaN draw SE is absent)
    mu_s_free = math.nan
    if n >= 4:
        slope, icpt = np.polyfit(mu, r, 1)
        if slope < 0:
            mu_s_free = float(-icpt / slope)
    xs = prof["xi"].to_numpy()[w]
    return BulkAmplitude(float(a), float(se), n, float(xs.min()), float(xs.max()),
                         float(mu.min()), float(mu.max()), mu_s_free)


def bulk_table(cases: Sequence[ChannelCase], cal: Mapping[float, Calibration],
               reference: ChannelCase | None = None) -> pl.DataFrame:
    """Per run: its bulk amplitude (:func:`bulk_amplitude`), the share of its velocity rise
    u_max - u_slip that lies inside the wall layer (x < :data:`X_BULK`), and, with
    ``reference``, the transfer test: the reference run's bulk A held, the nonlocal model
    with its boundary data at the first bulk bin, misfit relative to the rise past it
    (``u_rel_bulk``). Runs without a bulk window get NaN and their reason."""
    ref = bulk_amplitude(reference, law_for(reference, cal).law) if reference else None
    a_ref = ref.A if ref is not None else math.nan
    rows = []
    for case in cases:
        law = law_for(case, cal).law
        t = case.profile
        xi, u = t["xi"].to_numpy(), t["u"].to_numpy()
        k = int(np.searchsorted(xi, X_BULK))
        row = {"W": case.W, "phi_bar": case.phi_bar, "seed": case.seed, "mu_s": law.mu_s,
               "wall_share": float((u[k] - u[0]) / (u[-1] - u[0])) if k < xi.size
               else math.nan, "A_ref": a_ref, "why": "",
               **dict.fromkeys(("A", "A_se", "x_lo", "x_hi", "mu_lo", "mu_hi", "mu_s_free"),
                               math.nan), "n_bins": 0}
        try:
            b = ref if ref is not None and case is reference else bulk_amplitude(case, law)
            row.update({"A": b.A, "A_se": b.se, "n_bins": b.n, "x_lo": b.x_lo, "x_hi": b.x_hi,
                        "mu_lo": b.mu_lo, "mu_hi": b.mu_hi, "mu_s_free": b.mu_s_free})
        except ParameterError as e:
            row["why"] = str(e)
        row["u_rel_bulk"] = (
            velocity_misfit(case, solve("nonlocal", law, case, a_ref, "model", k), k,
                            rise_past_k=True)
            if math.isfinite(a_ref) and k < xi.size - 1 else math.nan)
        rows.append(row)
    return pl.DataFrame(rows, schema_overrides={"A": pl.Float64, "u_rel_bulk": pl.Float64})


@dataclass(frozen=True)
class Trend:
    """A weighted straight line A = a + slope (v - v_mean) through the runs' bulk amplitudes
    against ``against`` (W or phi_bar): the slope, its SE and their ratio ``z``; ``chi2_dof``
    of the runs about their weighted mean (about 1 if one A holds within the SEs)."""

    against: str
    slope: float
    se: float
    z: float
    mean: float
    mean_se: float
    chi2_dof: float


def trend(table: pl.DataFrame, against: str, least: int = 3) -> Trend:
    """Does the bulk amplitude trend with ``against`` ("W" or "phi_bar")? Weighted least
    squares over the rows of :func:`bulk_table` with an amplitude (or any table with ``A``,
    ``A_se`` and ``against``: points' replica means), at least ``least`` of them (2: the
    line through two points, its slope's SE from theirs alone)."""
    if against not in ("W", "phi_bar"):
        raise ParameterError(f"invalid against = {against!r}: allowed 'W' or 'phi_bar'")
    if not (isinstance(least, int) and least >= 2):
        raise ParameterError(f"invalid least = {least!r}: allowed an integer >= 2")
    t = table.filter(pl.col("A").is_not_null() & pl.col("A").is_not_nan())
    if t.height < least:
        raise ParameterError(f"invalid table: {t.height} rows with an amplitude, allowed "
                             f">= {least} for a trend")
    a, s, v = (t[c].to_numpy().astype(np.float64) for c in ("A", "A_se", against))
    w = 1.0 / s**2
    mean, mean_se = weighted_mean(a, s)
    chi2 = float(np.sum(w * (a - mean) ** 2)) / (a.size - 1)
    # (one value of ``against``: no slope. Tested on the values themselves: their weighted
    # mean's rounding leaves a centred sum of squares of ~1e-30 rather than 0, and whether it
    # is exactly 0 depends on the machine's summation order)
    if np.unique(v).size < 2:
        return Trend(against, math.nan, math.nan, math.nan, mean, mean_se, chi2)
    vc = v - np.sum(w * v) / np.sum(w)
    sxx = float(np.sum(w * vc * vc))
    if sxx <= 0:
        return Trend(against, math.nan, math.nan, math.nan, mean, mean_se, chi2)
    slope = float(np.sum(w * vc * (a - mean)) / sxx)
    se = sxx ** -0.5
    return Trend(against, slope, se, slope / se, mean, mean_se, chi2)


def layer_profile(case: ChannelCase, law: LocalLaw, A: float, A_layer: float) -> Profile:
    """The nonlocal model of ``case`` with the DEM's phi profile, boundary data at the wall
    bin, amplitude ``A`` in the bulk and ``A_layer`` in the wall layer (x < :data:`X_BULK`):
    the wall layer with a law of its own."""
    t = case.profile
    return solve_nonlocal_given_phi(law, A, case.problem(0), t["xi"].to_numpy(),
                                    t["phi"].to_numpy(), layer=(X_BULK, A_layer))


def fit_layer_amplitude(case: ChannelCase, law: LocalLaw, A: float) -> float:
    """The wall layer's amplitude that best fits ``case``'s whole velocity profile
    (:func:`granflow.continuum.channel_model.velocity_misfit`) with the bulk's ``A`` held
    (bounded search in log10, 0.01-3)."""
    from scipy.optimize import minimize_scalar

    r = minimize_scalar(lambda la: velocity_misfit(case, layer_profile(case, law, A, 10**la)),
                        bounds=(-2.0, 0.5), method="bounded", options={"xatol": 2e-3})
    return float(10**r.x)


def layer_table(cases: Sequence[ChannelCase], cal: Mapping[float, Calibration], A: float,
                reference: ChannelCase) -> pl.DataFrame:
    """The wall layer with its own amplitude, the bulk's ``A`` held everywhere: per run its
    own best layer amplitude and misfit, and the misfit with the layer amplitude fitted on
    ``reference`` held (whole-channel velocity misfits, the DEM's phi); ``u_rel_one`` the
    misfit with one amplitude, ``A``, in the layer too."""
    a_ref = fit_layer_amplitude(reference, law_for(reference, cal).law, A)
    rows = []
    for case in cases:
        law = law_for(case, cal).law
        a = a_ref if case is reference else fit_layer_amplitude(case, law, A)
        rows.append({
            "W": case.W, "phi_bar": case.phi_bar, "seed": case.seed, "A": A,
            "A_layer_ref": a_ref, "A_layer_best": a,
            "u_rel_one": velocity_misfit(case, layer_profile(case, law, A, A)),
            "u_rel_best": velocity_misfit(case, layer_profile(case, law, A, a)),
            "u_rel_held": velocity_misfit(case, layer_profile(case, law, A, a_ref))})
    return pl.DataFrame(rows)
