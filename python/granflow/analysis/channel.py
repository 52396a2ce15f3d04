"""Vertical-channel analysis (paper 000: Debnath, Kesava Rao & Kumaran, J. Fluid Mech. 2022):
the model curves (3.1), (3.2), (B3), (B4), (B13), the velocity scaling of §3.1, the zones of
§3.2, the rheology of appendix B and the run's :func:`summary`.

Geometry, units and errors as in :mod:`granflow.analysis.channel_profiles` (the flow state and
the profiles with jackknife errors, on which everything here is built): ``u`` is the velocity
along the flow, ``xi`` the distance from the nearest wall; every derived quantity has a
delete-one-block jackknife standard error over blocks of windows (NaN, not enough data, from
fewer than :data:`~granflow.analysis.stats.MIN_SE_BLOCKS` blocks). :func:`steady_check`
tests the steady part for a slow drift and measures its correlation times.

Columns used from the ``bins`` table (docs/columns.md): window, t0, t1, n_samples, bin, x_lo,
x_hi, x, phi, u_y, w_z, T, sigma_xx, sigma_xy, Gamma, shear_production (missing optional
columns give NaN results for the quantities that need them).  From ``series``: t, vcm_y and
the wall stresses wall{0,1}_sigma_{xx,xy}.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import polars as pl
from scipy import optimize
from scipy.stats import chi2 as chi2_law

from ._numerics import quiet
from .binned import bin_matrix, profile_se
from .channel_profiles import (
    RAW_COLUMNS,
    ChannelProfiles,
    flow_state,
    profiles,
)
from .estimate import Estimate
from .stats import (
    DRIFT_Z,
    MIN_SE_BLOCKS,
    Stationarity,
    blocking_many,
    choose_blocks,
    jackknife_se,
    mean_se,
    ratio_se,
    stationarity,
)
from .tables import FloatArray, TableLike, column, column_names, sample_interval

#: Volume fraction for arrested dynamics used by paper 000 for mu_p = 0.5 (section 1, 3.2).
PHI_AD = 0.587
#: Random close packing volume fraction used in fig. 11(b) / fig. 13 of paper 000.
PHI_RCP = 0.64
#: Parameters of (B3)/(B4) used for the dotted lines of fig. 11 (Jop 2015, quoted in 000 §3.2).
JOP2015: dict[str, float] = {
    "mu_s": 0.384,
    "mu_inf": 0.625,
    "I0": 0.3,
    "phi_min": 0.4,
    "phi_max": 0.6,
}
#: Conduction length reported in 000 §3.2 for the plug temperature (B13 fit), in d.
L_C_PAPER = 11.5


# --------------------------------------------------------------------------------------------
# model curves
# --------------------------------------------------------------------------------------------
@quiet
def scaled_profile_31(xi: npt.ArrayLike, delta: float) -> FloatArray:
    """Eq. (3.1): ``(u - u_slip)/(u_max - u_slip) = 1 - exp(-3 x / delta_0.95)``."""
    return 1.0 - np.exp(-3.0 * np.asarray(xi, dtype=np.float64) / delta)


@quiet
def velocity_profile_31(xi: npt.ArrayLike, u_slip: float, u_max: float, delta: float) -> FloatArray:
    """Eq. (3.1) solved for the velocity: ``u = u_slip + (u_max - u_slip)(1 - exp(-3x/delta))``."""
    return u_slip + (u_max - u_slip) * scaled_profile_31(xi, delta)


@quiet
def mean_velocity_32(u_slip: float, u_max: float, delta: float, W: float) -> float:
    """Eq. (3.2): ``ubar = u_max - 2 delta (u_max - u_slip)(1 - exp(-3W/(2 delta))) / (3W)``,
    the width average of (3.1) over 0 <= x <= W/2."""
    return u_max - 2.0 * delta * (u_max - u_slip) * (1.0 - math.exp(-1.5 * W / delta)) / (3.0 * W)


@quiet
def mu_B3(
    I: npt.ArrayLike,  # noqa: E741 - the paper's symbol
    mu_s: float = JOP2015["mu_s"],
    mu_inf: float = JOP2015["mu_inf"],
    I0: float = JOP2015["I0"],
) -> FloatArray:
    """Eq. (B3): ``mu(I) = mu_s + (mu_inf - mu_s) / (1 + I0 / I)`` (defaults: Jop 2015)."""
    ii = np.asarray(I, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return mu_s + (mu_inf - mu_s) / (1.0 + I0 / ii)


@quiet
def phi_B4(
    I: npt.ArrayLike,  # noqa: E741 - the paper's symbol
    phi_max: float = JOP2015["phi_max"],
    phi_min: float = JOP2015["phi_min"],
) -> FloatArray:
    """Eq. (B4): ``phi(I) = phi_max - (phi_max - phi_min) I`` (defaults: Jop 2015)."""
    return phi_max - (phi_max - phi_min) * np.asarray(I, dtype=np.float64)


@quiet
def conduction_profile_B13(xc: npt.ArrayLike, T_c: float, l_c: float) -> FloatArray:
    """Solution of (B13) with zero flux at the centre:
    ``T^{3/2}(xc) = T_c^{3/2} cosh(xc / l_c)``, i.e. ``T = T_c cosh(xc/l_c)^{2/3}``, where
    ``xc`` is the distance from the channel centre."""
    return T_c * np.cosh(np.asarray(xc, dtype=np.float64) / l_c) ** (2.0 / 3.0)



# velocity scaling (section 3.1)
# --------------------------------------------------------------------------------------------
def _u_slip(q: Mapping[str, FloatArray]) -> float:
    return float(q["u"][0])


def _u_max(q: Mapping[str, FloatArray]) -> float:
    # the half-profile bin nearest the centre (after folding: mean of the two central bins)
    return float(q["u"][-1])


def delta_095_profile(xi: FloatArray, q: Mapping[str, FloatArray]) -> float:
    """First distance from the wall where the scaled velocity reaches 0.95 (linear
    interpolation between bin centres)."""
    u = q["u"]
    s = (u - u[0]) / (u[-1] - u[0])
    above = np.flatnonzero(s >= 0.95)
    if above.size == 0:
        return float("nan")
    j = int(above[0])
    if j == 0:
        return float(xi[0])
    return float(np.interp(0.95, [s[j - 1], s[j]], [xi[j - 1], xi[j]]))


def _fit_scaled(xi: FloatArray, q: Mapping[str, FloatArray], W: float) -> tuple[float, float]:
    """One-parameter least-squares fit of (3.1) to the scaled profile: (delta, rms residual)."""
    u = q["u"]
    s = (u - u[0]) / (u[-1] - u[0])
    if not np.all(np.isfinite(s)):
        return float("nan"), float("nan")

    def cost(delta: float) -> float:
        return float(np.sum((s - scaled_profile_31(xi, delta)) ** 2))

    res = optimize.minimize_scalar(cost, bounds=(1e-3 * W, 2.0 * W), method="bounded")
    return float(res.x), float(math.sqrt(res.fun / s.size))


def _fit_full(
    xi: FloatArray, q: Mapping[str, FloatArray], sigma: FloatArray | None, p0: tuple[float, ...]
) -> FloatArray:
    """Three-parameter fit of (3.1) to u(xi): (u_slip, u_max, delta, rms residual)."""
    u = q["u"]
    ok = np.isfinite(u)
    if sigma is not None:
        ok &= np.isfinite(sigma) & (sigma > 0)
    if ok.sum() < 4:
        return np.full(4, np.nan)
    try:
        p, _ = optimize.curve_fit(
            velocity_profile_31,
            xi[ok],
            u[ok],
            p0=p0,
            sigma=None if sigma is None else sigma[ok],
            absolute_sigma=True,
            maxfev=20000,
        )
    except (RuntimeError, ValueError):
        return np.full(4, np.nan)
    rms = math.sqrt(float(np.mean((u[ok] - velocity_profile_31(xi[ok], *p)) ** 2)))
    return np.array([p[0], p[1], p[2], rms])


@quiet
def velocity_scaling(prof: ChannelProfiles) -> dict[str, Estimate]:
    """Section 3.1 quantities, each with a jackknife SE.

    * ``u_slip``: velocity of the wall bin (the paper's definition, "the velocity of the
      interval closest to the wall");
    * ``u_max``: velocity at the centre (half-profile bin nearest x = W/2);
    * ``u_max_over_u_slip`` (paper: 1.37-1.40);
    * ``delta_095``: distance from the wall (bin centres, linear interpolation) where
      ``(u - u_slip)/(u_max - u_slip)`` first reaches 0.95.  As in the paper, x is measured
      from the wall while u_slip is the velocity of the wall bin (centre at 0.75 d for a 1.5 d
      bin), so a profile that is exactly (3.1) from the wall gives a delta_095 somewhat larger
      than its delta; the three-parameter fit below is free of that offset;
    * ``residual_31``: RMS of scaled data minus (3.1) with that delta (no free parameter, as in
      fig. 4b); ``delta_fit_scaled`` / ``residual_31_fit``: one-parameter least-squares fit of
      (3.1) to the scaled profile and its RMS residual;
    * ``u_slip_fit``, ``u_max_fit``, ``delta_fit``, ``residual_fit``: three-parameter fit of
      (3.1) to u(xi) weighted by the per-bin SE (xi measured from the wall, so ``u_slip_fit`` is
      the extrapolated velocity at the wall itself);
    * ``mean_velocity``: width average of the full-channel profile; ``mean_velocity_32``: (3.2)
      from (u_slip, u_max, delta_095, W); ``mean_velocity_ratio`` = measured / (3.2).
    """
    xi, W = prof.xi, prof.W
    tab = prof.table()
    u_se = tab["u_se"].to_numpy()
    sigma = u_se if np.all(np.isfinite(u_se) & (u_se > 0)) else None
    q0 = prof.derived()
    d0 = delta_095_profile(xi, q0)
    p0 = (_u_slip(q0), _u_max(q0), max(d0, 1e-3 * W) if np.isfinite(d0) else 0.2 * W)
    width = prof.width_full

    def fn(q: Mapping[str, FloatArray]) -> FloatArray:
        us, um = _u_slip(q), _u_max(q)
        dl = delta_095_profile(xi, q)
        res31 = (
            float(np.sqrt(np.mean(((q["u"] - us) / (um - us) - scaled_profile_31(xi, dl)) ** 2)))
            if np.isfinite(dl)
            else float("nan")
        )
        dfit, rfit = _fit_scaled(xi, q, W)
        full = _fit_full(xi, q, sigma, p0)
        return np.array([us, um, um / us, dl, res31, dfit, rfit, *full])

    names = [
        "u_slip",
        "u_max",
        "u_max_over_u_slip",
        "delta_095",
        "residual_31",
        "delta_fit_scaled",
        "residual_31_fit",
        "u_slip_fit",
        "u_max_fit",
        "delta_fit",
        "residual_fit",
    ]
    val, se = prof.estimate(fn)
    out = {k: Estimate(float(val[i]), float(se[i])) for i, k in enumerate(names)}

    # mean velocity: needs the full-channel u, so jackknife on the raw means directly
    def mean_u(m: Mapping[str, FloatArray]) -> FloatArray:
        u = prof.sign * np.asarray(m["u_y"])
        q = prof.derived(m)
        measured = float(np.sum(u * width) / np.sum(width))
        dl = delta_095_profile(xi, q)
        pred = mean_velocity_32(_u_slip(q), _u_max(q), dl, W) if np.isfinite(dl) else np.nan
        return np.array([measured, pred, measured / pred])

    v0 = mean_u(prof.full)
    reps = [mean_u({k: v[i] for k, v in prof.loo.items()}) for i in range(prof.n_blocks)]
    s0 = jackknife_se(v0, reps)
    for i, k in enumerate(["mean_velocity", "mean_velocity_32", "mean_velocity_ratio"]):
        out[k] = Estimate(float(v0[i]), float(s0[i]))
    return out


# --------------------------------------------------------------------------------------------
# zones (section 3.2)
# --------------------------------------------------------------------------------------------
@dataclass
class Zones:
    """The four zones of paper 000 §3.2 on the half profile.

    * wall shearing zone: bins whose centre is within ``wall_width`` (default 2 d) of the wall;
    * plug: contiguous bins around the centre where ``|du/dx|`` is zero within ``z`` standard
      errors: scanning outward from the centre, the plug ends where ``min_run`` consecutive
      bins (default 2) have ``|du/dx| > z SE`` (a single 2-sigma excursion is expected among
      tens of plug bins; real shear, growing monotonically toward the wall, stays
      significant);
    * between them: dense shearing zone where phi >= phi_ad, loose shearing zone where
      phi < phi_ad, separated at the first crossing of phi = phi_ad met going outward from the
      plug (linear interpolation; none if phi stays >= phi_ad outside the wall zone, as for
      phi_bar = 0.62 in the paper).

    Without an SE of du/dx (fewer than MIN_SE_BLOCKS blocks) the plug is undetermined:
    no plug bins, ``xi_plug`` NaN.

    ``xi_plug`` is the plug edge (between the last plug bin and the first sheared one),
    ``xi_ad`` the dense/loose boundary (Estimate, jackknife SE) and ``xi_wall`` the outer edge
    of the wall zone.
    """

    labels: list[str]
    xi_wall: float
    xi_ad: Estimate
    xi_plug: float
    phi_plug: Estimate
    plug_bins: npt.NDArray[np.int64]


def _crossing(xi: FloatArray, phi: FloatArray, i_from: int, i_to: int, phi_ad: float) -> float:
    """Walk from index i_from down to i_to (outward) and return the interpolated position of
    the first bin with phi < phi_ad; NaN if none."""
    for j in range(i_from, i_to - 1, -1):
        if phi[j] < phi_ad:
            if j + 1 >= xi.size or not phi[j + 1] >= phi_ad:
                return float(xi[j])
            return float(np.interp(phi_ad, [phi[j], phi[j + 1]], [xi[j], xi[j + 1]]))
    return float("nan")


@quiet
def zones(
    prof: ChannelProfiles,
    *,
    phi_ad: float = PHI_AD,
    wall_width: float = 2.0,
    z: float = 2.0,
    min_run: int = 2,
) -> Zones:
    """Split the half profile into plug / dense / loose / wall shearing zones (:class:`Zones`)."""
    tab = prof.table()
    xi = prof.xi
    nb = xi.size
    gd = tab["gamma_dot"].to_numpy()
    gd_se = tab["gamma_dot_se"].to_numpy()
    wall = xi <= wall_width * prof.d
    n_wall = int(wall.sum())
    j = nb - 1
    if not np.any(np.isfinite(gd_se)):
        # no SE of the shear rate (too few blocks): zero shear cannot be told from shear, the
        # plug is undetermined (no plug bins, xi_plug NaN) and phi_ad is sought from the centre
        plug_bins = np.zeros(0, dtype=np.int64)
        xi_plug = float("nan")
    else:
        sig = np.abs(gd) > z * np.where(np.isfinite(gd_se), gd_se, 0.0)
        # plug: from the centre outward until min_run consecutive bins show significant shear
        # (j = innermost bin of that run; the run may be cut short by the wall zone)
        while j >= n_wall and not np.all(sig[max(j - min_run + 1, n_wall) : j + 1]):
            j -= 1
        plug_bins = np.arange(j + 1, nb, dtype=np.int64)
        if plug_bins.size:
            xi_plug = float(prof.xi_lo[plug_bins[0]])
        else:
            xi_plug = float(prof.xi_hi[-1])
    i_from = j  # first sheared bin from the centre
    i_to = n_wall

    def cross(q: Mapping[str, FloatArray]) -> float:
        if i_from < i_to:
            return float("nan")
        return _crossing(xi, q["phi"], i_from, i_to, phi_ad)

    xa, xa_se = prof.estimate(cross)
    labels: list[str] = []
    in_plug = set(plug_bins.tolist())
    for b in range(nb):
        if wall[b]:
            labels.append("wall")
        elif b in in_plug:
            labels.append("plug")
        elif np.isfinite(xa) and xi[b] < xa:
            labels.append("loose")
        else:
            labels.append("dense")
    if plug_bins.size:
        pv, ps = prof.estimate(lambda q: float(np.mean(q["phi"][plug_bins])))
    else:
        pv, ps = float("nan"), float("nan")
    xi_wall = float(prof.xi_hi[n_wall - 1]) if n_wall else 0.0
    return Zones(
        labels,
        xi_wall,
        Estimate(float(xa), float(xa_se)),
        xi_plug,
        Estimate(float(pv), float(ps)),
        plug_bins,
    )


# --------------------------------------------------------------------------------------------
# rheology in the channel (appendix B)
# --------------------------------------------------------------------------------------------
@quiet
def conduction_length(prof: ChannelProfiles, zn: Zones, *, min_bins: int = 3) -> dict[str, Any]:
    """Fit (B13) to the plug temperature: ``T = T_c cosh((W/2 - xi)/l_c)^{2/3}`` (zero flux at
    the centre), weighted by the per-bin SE of T; jackknife SEs of ``l_c`` and ``T_c``.

    Paper 000 §3.2 finds ``l_c ~ 11.5 d``.  Returns l_c, T_c (Estimates), chi2_per_dof, n_bins
    and ``at_bound`` (True if l_c ran into the upper bound: T flat, l_c undetermined).
    """
    idx = zn.plug_bins
    tab = prof.table()
    T_se = tab["T_se"].to_numpy()
    if idx.size < min_bins:
        nan = Estimate(float("nan"), float("nan"))
        return {
            "l_c": nan,
            "T_c": nan,
            "chi2_per_dof": float("nan"),
            "n_bins": int(idx.size),
            "at_bound": False,
        }
    xc = 0.5 * prof.W - prof.xi[idx]
    sig = T_se[idx]
    sig = np.where(np.isfinite(sig) & (sig > 0), sig, np.nanmax(np.abs(tab["T"].to_numpy())))
    upper = 1e3 * prof.W

    def fit(q: Mapping[str, FloatArray]) -> FloatArray:
        T = q["T"][idx]
        if not np.all(np.isfinite(T)) or np.all(T <= 0):
            return np.full(3, np.nan)
        p0 = (float(T[-1]), 10.0 * prof.d)
        try:
            p, _ = optimize.curve_fit(
                conduction_profile_B13,
                xc,
                T,
                p0=p0,
                sigma=sig,
                absolute_sigma=True,
                bounds=([0.0, 1e-3], [np.inf, upper]),
                maxfev=20000,
            )
        except (RuntimeError, ValueError):
            return np.full(3, np.nan)
        chi2 = float(np.sum(((T - conduction_profile_B13(xc, *p)) / sig) ** 2))
        return np.array([p[0], p[1], chi2 / max(1, T.size - 2)])

    val, se = prof.estimate(fit)
    return {
        "l_c": Estimate(float(val[1]), float(se[1])),
        "T_c": Estimate(float(val[0]), float(se[0])),
        "chi2_per_dof": float(val[2]),
        "n_bins": int(idx.size),
        "at_bound": bool(np.isfinite(val[1]) and val[1] > 0.99 * upper),
    }


@quiet
def rheology_table(prof: ChannelProfiles, zn: Zones) -> pl.DataFrame:
    """Per-bin mu(I), phi(I) and kinetic-theory coefficients with SEs, the zone label, and
    the (B3)/(B4) curves at the measured I (fig. 11, fig. 13)."""
    tab = prof.table()
    cols = [
        "xi",
        "I",
        "I_se",
        "mu",
        "mu_se",
        "phi",
        "phi_se",
        "p_phi",
        "p_phi_se",
        "mu_phi",
        "mu_phi_se",
        "D_phi",
        "D_phi_se",
        "omega_ratio",
        "omega_ratio_se",
        "gamma_over_sqrtT",
        "gamma_over_sqrtT_se",
    ]
    out = tab.select(cols).with_columns(pl.Series("zone", zn.labels))
    inum = out["I"].to_numpy()
    return out.with_columns(
        pl.Series("mu_B3", mu_B3(inum)),
        pl.Series("phi_B4", phi_B4(inum)),
        pl.Series("rcp_minus_phi", PHI_RCP - out["phi"].to_numpy()),
    )


@quiet
def omega_ratio_in_zones(
    prof: ChannelProfiles, zn: Zones, which: tuple[str, ...] = ("dense", "loose")
) -> Estimate:
    """``Omega_z / (du_y/dx)`` over the bins of the given zones, as the least-squares slope of
    Omega_z against du_y/dx through the origin, ``sum(Omega_z du_y/dx) / sum((du_y/dx)^2)``
    (a plain mean of per-bin ratios is dominated by the bins where du_y/dx -> 0).  Expected 1/2
    where the particles rotate with the material: ``Omega_z = omega_z / 2`` with the vorticity
    ``omega_z = du_y/dx`` of this unidirectional flow (paper 000 §3.2, fig. 9a)."""
    idx = np.array([i for i, lab in enumerate(zn.labels) if lab in which], dtype=np.int64)
    if idx.size == 0:
        return Estimate(float("nan"), float("nan"))

    def slope(q: Mapping[str, FloatArray]) -> float:
        g, w = q["du_y_dx"][idx], q["w_z"][idx]
        return float(np.sum(w * g) / np.sum(g * g))

    v, s = prof.estimate(slope)
    return Estimate(float(v), float(s))


@quiet
def wall_friction(series: TableLike, t_start: float) -> Estimate:
    """Wall friction coefficient ``|<sigma_xy>| / |<sigma_xx>|`` (fig. 7b) from the wall
    stresses of the ``series`` table, both walls combined, blocking SE of the ratio."""
    names = column_names(series)
    need = [f"wall{w}_sigma_{c}" for w in (0, 1) for c in ("xx", "xy")]
    if not all(n in names for n in need):
        return Estimate(float("nan"), float("nan"))
    t = column(series, "t")
    keep = t >= t_start
    cols = {n: column(series, n)[keep] for n in need}
    num = 0.5 * sum(
        np.sign(np.mean(cols[f"wall{w}_sigma_xy"])) * cols[f"wall{w}_sigma_xy"] for w in (0, 1)
    )
    den = 0.5 * sum(
        np.sign(np.mean(cols[f"wall{w}_sigma_xx"])) * cols[f"wall{w}_sigma_xx"] for w in (0, 1)
    )
    r = ratio_se(num, den, sample_interval(t[keep]))
    return Estimate(abs(r.value), r.se)


#: the columns of the ``bins`` and ``series`` tables that :func:`summary` reads (a campaign
#: keeps only these between sessions: granflow.studies.reproduce_000.ChannelStudy.kept_tables)
BINS_READ = ("window", "t0", "t1", "n_samples", "bin", "x_lo", "x_hi", "x", *RAW_COLUMNS)
SERIES_READ = ("t", "vcm_y", *(f"wall{w}_sigma_{c}" for w in (0, 1) for c in ("xx", "xy")))


#: the reported quantities (one value per window of the bins table) whose drift across the
#: steady part makes a channel run "drifting" and whose slowest correlation time sets a campaign
#: run's minimum length: u_slip, u_max, the width-averaged velocity and the mean sigma_xx
STEADY_QUANTITIES = ("u_slip", "u_max", "mean_velocity", "sigma_xx_mean")


@dataclass(frozen=True)
class SteadyCheck:
    """Is a channel run's steady part stationary, and how long are its correlations?
    (:func:`steady_check`)

    Attributes
    ----------
    stationarity
        The thirds test (:func:`granflow.analysis.stats.stationarity`) of STEADY_QUANTITIES
        per window.
    tau
        Per quantity: its integrated correlation time (blocking of the window series), in
        time units.
    tau_max
        The largest of ``tau`` (NaN if any is not finite).
    """

    stationarity: Stationarity
    tau: dict[str, float]
    tau_max: float

    @property
    def drifting(self) -> bool:
        """Tested and not stationary: a quantity drifts across the steady part."""
        return self.stationarity.tested and not self.stationarity.stationary


def window_quantities(prof: ChannelProfiles) -> dict[str, FloatArray]:
    """The STEADY_QUANTITIES of each steady window of ``prof`` (as :func:`velocity_scaling`
    and :func:`summary` define them on the averages), a series per quantity: what
    :func:`steady_check` tests for drift and takes its correlation times from."""
    width = prof.width_full

    def fn(m: Mapping[str, FloatArray]) -> FloatArray:
        q = prof.derived(m)
        u = prof.sign * np.asarray(m["u_y"])
        return np.array([_u_slip(q), _u_max(q), float(np.sum(u * width) / np.sum(width)),
                         float(np.mean(q["sigma_xx"]))])

    ser = prof.window_series(fn)
    if ser.ndim != 2:
        ser = np.zeros((0, len(STEADY_QUANTITIES)))
    return {k: ser[:, j] for j, k in enumerate(STEADY_QUANTITIES)}


@quiet
def steady_check(prof: ChannelProfiles, *, z_max: float = DRIFT_Z) -> SteadyCheck:
    """The thirds test and the correlation times of the STEADY_QUANTITIES of ``prof``'s steady
    windows (:class:`SteadyCheck`): a run whose thirds differ by more than ``z_max`` of their
    SEs drifts (the flow_state trend test sees only |v_cm| over the last half)."""
    ser = window_quantities(prof)
    st = stationarity(ser, z_max=z_max)
    n = min(v.size for v in ser.values())
    tau = {k: math.nan for k in ser}
    if n >= 2:
        res = blocking_many(np.column_stack([ser[k] for k in ser]), dt=prof.window_dt)
        tau = {k: float(t) for k, t in zip(ser, res.tau, strict=True)}
    tmax = max(tau.values()) if all(math.isfinite(t) for t in tau.values()) else math.nan
    return SteadyCheck(st, tau, tmax)


#: the shape of the velocity profile (§3.1): the profile over itself. The flow's level (the
#: plug's speed and the mean velocity) has a slow mode of its own (it relaxes against the
#: shear zones' drag over hundreds of time units at W >= 60: benchmarks/NOTES.md), which
#: sets the run's jackknife blocks (:func:`profiles`: on the mean velocity) and leaves a
#: capped run too few of them for any SE; the shape moves with the level far less, so it
#: gets an SE on blocks of its own correlation time (:func:`own_blocked`)
SHAPE_QUANTITIES = ("u_max_over_u_slip", "delta_095")


def _shape(xi: FloatArray, q: Mapping[str, FloatArray]) -> FloatArray:
    """SHAPE_QUANTITIES of the derived half profile ``q`` (as :func:`velocity_scaling`)."""
    return np.array([_u_max(q) / _u_slip(q), delta_095_profile(xi, q)])


@dataclass(frozen=True)
class OwnBlocked:
    """A quantity's value and jackknife SE over blocks of its own correlation time
    (:func:`own_blocked`).

    Attributes
    ----------
    estimate
        The value (the steady part's profile, less the windows a whole number of blocks
        leaves out) and its SE: NaN unless ``n_blocks >= MIN_SE_BLOCKS``, the quantity's
        blocking reached its plateau (``tau`` is a measurement, not a lower bound) and its
        own thirds test passes (``drift_z <= DRIFT_Z``).
    tau
        Its integrated correlation time (blocking of its window series), in time units.
    n_blocks
        Blocks of at least its statistical inefficiency the steady part holds (at most 32).
    drift_z
        |z| of its own thirds test (NaN: too short to test).
    """

    estimate: Estimate
    tau: float
    n_blocks: int
    drift_z: float


@quiet
def own_blocked(bins: TableLike, start_time: float, *,
                max_blocks: int = 32) -> dict[str, OwnBlocked]:
    """SHAPE_QUANTITIES of the steady part of ``bins`` (windows from ``start_time``), each on
    jackknife blocks as long as its own statistical inefficiency (:class:`OwnBlocked`), not
    the mean velocity's as :func:`profiles` chooses them for every other quantity. Longer
    blocks than a quantity needs are valid too (fewer of them), so this matters only where
    the run's blocks are too few for an SE."""
    base = profiles(bins, start_time=start_time)
    ser = base.window_series(lambda m: _shape(base.xi, base.derived(m)))
    names = SHAPE_QUANTITIES
    if ser.ndim != 2 or ser.shape[0] < 2:
        return {k: OwnBlocked(Estimate(math.nan, math.nan), math.nan, 0, math.nan)
                for k in names}
    res = blocking_many(ser, dt=base.window_dt)
    st = stationarity({k: ser[:, j] for j, k in enumerate(names)})
    out: dict[str, OwnBlocked] = {}
    by_nb: dict[int, ChannelProfiles] = {}
    for j, k in enumerate(names):
        _, nb = choose_blocks(ser.shape[0], float(res.g[j]), max_blocks)
        nb = max(2, nb)
        if nb not in by_nb:
            by_nb[nb] = profiles(bins, start_time=start_time, n_blocks=nb)
        p = by_nb[nb]
        xi = p.xi
        val, se = p.estimate(lambda q, xi=xi: _shape(xi, q))  # type: ignore[misc]
        z = abs(st.z[k]) if st.tested else math.nan
        ok = (nb >= MIN_SE_BLOCKS and bool(res.converged[j]) and math.isfinite(z)
              and z <= DRIFT_Z)
        out[k] = OwnBlocked(Estimate(float(val[j]), float(se[j]) if ok else math.nan),
                            float(res.tau[j]), int(nb), z)
    return out


@quiet
def summary(
    bins: TableLike,
    series: TableLike | None = None,
    *,
    start_time: float | None = None,
    symmetrise: bool = True,
    n_blocks: int | None = None,
    phi_ad: float = PHI_AD,
    wall_width: float = 2.0,
    d: float = 1.0,
    rho_p: float = 1.0,
) -> dict[str, Any]:
    """Everything of paper 000 §3 for one run, with standard errors.

    Keys (a scalar with its error is an :class:`~granflow.analysis.estimate.Estimate`):

    * ``flow_state`` (dict, from ``series``), ``steady`` (t_start, n_windows, n_blocks,
      block_len, folded, W);
    * the section 3.1 numbers of :func:`velocity_scaling`;
    * ``vcm`` (mean |vcm_y| over the steady samples, mass-weighted mean velocity, blocking SE),
      ``wall_friction``, ``sigma_xx_mean`` and ``sigma_xx_rel_spread`` (max |deviation| /
      mean over bins: should be ~0 by (B1));
    * ``zones`` (xi_wall, xi_ad, xi_plug, phi_plug, labels);
    * ``omega_ratio_shearing`` (dense + loose zones), ``conduction`` ((B13) fit);
    * ``profile`` (polars DataFrame: half profile, all derived quantities with ``_se`` and a
      ``zone`` column), ``rheology`` (:func:`rheology_table`), ``profile_errors``
      (whole-profile relative errors of u_y, phi, T from :func:`binned.profile_se`).
    """
    prof = profiles(
        bins,
        series,
        start_time=start_time,
        symmetrise=symmetrise,
        n_blocks=n_blocks,
        d=d,
        rho_p=rho_p,
    )
    out: dict[str, Any] = {}
    if series is not None and "vcm_y" in column_names(series):
        out["flow_state"] = asdict(flow_state(series))
        t = column(series, "t")
        keep = t >= prof.t_start
        ms = mean_se(np.abs(column(series, "vcm_y"))[keep], sample_interval(t[keep]))
        out["vcm"] = ms
        out["wall_friction"] = wall_friction(series, prof.t_start)
    out["steady"] = {
        "t_start": prof.t_start,
        "n_windows": prof.n_windows,
        "n_blocks": prof.n_blocks,
        "block_len": prof.block_len,
        "folded": prof.folded,
        "W": prof.W,
    }
    for k, v in velocity_scaling(prof).items():
        out[k] = v
    sv, ss = prof.estimate(lambda q: float(np.mean(q["sigma_xx"])))
    out["sigma_xx_mean"] = Estimate(float(sv), float(ss))
    sxx = prof.derived()["sigma_xx"]
    out["sigma_xx_rel_spread"] = float(np.nanmax(np.abs(sxx - sv)) / abs(sv)) if sv else np.nan
    zn = zones(prof, phi_ad=phi_ad, wall_width=wall_width)
    out["zones"] = {
        "xi_wall": zn.xi_wall,
        "xi_ad": zn.xi_ad,
        "xi_plug": zn.xi_plug,
        "phi_plug": zn.phi_plug,
        "labels": zn.labels,
    }
    out["omega_ratio_shearing"] = omega_ratio_in_zones(prof, zn)
    cond = conduction_length(prof, zn)
    out["conduction"] = dict(cond)
    out["profile"] = prof.table().with_columns(pl.Series("zone", zn.labels))
    out["rheology"] = rheology_table(prof, zn)
    bm = bin_matrix(bins, ["u_y"])
    tw = bm.t0 if np.all(np.isfinite(bm.t0)) else bm.t_mid
    start_window = int(np.sum(tw < prof.t_start - 1e-9 * max(1.0, abs(prof.t_start))))
    pe = profile_se(
        bins, [c for c in ("u_y", "phi", "T") if c in column_names(bins)], start_window=start_window
    )
    out["profile_errors"] = pe.whole
    return out


@quiet
def zone_means(
    prof: ChannelProfiles, zn: Zones, keys: tuple[str, ...] = ("phi", "u", "abs_dudx", "T")
) -> dict[str, dict[str, Estimate]]:
    """Mean of each half-profile quantity in ``keys`` over the bins of each zone (plug, dense,
    loose, wall), weighted by bin width, with its jackknife SE (the bins of a zone are
    correlated: their mean is re-averaged per jackknife replicate, not combined per bin).
    The quantities compared across k_n in 000 fig. 10."""
    width = prof.xi_hi - prof.xi_lo
    out: dict[str, dict[str, Estimate]] = {}
    for zone in ("plug", "dense", "loose", "wall"):
        idx = np.array([i for i, lab in enumerate(zn.labels) if lab == zone], dtype=np.int64)
        if idx.size == 0:
            continue
        w = width[idx] / np.sum(width[idx])

        def mean(q: Mapping[str, FloatArray], idx: npt.NDArray[np.int64] = idx,
                 w: FloatArray = w) -> FloatArray:
            return np.array([float(np.sum(w * q[k][idx])) for k in keys])

        v, s = prof.estimate(mean)
        out[zone] = {k: Estimate(float(v[j]), float(s[j])) for j, k in enumerate(keys)}
    return out


@quiet
def fit_phi_ad(phi: npt.ArrayLike, y: npt.ArrayLike, y_se: npt.ArrayLike) -> dict[str, float]:
    """Fit ``y = A / (phi_ad - phi)`` (000 fig. 13: the kinetic coefficients p_phi, mu_phi,
    D_phi of the loose shearing zone diverge as chi = (phi_ad - phi)^-1; the paper finds
    phi_ad = 0.59 +- 0.002) to loose-zone bins, in log y (the coefficients span decades)
    weighted by the per-bin relative SE. Returns phi_ad, its SE (covariance scaled by
    sqrt(chi2/dof) where that exceeds 1), A, chi2_per_dof, chi2_p (the chance of a chi2 this
    large were the form right: a small one says the form does not describe the bins) and n;
    NaN with fewer than 3 bins."""
    ph = np.asarray(phi, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    ee = np.asarray(y_se, dtype=np.float64)
    ok = np.isfinite(ph) & np.isfinite(yy) & (yy > 0) & np.isfinite(ee) & (ee > 0)
    ph, yy, ee = ph[ok], yy[ok], ee[ok]
    nan = {"phi_ad": math.nan, "phi_ad_se": math.nan, "A": math.nan,
           "chi2_per_dof": math.nan, "chi2_p": math.nan, "n": int(ph.size)}
    if ph.size < 3:
        return nan
    sig = ee / yy

    def model(p: FloatArray, log_a: float, phi_ad: float) -> FloatArray:
        return log_a - np.log(np.maximum(phi_ad - p, 1e-12))

    lo = float(np.max(ph)) + 1e-6
    try:
        popt, pcov = optimize.curve_fit(
            model, ph, np.log(yy), p0=(float(np.log(np.median(yy) * 0.01)), lo + 0.005),
            sigma=sig, absolute_sigma=True, bounds=([-np.inf, lo], [np.inf, PHI_RCP]),
            maxfev=20000)
    except (RuntimeError, ValueError):
        return nan
    chi2 = float(np.sum(((np.log(yy) - model(ph, *popt)) / sig) ** 2))
    dof = max(1, ph.size - 2)
    scale = math.sqrt(max(1.0, chi2 / dof))
    return {"phi_ad": float(popt[1]), "phi_ad_se": float(math.sqrt(pcov[1, 1]) * scale),
            "A": float(math.exp(popt[0])), "chi2_per_dof": chi2 / dof,
            "chi2_p": float(chi2_law.sf(chi2, dof)), "n": int(ph.size)}
