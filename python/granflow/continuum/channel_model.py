"""A channel's steady DEM runs (a reproduce_000 dataset: points and half profiles) against
the continuum models (granflow.continuum) with a calibrated local law: the local mu(I) and
the nonlocal granular fluidity model, the nonlocal amplitude fitted on one run and held for
the others, per-zone misfits, prediction bands from the calibration's covariance, and the
sensitivity to where the boundary data are taken (granflow.studies.cross_scene runs it)."""

from __future__ import annotations

import math
import os
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl

from granflow.analysis.channel import delta_095_profile
from granflow.analysis.tables import FloatArray
from granflow.continuum import (
    ChannelProblem,
    LocalLaw,
    Profile,
    plug_half_width,
    prediction_band,
    solve_local,
    solve_nonlocal,
)
from granflow.continuum.calibration import Calibration, calibrate
from granflow.errors import GranflowError, ParameterError

#: I below which a profile counts as plug (both the DEM's bins and the models'): the DEM's
#: plugs creep at I ~ 1e-5 (its resolution), its dense zones start near 1e-4
I_PLUG = 1e-4
#: the width whose DEM profiles fix the nonlocal amplitude A (then held for all others)
A_WIDTH, A_PHI_BAR = 40.0, 0.60
ZONES = ("plug", "dense", "loose", "wall")


@dataclass
class ChannelCase:
    """One steady channel run of the reproduce_000 dataset: its half profile (bin centres
    ``xi`` from the wall, SEs, zone labels) and the boundary data the models take from it."""

    W: float
    phi_bar: float
    kn: float
    profile: pl.DataFrame
    sigma_xx: float
    delta_095: float

    @property
    def name(self) -> str:
        return f"W = {self.W:g}, phi_bar = {self.phi_bar:g}"

    def problem(self, k: int = 0) -> ChannelProblem:
        """Boundary data at the centre of bin ``k`` (0: the wall bin, whose u is u_slip):
        u there and the fluidity |du/dx|/mu of that bin; sigma_xx the run's mean (uniform
        to 0.3 %)."""
        w = self.profile.row(k, named=True)
        return ChannelProblem(W=self.W, sigma_xx=self.sigma_xx, u_wall=w["u"],
                              x0=w["xi"], g_wall=abs(w["gamma_dot"]) / abs(w["mu"]))

    def pressure(self) -> float:
        """sigma_xx d/kn, the calibration's p_ext a/kn."""
        return self.sigma_xx / self.kn


def channel_cases(channel: str | os.PathLike[str], kn: float = 1e5) -> list[ChannelCase]:
    """The steady runs at ``kn`` of a reproduce_000 dataset (points and profiles)."""
    d = Path(channel)
    missing = [f for f in ("points.parquet", "profiles.parquet") if not (d / f).is_file()]
    if missing:
        raise ParameterError(f"invalid channel dataset {os.fspath(channel)!r}: no "
                             f"{', '.join(missing)} (allowed a reproduce_000 dataset, e.g. "
                             "docs/data/reproduce_000 of a granflow checkout)")
    pts = pl.read_parquet(d / "points.parquet").filter(
        (pl.col("kn") == kn) & pl.col("u_slip").is_not_null())
    prof = pl.read_parquet(d / "profiles.parquet")
    out = []
    for r in pts.sort("W", "phi_bar").iter_rows(named=True):
        p = prof.filter((pl.col("W") == r["W"]) & (pl.col("phi_bar") == r["phi_bar"])
                        & (pl.col("kn") == kn) & (pl.col("parent") == r["parent"])).sort("xi")
        out.append(ChannelCase(r["W"], r["phi_bar"], kn, p, r["sigma_xx_mean"],
                               r["delta_095"]))
    if not out:
        raise ParameterError(f"invalid channel dataset {os.fspath(channel)!r}: no steady run "
                             f"at kn = {kn:g} (allowed a reproduce_000 dataset)")
    return out


def law_for(case: ChannelCase, cal: Mapping[float, Calibration]) -> Calibration:
    """The calibration at the pressure nearest (in log) to the channel's sigma_xx d/kn."""
    return min(cal.values(), key=lambda c: abs(math.log(c.p_ext / case.pressure())))


def solve(model: str, law: LocalLaw, case: ChannelCase, A: float) -> Profile:
    return (solve_local(law, case.problem()) if model == "local"
            else solve_nonlocal(law, A, case.problem()))


def _velocity_misfit(case: ChannelCase, prof: Profile, k: int = 0) -> float:
    """RMS of (u_model - u_DEM)/(u_max - u_slip) over the DEM's bins past bin ``k`` (the
    boundary data's)."""
    t = case.profile
    xi, u = t["xi"].to_numpy(), t["u"].to_numpy()
    um = prof.at(xi[k + 1:])["u"]
    return float(np.sqrt(np.mean(((um - u[k + 1:]) / (u[-1] - u[0])) ** 2)))


def fit_amplitude(law: LocalLaw, case: ChannelCase, k: int = 0) -> float:
    """The nonlocal amplitude A that best fits the DEM velocity profile of ``case`` with
    the boundary data of bin ``k`` (least squares of (u - u_slip)/(u_max - u_slip) over the
    bins past ``k``; bounded search in log10 A)."""
    from scipy.optimize import minimize_scalar

    def cost(la: float) -> float:
        try:
            return _velocity_misfit(case, solve_nonlocal(law, 10**la, case.problem(k)), k)
        except GranflowError:
            return 1e3

    r = minimize_scalar(cost, bounds=(-1.5, 1.0), method="bounded",
                        options={"xatol": 2e-3})
    return float(10**r.x)


def zone_misfits(case: ChannelCase, prof: Profile, model: str) -> list[dict[str, Any]]:
    """Per zone of the DEM profile: RMS misfit of u - u_slip (relative to u_max - u_slip),
    of log10 |du/dx| (each floored at 1e-6, the local plug's zero) and of phi; the wall
    zone without its first bin (the boundary data)."""
    t = case.profile
    xi = t["xi"].to_numpy()
    m = prof.at(xi)
    u, gd, phi = (t[c].to_numpy() for c in ("u", "gamma_dot", "phi"))
    span = u[-1] - u[0]
    rows = []
    for zone in ZONES:
        idx = np.array([i for i, z in enumerate(t["zone"].to_list()) if z == zone and i > 0])
        if idx.size == 0:
            continue
        lg = np.log10(np.maximum(m["dudx"][idx], 1e-6)) - np.log10(
            np.maximum(np.abs(gd[idx]), 1e-6))
        rows.append({"W": case.W, "phi_bar": case.phi_bar, "model": model, "zone": zone,
                     "n_bins": int(idx.size),
                     "u_rel": float(np.sqrt(np.mean(((m["u"][idx] - u[idx]) / span) ** 2))),
                     "log_dudx": float(np.sqrt(np.mean(lg**2))),
                     "phi": float(np.sqrt(np.mean((m["phi"][idx] - phi[idx]) ** 2)))})
    return rows


def local_law_residuals(case: ChannelCase, law: LocalLaw) -> pl.DataFrame:
    """The DEM's bins against the cell's law directly (000's claim that the loose zone
    follows local rheology): mu - mu(I) and phi - phi(I) at each bin's I, with the bin's SE,
    and whether its I lies in the calibrated range."""
    t = case.profile.filter(pl.col("I") > 0)
    inum = t["I"].to_numpy()
    return t.select("xi", "zone", "I", "I_se", "mu", "mu_se", "phi", "phi_se").with_columns(
        pl.lit(case.W).alias("W"), pl.lit(case.phi_bar).alias("phi_bar"),
        pl.Series("d_mu", t["mu"].to_numpy() - law.mu(inum)),
        pl.Series("d_phi", t["phi"].to_numpy() - law.phi(inum)),
        pl.Series("in_range", (inum >= law.I_min) & (inum <= law.I_max)))


#: where the nonlocal model's boundary data may be taken: the wall bin (the report's
#: predictions), and the first and second bins inside it (the wall zone's edge, 000's ~2 d)
BOUNDARY_BINS = (0, 1, 2)  # (0 first: the report's A and own amplitudes are its rows)


def boundary_sensitivity(cal: Mapping[float, Calibration], cases: Sequence[ChannelCase],
                         ref: ChannelCase, bins: Sequence[int] = BOUNDARY_BINS) -> pl.DataFrame:
    """For each boundary bin k: every run's own best A and its misfit, and the misfit with
    the A fitted on ``ref`` held (misfits over the bins past k, relative to the DEM's
    u_max - u_slip). Does the amplitude become a material constant when the boundary data
    are taken outside the layered wall zone?"""
    rows = []
    for k in bins:
        a_ref = fit_amplitude(law_for(ref, cal).law, ref, k)
        for case in cases:
            law = law_for(case, cal).law
            a = fit_amplitude(law, case, k)
            rows.append({
                "bin": k, "x0": float(case.profile["xi"][k]), "W": case.W,
                "phi_bar": case.phi_bar, "A_best": a, "A_ref": a_ref,
                "u_rel_best": _velocity_misfit(case, solve_nonlocal(law, a, case.problem(k)), k),
                "u_rel_held": _velocity_misfit(
                    case, solve_nonlocal(law, a_ref, case.problem(k)), k)})
    return pl.DataFrame(rows)


@dataclass
class Prediction:
    """Everything the report shows: the calibrations, the amplitude fitted on one width, per
    channel run the summary (``cases``), the per-zone misfits (``zones``), the model
    profiles at the DEM's bins with the calibration bands (``profiles``) and the DEM's bins
    against the local law (``residuals``); the solve time."""

    cal: dict[float, Calibration]
    A: float
    A_se: float
    cases: pl.DataFrame
    zones: pl.DataFrame
    profiles: pl.DataFrame
    residuals: pl.DataFrame
    boundary: pl.DataFrame
    seconds: float
    #: nonlocal solves that reached only a relaxed tolerance (solve_nonlocal's warning)
    relaxed: int = 0


def _band(case: ChannelCase, laws: Sequence[LocalLaw], model: str, A: float,
          xi: FloatArray) -> tuple[dict[str, FloatArray], int]:
    """16th and 84th percentiles of u - u_wall, du/dx and phi over ``laws`` at ``xi``
    (continuum.prediction_band), and how many laws failed to solve."""
    band = prediction_band(laws, lambda law, prob: solve(model, law, case, A), case.problem(),
                           quantiles=(0.16, 0.84), x=xi)
    out = {}
    for key, name in (("u", "du"), ("dudx", "dudx"), ("phi", "phi")):
        out[f"{name}_lo"], out[f"{name}_hi"] = band[key][0], band[key][1]
    return out, int(band["failed"])


def predict(points: pl.DataFrame, channel: str | os.PathLike[str], n_band: int = 24,
            log: Any = print) -> Prediction:
    """Calibrate, fit A on the (A_WIDTH, A_PHI_BAR) run (its SE: the spread of A refitted
    for ``n_band // 3`` laws drawn from the calibration), and predict every steady run of
    ``channel`` with the local and the nonlocal model (A held), with bands from ``n_band``
    drawn laws."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        pred = _predict(points, channel, n_band, log)
    pred.relaxed = sum("not reached" in str(w.message) for w in caught)
    return pred


def _predict(points: pl.DataFrame, channel: str | os.PathLike[str], n_band: int,
             log: Any) -> Prediction:
    t0 = time.perf_counter()
    cal = calibrate(points)
    cases = channel_cases(channel)
    ref = min(cases, key=lambda c: (abs(c.W - A_WIDTH), abs(c.phi_bar - A_PHI_BAR)))
    c_ref = law_for(ref, cal)
    # the amplitudes with the wall bin's data (bin 0): A on ref, and each run's own
    boundary = boundary_sensitivity(cal, cases, ref)
    own = {(r["W"], r["phi_bar"]): r for r in boundary.filter(pl.col("bin") == 0)
           .iter_rows(named=True)}
    A = float(boundary.filter(pl.col("bin") == 0)["A_ref"][0])
    a_draws = [fit_amplitude(law, ref) for law in c_ref.sample(max(3, n_band // 3), seed=1)]
    A_se = float(np.std(a_draws, ddof=1))
    log(f"nonlocal amplitude A = {A:.4g} ± {A_se:.2g} (fitted on {ref.name})")
    rows, zrows, prows, res = [], [], [], []
    for case in cases:
        c = law_for(case, cal)
        t = case.profile
        xi = t["xi"].to_numpy()
        laws = c.sample(n_band, seed=2)
        a_best = float(own[(case.W, case.phi_bar)]["A_best"])
        row: dict[str, Any] = {
            "W": case.W, "phi_bar": case.phi_bar, "p_cal": c.p_ext,
            "sigma_xx_d_kn": case.pressure(), "mu_wall": float(t["mu"][0]),
            "A_best": a_best, "dem_du": float(t["u"][-1] - t["u"][0]),
            "dem_plug": plug_half_width(xi, t["I"].to_numpy(), I_PLUG),
            "dem_delta_095": case.delta_095,
            "dem_mass": float(case.phi_bar * case.W / 2)}
        for model in ("local", "nonlocal"):
            prof = solve(model, c.law, case, A)
            m = prof.at(xi)
            band, failed = _band(case, laws, model, A, xi)
            row.update({f"{model}_du": float(m["u"][-1] - m["u"][0]),
                        f"{model}_plug": plug_half_width(xi, m["I"], I_PLUG),
                        # (a local plug that only slides has no delta_0.95)
                        f"{model}_delta_095": (delta_095_profile(xi, m)
                                               if m["u"][-1] > m["u"][0] else math.nan),
                        f"{model}_mass": prof.mass() + float(xi[0] * t["phi"][0]),
                        f"{model}_u_rel": _velocity_misfit(case, prof),
                        f"{model}_band_failed": failed})
            zrows += zone_misfits(case, prof, model)
            prows.append(pl.DataFrame({
                "W": case.W, "phi_bar": case.phi_bar, "model": model, "xi": xi,
                "du": m["u"] - m["u"][0], "dudx": m["dudx"], "phi": m["phi"], "I": m["I"],
                **band}))
        row["nonlocal_best_u_rel"] = float(own[(case.W, case.phi_bar)]["u_rel_best"])
        rows.append(row)
        res.append(local_law_residuals(case, c.law))
        log(f"  {case.name}: local u_rel {row['local_u_rel']:.3f}, nonlocal "
            f"{row['nonlocal_u_rel']:.3f} (own best A = {a_best:.3g}: "
            f"{row['nonlocal_best_u_rel']:.3f})")
    return Prediction(cal, A, A_se, pl.DataFrame(rows), pl.DataFrame(zrows),
                      pl.concat(prows), pl.concat(res), boundary, time.perf_counter() - t0)
