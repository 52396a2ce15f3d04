"""Vertical-channel profiles (paper 000: Debnath, Kesava Rao & Kumaran, J. Fluid Mech. 2022):
the flow state from the centre-of-mass velocity, and the steady profiles across the channel
(folded about the centre) with jackknife standard errors. :mod:`granflow.analysis.channel`
builds the paper's figures on them.

Geometry and units: walls at x = 0 and x = W, gravity along -y, so the material flows in -y and
``u_y < 0``.  Lengths in d, velocities in sqrt(g d), stresses in rho_p g d (rho_p = d = g = 1).
Throughout, ``u`` is the velocity *along the flow* (``u = -u_y`` for flow in -y; the sign is
detected from the data), ``xi`` is the distance from the nearest wall and ``gamma_dot = du/dxi``
(positive in the shear layers).  The paper's ``du_y/dx`` keeps its sign in ``du_y_dx`` (profile
across the whole channel, or the wall-0 half after folding).

Errors: profiles are averaged over the windows of the steady part.  Each derived quantity
(profiles, u_slip, delta_0.95, fits, zone boundaries, ...) is computed from window-averaged raw
columns and its standard error comes from a delete-one-block jackknife over ``n_blocks``
contiguous blocks of windows; the block length is at least the statistical inefficiency g (in
windows) of the spatially averaged flow velocity, so that blocks are nearly independent
(:func:`granflow.analysis.stats.choose_blocks`). A steady part shorter than MIN_SE_BLOCKS
such blocks gives no SE (NaN: not enough data; :attr:`ChannelProfiles.enough_blocks` False)
rather than one from a few degrees of freedom.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import polars as pl

from granflow.errors import ParameterError
from granflow.states import FlowState

from ._numerics import quiet
from .binned import BinMatrix, bin_matrix, window_steady_start
from .stats import (
    MIN_SE_BLOCKS,
    SteadyStart,
    block_means,
    blocking,
    choose_blocks,
    jackknife_se,
    steady_state_start,
    trend,
)
from .tables import FloatArray, TableLike, column, column_names

RAW_COLUMNS = (
    "phi",
    "u_y",
    "w_z",
    "T",
    "sigma_xx",
    "sigma_xy",
    "sigma_yy",
    "sigma_zz",
    "Gamma",
    "shear_production",
    "count",
)
# quantities that change sign under x -> W - x (folded antisymmetrically)
_ANTISYMMETRIC = {"du_y_dx", "w_z", "sigma_xy"}


# --------------------------------------------------------------------------------------------
# flow state from the centre-of-mass velocity
# --------------------------------------------------------------------------------------------
#: 000's smallest channel (W = 60 d: 1.7e5 particles), for which its 1 % steadiness threshold
#: on the centre-of-mass velocity's fluctuation was set (§2)
N_REF_000 = 1.7e5


@dataclass
class ChannelState:
    """Classification of the centre-of-mass velocity series: ``state`` a
    :class:`granflow.states.FlowState`.

    The last ``tail_fraction`` of the series is examined; ``v = |vcm_y|`` along the flow.

    1. ``arrested``: ``max |v| < v_arrest sqrt(g d)`` on the tail.
    2. ``accelerating`` / ``decelerating``: the fitted slope of ``v(t)`` is significant
       (``|t_stat| > t_sig``, slope SE corrected for serial correlation) and either
       ``|slope| > accel_fraction g`` or the relative drift across the tail
       ``|slope| T_tail / v_mean`` exceeds ``max_rel_drift``.  (``decelerating`` is an extra
       state for a flow slowing down, e.g. on its way to arrest: not steady either.)
    3. ``fluctuating``: relative fluctuation amplitude ``(p95 - p5) / (2 v_mean)`` above
       ``max_rel_amplitude`` (paper 000 §3.1 / fig. 3: < 1 % variation is steady, 1-2 % at
       phi_bar = 0.62 is fluctuating). 000 set 1 % for 1.7-4.1e5 particles; the centre-of-mass
       velocity of N particles fluctuates as N^-1/2, so given ``n_particles`` the threshold is
       ``max_rel_amplitude sqrt(N_REF_000 / n_particles)`` (N_REF_000 = 1.7e5, 000's smallest
       channel: 6.1 % at N = 4500, 1 % at 000's size).
    4. ``steady`` otherwise.
    """

    state: FlowState
    v_mean: float
    v_std: float
    rel_amplitude: float
    slope: float
    slope_se: float
    t_stat: float
    rel_drift: float
    t_tail_start: float
    thresholds: dict[str, float] = field(default_factory=dict)

    @property
    def is_steady(self) -> bool:
        """True for 'steady' and 'fluctuating' (a statistically stationary flow)."""
        return self.state in (FlowState.STEADY, FlowState.FLUCTUATING)


@quiet
def flow_state(
    series: TableLike,
    *,
    column_name: str = "vcm_y",
    tail_fraction: float = 0.5,
    g: float = 1.0,
    d: float = 1.0,
    v_arrest: float = 1e-3,
    max_rel_amplitude: float = 0.01,
    accel_fraction: float = 0.01,
    max_rel_drift: float = 0.05,
    t_sig: float = 3.0,
    n_particles: int | None = None,
) -> ChannelState:
    """Classify a channel run as steady, fluctuating, arrested, accelerating or decelerating
    (a :class:`granflow.states.FlowState`) from its centre-of-mass velocity (criteria in
    :class:`ChannelState`).

    Parameters
    ----------
    series
        Channel ``series`` table (needs ``t`` and ``column_name``) or a mapping.
    tail_fraction
        Fraction of the series (at its end) that is examined.
    g, d
        Gravity and particle diameter (velocity scale ``sqrt(g d)``).
    v_arrest, max_rel_amplitude, accel_fraction, max_rel_drift, t_sig
        Thresholds (see :class:`ChannelState`).
    n_particles
        The channel's particle count: scales ``max_rel_amplitude`` as N^-1/2 from 000's
        (:class:`ChannelState`); None keeps it as given.
    """
    if n_particles is not None:
        if not n_particles > 0:
            raise ParameterError(f"invalid n_particles = {n_particles!r}: allowed an integer "
                                 "> 0, or None")
        max_rel_amplitude *= math.sqrt(N_REF_000 / n_particles)
    t = column(series, "t")
    v = np.abs(column(series, column_name))
    n = t.size
    i0 = int(math.floor((1.0 - tail_fraction) * n))
    tt, vv = t[i0:], v[i0:]
    thr = {
        "v_arrest": v_arrest * math.sqrt(g * d),
        "max_rel_amplitude": max_rel_amplitude,
        "accel": accel_fraction * g,
        "max_rel_drift": max_rel_drift,
        "t_sig": t_sig,
    }
    tr = trend(tt, vv)
    vmean = float(np.mean(vv)) if vv.size else np.nan
    p5, p95 = np.percentile(vv, [5, 95]) if vv.size else (np.nan, np.nan)
    amp = float((p95 - p5) / (2.0 * vmean)) if vmean > 0 else np.inf
    if vv.size == 0:
        state = FlowState.ARRESTED
    elif float(np.max(vv)) < thr["v_arrest"]:
        state = FlowState.ARRESTED
    elif abs(tr.t_stat) > t_sig and (
        abs(tr.slope) > thr["accel"] or abs(tr.rel_drift) > max_rel_drift
    ):
        state = FlowState.ACCELERATING if tr.slope > 0 else FlowState.DECELERATING
    elif amp > max_rel_amplitude:
        state = FlowState.FLUCTUATING
    else:
        state = FlowState.STEADY
    return ChannelState(
        state,
        vmean,
        float(np.std(vv)) if vv.size else np.nan,
        amp,
        tr.slope,
        tr.slope_se,
        tr.t_stat,
        tr.rel_drift,
        float(tt[0]) if tt.size else np.nan,
        thr,
    )




# profiles with jackknife errors
# --------------------------------------------------------------------------------------------
@dataclass
class ChannelProfiles:
    """Window-averaged channel profiles of the steady part, with jackknife machinery.

    ``derived(m)`` maps raw column means ``m`` (full channel) to the half-profile quantities
    (folded about the centre line if ``folded``, else the wall-0 half x <= W/2); ``estimate(fn)``
    returns ``fn(derived)`` and its delete-one-block jackknife SE.

    Half-profile quantities (arrays over the half-profile bins, ``xi`` = bin-centre distance from
    the wall): u, gamma_dot (= du/dxi), du_y_dx, abs_dudx, phi, T, sigma_xx, sigma_xy, w_z,
    mu (= |sigma_xy/sigma_xx|), I (= |du_y/dx| d / sqrt(sigma_xx/rho_p)), omega_ratio
    (= Omega_z/(du_y/dx)), p_phi (B8: sigma_xx/T), mu_phi (B9: |sigma_xy|/(|du_y/dx| T^1/2)),
    D_phi (B10: Gamma/T^3/2), Gamma, production (= |shear_production|), gamma_over_sqrtT
    (= d |du_y/dx| / sqrt(T), fig. 9b).

    ``windows`` holds the raw per-window means of every steady window (window x bin) and
    ``window_dt`` the windows' duration, for :meth:`window_series` (stationarity, correlation
    times). With fewer than MIN_SE_BLOCKS blocks every SE is NaN (``enough_blocks``).
    """

    xi: FloatArray
    xi_lo: FloatArray
    xi_hi: FloatArray
    W: float
    folded: bool
    sign: float
    d: float
    rho_p: float
    t_start: float
    n_windows: int
    n_blocks: int
    block_len: int
    x_full: FloatArray
    width_full: FloatArray
    full: dict[str, FloatArray] = field(repr=False)
    loo: dict[str, FloatArray] = field(repr=False)
    windows: dict[str, FloatArray] = field(default_factory=dict, repr=False)
    window_dt: float = math.nan
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)

    # ---- derived quantities ------------------------------------------------------------
    @quiet
    def derived(self, m: Mapping[str, FloatArray] | None = None) -> dict[str, FloatArray]:
        """Half-profile derived quantities from raw full-channel means ``m`` (default: all
        steady windows)."""
        if m is None:
            if "full" not in self._cache:
                self._cache["full"] = self._derive(self.full)
            return self._cache["full"]
        return self._derive(m)

    def _derive(self, m: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
        x = self.x_full
        nan = np.full(x.size, np.nan)
        get = lambda k: np.asarray(m[k]) if k in m else nan  # noqa: E731
        u_y = get("u_y")
        dudx = np.gradient(u_y, x) if x.size >= 2 else nan
        side = np.where(x <= 0.5 * self.W, 1.0, -1.0)
        sxx, sxy, T = get("sigma_xx"), get("sigma_xy"), get("T")
        absd = np.abs(dudx)
        with np.errstate(divide="ignore", invalid="ignore"):
            q: dict[str, FloatArray] = {
                "u": self.sign * u_y,
                "gamma_dot": self.sign * dudx * side,
                "du_y_dx": dudx,
                "abs_dudx": absd,
                "phi": get("phi"),
                "T": T,
                "sigma_xx": sxx,
                "sigma_xy": sxy,
                "w_z": get("w_z"),
                "mu": np.abs(sxy / sxx),
                "I": absd * self.d / np.sqrt(np.abs(sxx) / self.rho_p),
                "omega_ratio": get("w_z") / dudx,
                "p_phi": sxx / T,
                "mu_phi": np.abs(sxy) / (absd * np.sqrt(T)),
                "D_phi": get("Gamma") / T**1.5,
                "Gamma": get("Gamma"),
                "production": np.abs(get("shear_production")),
                "gamma_over_sqrtT": self.d * absd / np.sqrt(T),
            }
        return {k: self._half(v, k in _ANTISYMMETRIC) for k, v in q.items()}

    def _half(self, q: FloatArray, anti: bool) -> FloatArray:
        h = (q.size + 1) // 2
        if not self.folded:
            return q[:h]
        mirror = q[::-1][:h]
        return 0.5 * (q[:h] + (-mirror if anti else mirror))

    @quiet
    def window_series(self, fn: Callable[[dict[str, FloatArray]], Any]) -> FloatArray:
        """``fn(m)`` of every steady window's raw full-channel means ``m`` (as
        :meth:`derived` takes them), in time order: an array (windows, ...) sampled every
        ``window_dt``."""
        n = next(iter(self.windows.values())).shape[0] if self.windows else 0
        return np.asarray([fn({k: v[i] for k, v in self.windows.items()}) for i in range(n)],
                          dtype=np.float64)

    # ---- jackknife ------------------------------------------------------------------------
    @property
    def enough_blocks(self) -> bool:
        """Whether the jackknife has MIN_SE_BLOCKS blocks (else every SE is NaN)."""
        return self.n_blocks >= MIN_SE_BLOCKS

    @quiet
    def estimate(self, fn: Callable[[dict[str, FloatArray]], Any]) -> tuple[Any, Any]:
        """``(fn(derived()), jackknife SE)`` over the blocks of windows (NaN SE with fewer
        than MIN_SE_BLOCKS blocks)."""
        value = fn(self.derived())
        reps = []
        for i in range(self.n_blocks):
            reps.append(fn(self._derive({k: v[i] for k, v in self.loo.items()})))
        return value, jackknife_se(value, reps)

    @quiet
    def table(self) -> pl.DataFrame:
        """Half profile: xi, xi_lo, xi_hi and every derived quantity with its ``_se``."""
        if "table" in self._cache:
            return self._cache["table"]
        keys = list(self.derived().keys())
        vals, ses = self.estimate(lambda q: np.array([q[k] for k in keys]))
        out: dict[str, Any] = {"xi": self.xi, "xi_lo": self.xi_lo, "xi_hi": self.xi_hi}
        for j, k in enumerate(keys):
            out[k] = vals[j]
            out[f"{k}_se"] = ses[j]
        self._cache["table"] = pl.DataFrame(out)
        return self._cache["table"]


def channel_steady_start(bm: BinMatrix, series: TableLike | None) -> SteadyStart:
    """The channel's steady start (the one rule, :func:`granflow.analysis.stats.steady_state_start`
    on the channel's observable): MSER on ``|vcm_y|`` of ``series`` where it has that column,
    else on the per-window mean velocity of the bins (:func:`.binned.window_steady_start`)."""
    if series is not None and "vcm_y" in column_names(series):
        return steady_state_start(column(series, "t"), np.abs(column(series, "vcm_y")))
    return window_steady_start(bm, "u_y")


def _steady_windows(
    bm: BinMatrix, series: TableLike | None, start_time: float | None
) -> tuple[float, SteadyStart | None]:
    """Start time of the steady part: given, else :func:`channel_steady_start`."""
    if start_time is not None:
        return float(start_time), None
    ss = channel_steady_start(bm, series)
    return ss.t_start, ss


@quiet
def profiles(
    bins: TableLike,
    series: TableLike | None = None,
    *,
    start_time: float | None = None,
    symmetrise: bool = True,
    n_blocks: int | None = None,
    max_blocks: int = 32,
    d: float = 1.0,
    rho_p: float = 1.0,
) -> ChannelProfiles:
    """Average the channel ``bins`` over the steady windows and prepare jackknife blocks.

    Parameters
    ----------
    bins, series
        Channel tables (docs/columns.md).  ``series`` is only used to find the steady start.
    start_time
        First time of the steady part (windows with ``t0 >= start_time`` are used); default:
        MSER on |vcm_y| of ``series`` or on the per-window mean u_y.
    symmetrise
        Fold the profile about x = W/2 (requires mirror-symmetric bins; otherwise the
        wall-0 half is used with a warning).
    n_blocks
        Number of jackknife blocks (default from the correlation of the window series, at most
        ``max_blocks``); the values are computed from as few as 2, the SEs need
        MIN_SE_BLOCKS.
    d, rho_p
        Particle diameter and density for I (B3) and the kinetic coefficients.
    """
    bm = bin_matrix(bins, [c for c in RAW_COLUMNS if c in column_names(bins)])
    if "u_y" not in bm.data:
        raise ValueError("bins table needs a u_y column")
    t_start, _ = _steady_windows(bm, series, start_time)
    tw = bm.t0 if np.all(np.isfinite(bm.t0)) else bm.t_mid
    keep = tw >= t_start - 1e-9 * max(1.0, abs(t_start))
    if keep.sum() < 2:
        keep = np.ones_like(keep)
    bm = bm.select(keep)
    nw = bm.window.size
    if nw < 2:
        raise ValueError("need at least two steady windows")
    if n_blocks is None:
        g = blocking(np.nanmean(bm.data["u_y"], axis=1)).g
        block_len, nb = choose_blocks(nw, g, max_blocks)
    else:
        nb = int(n_blocks)
    nb = max(2, min(nb, nw))
    block_len = nw // nb
    full: dict[str, FloatArray] = {}
    loo: dict[str, FloatArray] = {}
    kept = np.ones(nw, bool)
    for k, mat in bm.data.items():
        f, lo, kept = block_means(mat, bm.n_samples, block_len)
        full[k], loo[k] = f, lo
    x_lo, x_hi, x = bm.x_lo, bm.x_hi, bm.x
    W = float(np.nanmax(x_hi)) if np.all(np.isfinite(x_hi)) else float(np.max(x) + np.min(x))
    if np.all(np.isfinite(x_lo + x_hi)):
        width = x_hi - x_lo
    else:
        width = np.gradient(x)
    sym = bool(np.allclose(x + x[::-1], W, atol=1e-6 * max(W, 1.0)))
    folded = symmetrise and sym
    if symmetrise and not sym:
        warnings.warn(
            "bins are not mirror-symmetric about W/2: using the x <= W/2 half", stacklevel=2
        )
    sign = -1.0 if float(np.nanmean(full["u_y"])) < 0 else 1.0
    h = (x.size + 1) // 2
    xi = x[:h].copy()
    xi_lo = x_lo[:h].copy() if np.all(np.isfinite(x_lo)) else xi - 0.5 * width[:h]
    xi_hi = np.minimum(x_hi[:h], 0.5 * W) if np.all(np.isfinite(x_hi)) else xi + 0.5 * width[:h]
    t_used = float(tw[keep][kept][0]) if kept.any() else t_start
    return ChannelProfiles(
        xi=xi,
        xi_lo=xi_lo,
        xi_hi=xi_hi,
        W=W,
        folded=folded,
        sign=sign,
        d=d,
        rho_p=rho_p,
        t_start=t_used,
        n_windows=int(kept.sum()),
        n_blocks=int(nb),
        block_len=int(block_len),
        x_full=x,
        width_full=width,
        full=full,
        loo=loo,
        windows={k: np.asarray(v) for k, v in bm.data.items()},
        window_dt=_window_dt(bm),
    )


def _window_dt(bm: BinMatrix) -> float:
    """The windows' duration (their median t1 - t0; else the spacing of their mid times)."""
    if np.all(np.isfinite(bm.t0)) and np.all(np.isfinite(bm.t1)) and bm.t0.size:
        return float(np.median(bm.t1 - bm.t0))
    return float(np.median(np.diff(bm.t_mid))) if bm.t_mid.size > 1 else math.nan


