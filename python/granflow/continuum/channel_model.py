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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
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
from granflow.continuum.constants import ModelConstants, nearest_pressure
from granflow.continuum.given_phi import solve_local_given_phi, solve_nonlocal_given_phi
from granflow.errors import GranflowError, ParameterError

#: I below which a profile counts as plug (both the DEM's bins and the models'): the DEM's
#: plugs creep at I ~ 1e-5 (its resolution), its dense zones start near 1e-4
I_PLUG = 1e-4
#: the width whose DEM profiles fix the nonlocal amplitude A (then held for all others)
A_WIDTH, A_PHI_BAR = 40.0, 0.60
ZONES = ("plug", "dense", "loose", "wall")
#: the continuum models (:func:`solve`)
MODELS = ("local", "nonlocal")
#: where the models' phi comes from (:func:`solve`): their law's phi(I), or the DEM run's
PHI_SOURCES = ("model", "dem")


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
    #: the run's seed (replicas of a point are cases of their own); None for a replica mean
    seed: int | None = None
    #: how many runs the case averages (channel_cases(replicas="mean"))
    replicas: int = 1

    @property
    def name(self) -> str:
        return (f"W = {self.W:g}, phi_bar = {self.phi_bar:g}"
                + (f", seed {self.seed}" if self.seed is not None else "")
                + (f", {self.replicas} replicas" if self.replicas > 1 else ""))

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


#: the points columns a channel dataset needs (a reproduce_000 dataset's)
CASE_COLUMNS = ("W", "phi_bar", "kn", "parent", "state", "u_slip", "sigma_xx_mean",
                "delta_095")
#: the columns that tell a point's profile rows apart (those both tables have)
PROFILE_KEY = ("W", "phi_bar", "kn", "parent", "B", "H", "seed", "prep")


#: how channel_cases returns the replicas of a point
REPLICAS = ("apart", "mean")


def left_out_runs(channel: str | os.PathLike[str], kn: float = 1e5,
                  B: float | None = None) -> list[str]:
    """The steady runs :func:`channel_cases` leaves out of ``channel`` with these arguments
    (another depth than the main one; not converged), one sentence per reason; none: []."""
    return [note for note, _ in _steady_points(Path(channel), kn, False, B)[1]]


def _steady_points(d: Path, kn: float, include_unconverged: bool, B: float | None
                   ) -> tuple[pl.DataFrame, list[tuple[str, str]], str]:
    """The points of the dataset ``d`` that :func:`channel_cases` takes, the (sentence, hint)
    of each group it leaves out, and the allowed-input phrase of its errors."""
    what = "allowed a reproduce_000 dataset, e.g. docs/data/reproduce_000 of a granflow checkout"
    missing = [f for f in ("points.parquet", "profiles.parquet") if not (d / f).is_file()]
    if missing:
        raise ParameterError(f"invalid channel dataset {os.fspath(d)!r}: no "
                             f"{', '.join(missing)} ({what})")
    pts = pl.read_parquet(d / "points.parquet")
    if "u_slip" not in pts.columns:  # (no run of the dataset was ever analysed as steady)
        states = sorted(set(pts["state"].to_list())) if "state" in pts.columns else []
        raise ParameterError(f"invalid channel dataset {os.fspath(d)!r}: no steady run "
                             f"at kn = {kn:g} (its states: {', '.join(states) or 'none'}; "
                             f"{what})")
    lacking = [c for c in CASE_COLUMNS if c not in pts.columns]
    if lacking:
        raise ParameterError(f"invalid channel dataset {os.fspath(d)!r}: its points "
                             f"lack the columns {', '.join(lacking)} ({what})")
    pts = pts.filter((pl.col("kn") == kn) & pl.col("u_slip").is_not_null())
    notes: list[tuple[str, str]] = []
    if "B" in pts.columns and pts.height:
        depth = float(pts["B"].mode().sort()[0]) if B is None else float(B)
        if depth not in pts["B"].to_list():
            raise ParameterError(f"invalid B = {B!r}: no steady run at that depth; allowed one "
                                 "of " + ", ".join(f"{b:g}" for b in pts["B"].unique().sort()))
        other = pts.filter(pl.col("B") != depth)
        if other.height and B is None:
            notes.append((f"channel_cases: {other.height} steady run(s) at another depth than "
                          f"the main B = {depth:g} are left out: "
                          + "; ".join(f"W = {r['W']:g}, phi_bar = {r['phi_bar']:g}, B = "
                                      f"{r['B']:g}" for r in other.iter_rows(named=True)),
                          "B= takes them"))
        pts = pts.filter(pl.col("B") == depth)
    if "converged" in pts.columns and not include_unconverged:
        left = pts.filter(~pl.col("converged"))
        if left.height:
            notes.append((f"channel_cases: {left.height} steady run(s) of {os.fspath(d)} "
                          "did not converge and are left out: "
                          + "; ".join(f"W = {r['W']:g}, phi_bar = {r['phi_bar']:g} "
                                      f"({r['state']})" for r in left.iter_rows(named=True)),
                          "include_unconverged=True takes them"))
        pts = pts.filter(pl.col("converged"))
    return pts, notes, what


def channel_cases(channel: str | os.PathLike[str], kn: float = 1e5,
                  include_unconverged: bool = False, replicas: str = "apart",
                  B: float | None = None) -> list[ChannelCase]:
    """The steady runs at ``kn`` and depth ``B`` of a reproduce_000 dataset (points and
    profiles). ``replicas``: "apart", one case per run; "mean", one per point (W, phi_bar),
    its profile the replicas' bin-by-bin mean with the larger of the within-run and
    between-replica SEs (granflow.analysis.replicas.mean_profiles; each bin's zone the one
    most replicas give), sigma_xx and delta_0.95 the replicas' means. ``B``: None takes the
    dataset's most common depth (the main one; a depth check's other depths are left out with
    a warning naming them). Runs that did not meet their plan's stop rule (``converged``
    false) are left out with a warning naming them, unless ``include_unconverged``
    (:func:`left_out_runs` lists them)."""
    if replicas not in REPLICAS:
        raise ParameterError(f"invalid replicas = {replicas!r}: allowed one of "
                             f"{', '.join(map(repr, REPLICAS))}")
    d = Path(channel)
    pts, notes, what = _steady_points(d, kn, include_unconverged, B)
    for note, hint in notes:
        warnings.warn(f"{note} ({hint})", UserWarning, stacklevel=2)
    prof = pl.read_parquet(d / "profiles.parquet")
    key = [c for c in PROFILE_KEY if c in pts.columns and c in prof.columns]
    runs = []
    for r in pts.sort("W", "phi_bar", *(["seed"] if "seed" in key else [])).iter_rows(
            named=True):
        p = prof.filter(*(pl.col(c) == r[c] for c in key)).sort("xi")
        runs.append(ChannelCase(r["W"], r["phi_bar"], kn, p, r["sigma_xx_mean"],
                                r["delta_095"], r.get("seed")))
    if not runs:
        raise ParameterError(f"invalid channel dataset {os.fspath(channel)!r}: no steady run "
                             f"at kn = {kn:g} ({what})")
    return runs if replicas == "apart" else _replica_means(runs)


def _replica_means(runs: Sequence[ChannelCase]) -> list[ChannelCase]:
    """One case per (W, phi_bar) of ``runs`` (channel_cases' "mean")."""
    from granflow.analysis.replicas import mean_profiles

    groups: dict[tuple[float, float], list[ChannelCase]] = {}
    for c in runs:
        groups.setdefault((c.W, c.phi_bar), []).append(c)
    out = []
    for (w, pb), g in groups.items():
        if len({c.profile.height for c in g}) != 1:
            raise ParameterError(f"invalid channel dataset: the replicas at W = {w:g}, phi_bar "
                                 f"= {pb:g} have different bins ({[c.profile.height for c in g]})")
        tab = pl.concat([c.profile for c in g], how="diagonal_relaxed")
        labels = [c for c in ("zone",) if c in tab.columns]
        keep = [c for c in ("xi_lo", "xi_hi") if c in tab.columns]
        mean = mean_profiles(tab, [c for c in ("W", "phi_bar") if c in tab.columns],
                             keep=keep, labels=labels)
        out.append(ChannelCase(w, pb, g[0].kn, mean,
                               float(np.mean([c.sigma_xx for c in g])),
                               float(np.mean([c.delta_095 for c in g])), None, len(g)))
    return out


def run_case(run: str | os.PathLike[str], n_particles: int | None = None) -> ChannelCase:
    """One steady channel run of ``granflow run`` (a directory with its ``bins.parquet`` and
    ``series.parquet``; W, phi_bar, kn, the particle count and the seed from their metadata)
    as a case: its half profile and boundary data from granflow.analysis.channel.summary. A
    run that is not steady (granflow.analysis.channel_profiles.flow_state, the threshold
    scaled to ``n_particles``, by default the run's count) is refused, naming its state."""
    import pyarrow.parquet as pq

    from granflow.analysis import channel as ach
    from granflow.analysis.channel_profiles import flow_state
    from granflow.io import read_params

    d = Path(run)
    missing = [f for f in ("bins.parquet", "series.parquet") if not (d / f).is_file()]
    if missing:
        raise ParameterError(f"invalid channel run {os.fspath(run)!r}: no {', '.join(missing)} "
                             "(allowed the directory of a channel run of `granflow run`)")
    params = read_params(d / "bins.parquet")
    if not {"W", "phi_bar", "kn"} <= set(params):
        raise ParameterError(f"invalid channel run {os.fspath(run)!r}: its parameters are not "
                             "a channel's (no W, phi_bar, kn)")
    if n_particles is None and isinstance(params.get("n"), int):
        n_particles = params["n"]
    bins, series = pq.read_table(d / "bins.parquet"), pq.read_table(d / "series.parquet")
    fs = flow_state(series, n_particles=n_particles)
    if not fs.is_steady:
        raise ParameterError(f"invalid channel run {os.fspath(run)!r}: its flow is {fs.state}; "
                             "allowed a steady (or fluctuating) run")
    s = ach.summary(bins, series)
    seed = pq.read_schema(d / "bins.parquet").metadata.get(b"granflow.seed", b"None").decode()
    return ChannelCase(float(params["W"]), float(params["phi_bar"]),
                       float(params["kn"]), s["profile"], s["sigma_xx_mean"].value,
                       s["delta_095"].value, int(seed) if seed.lstrip("-").isdigit() else None)


def cases_of(source: str | os.PathLike[str] | ChannelCase | Sequence[ChannelCase],
             kn: float = 1e5, replicas: str = "apart") -> list[ChannelCase]:
    """The cases a prediction takes from ``source``: a reproduce_000 dataset
    (:func:`channel_cases`, its ``replicas`` apart or averaged), one run's directory
    (:func:`run_case`), or cases."""
    if isinstance(source, ChannelCase):
        return [source]
    if isinstance(source, (str, os.PathLike)):
        d = Path(source)
        if (d / "bins.parquet").is_file() and not (d / "points.parquet").is_file():
            return [run_case(d)]
        return channel_cases(d, kn, replicas=replicas)
    out = list(source)
    if not out or not all(isinstance(c, ChannelCase) for c in out):
        raise ParameterError(f"invalid source = {source!r}: allowed a reproduce_000 dataset, "
                             "a channel run's directory, or ChannelCase objects")
    return out


def law_for(case: ChannelCase, cal: Mapping[float, Calibration]) -> Calibration:
    """The calibration at the pressure nearest (in log) to the channel's sigma_xx d/kn."""
    return cal[nearest_pressure(cal, case.pressure())]


def solve(model: str, law: LocalLaw, case: ChannelCase, A: float, phi: str = "model",
          k: int = 0) -> Profile:
    """The ``model`` ("local" or "nonlocal", amplitude ``A``) of ``case`` with ``law``, its
    boundary data from bin ``k`` (0: the wall bin); ``phi`` "model": the law's phi(I) (the
    models as Henann & Kamrin), "dem": the run's own phi profile
    (granflow.continuum.given_phi: the DEM's stress, only the flow rule modelled)."""
    if model not in MODELS:
        raise ParameterError(f"invalid model = {model!r}: allowed one of {MODELS}")
    if phi not in PHI_SOURCES:
        raise ParameterError(f"invalid phi = {phi!r}: allowed one of {PHI_SOURCES}")
    prob = case.problem(k)
    if phi == "dem":
        xi, ph = case.profile["xi"].to_numpy(), case.profile["phi"].to_numpy()
        return (solve_local_given_phi(law, prob, xi, ph) if model == "local"
                else solve_nonlocal_given_phi(law, A, prob, xi, ph))
    return solve_local(law, prob) if model == "local" else solve_nonlocal(law, A, prob)


def velocity_misfit(case: ChannelCase, prof: Profile, k: int = 0,
                    rise_past_k: bool = False) -> float:
    """The whole-channel misfit of a model profile: the RMS of (u_model - u_DEM)/(u_max -
    u_slip) over the DEM's bins past bin ``k`` (the boundary data's); ``rise_past_k``:
    relative to the DEM's rise past bin ``k``, u_max - u(x_k), instead."""
    t = case.profile
    xi, u = t["xi"].to_numpy(), t["u"].to_numpy()
    um = prof.at(xi[k + 1:])["u"]
    span = u[-1] - (u[k] if rise_past_k else u[0])
    return float(np.sqrt(np.mean(((um - u[k + 1:]) / span) ** 2)))


def fit_amplitude(law: LocalLaw, case: ChannelCase, k: int = 0, phi: str = "model") -> float:
    """The nonlocal amplitude A that best fits the DEM velocity profile of ``case`` with
    the boundary data of bin ``k`` (least squares of (u - u_slip)/(u_max - u_slip) over the
    bins past ``k``; bounded search in log10 A), phi as :func:`solve`'s."""
    from scipy.optimize import minimize_scalar

    def cost(la: float) -> float:
        try:
            return velocity_misfit(case, solve("nonlocal", law, case, 10**la, phi, k), k)
        except GranflowError:
            return 1e3

    r = minimize_scalar(cost, bounds=(-1.5, 1.0), method="bounded",
                        options={"xatol": 2e-3})
    return float(10**r.x)


def zone_bins(profile: pl.DataFrame) -> dict[str, npt.NDArray[np.int64]]:
    """The bin indices of each zone of a DEM half profile (its ``zone`` column), in ZONES
    order, zones without bins left out; the wall zone without its first bin (the models'
    boundary data): the bins every per-zone misfit is taken over."""
    zones = profile["zone"].to_list()
    out = {}
    for zone in ZONES:
        idx = np.array([i for i, z in enumerate(zones) if z == zone and i > 0], dtype=np.int64)
        if idx.size:
            out[zone] = idx
    return out


def zone_residuals(profile: pl.DataFrame, du: FloatArray, phi: FloatArray
                   ) -> dict[str, tuple[npt.NDArray[np.int64], FloatArray, FloatArray]]:
    """Per zone of a DEM half ``profile`` (:func:`zone_bins`): its bins, and a model's
    residuals there: of u - u_slip relative to the DEM's u_max - u_slip (``du``: the model's
    u less its wall value, at the profile's bins) and of ``phi``. The one definition of a
    zone's residuals (:func:`zone_misfits`, :func:`granflow.continuum.verdict.zone_errors`)."""
    u = profile["u"].to_numpy()
    r_u = (np.asarray(du, dtype=np.float64) - (u - u[0])) / (u[-1] - u[0])
    r_phi = np.asarray(phi, dtype=np.float64) - profile["phi"].to_numpy()
    return {zone: (idx, r_u[idx], r_phi[idx]) for zone, idx in zone_bins(profile).items()}


def zone_misfits(case: ChannelCase, prof: Profile, model: str) -> list[dict[str, Any]]:
    """Per zone of the DEM profile: RMS misfit of u - u_slip (relative to u_max - u_slip),
    of log10 |du/dx| (each floored at 1e-6, the local plug's zero) and of phi; the wall
    zone without its first bin (the boundary data)."""
    t = case.profile
    m = prof.at(t["xi"].to_numpy())
    gd = t["gamma_dot"].to_numpy()
    rows = []
    for zone, (idx, r_u, r_phi) in zone_residuals(t, m["u"] - m["u"][0], m["phi"]).items():
        lg = np.log10(np.maximum(m["dudx"][idx], 1e-6)) - np.log10(
            np.maximum(np.abs(gd[idx]), 1e-6))
        rows.append({"W": case.W, "phi_bar": case.phi_bar, "model": model, "zone": zone,
                     "n_bins": int(idx.size), "u_rel": float(np.sqrt(np.mean(r_u**2))),
                     "log_dudx": float(np.sqrt(np.mean(lg**2))),
                     "phi": float(np.sqrt(np.mean(r_phi**2)))})
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
                         ref: ChannelCase | None, bins: Sequence[int] = BOUNDARY_BINS,
                         A: float | None = None) -> pl.DataFrame:
    """For each boundary bin k: every run's own best A and its misfit, and the misfit with
    the A fitted on ``ref`` held (misfits over the bins past k, relative to the DEM's
    u_max - u_slip). Does the amplitude become a material constant when the boundary data
    are taken outside the layered wall zone? With ``A`` given (no ``ref``), that A is held
    at bin 0 and nothing is held at the others."""
    rows = []
    for k in bins:
        a_ref = (fit_amplitude(law_for(ref, cal).law, ref, k) if ref is not None
                 else (A if A is not None and k == 0 else math.nan))
        for case in cases:
            law = law_for(case, cal).law
            a = fit_amplitude(law, case, k)
            rows.append({
                "bin": k, "x0": float(case.profile["xi"][k]), "W": case.W,
                "phi_bar": case.phi_bar, "seed": case.seed, "A_best": a, "A_ref": a_ref,
                "u_rel_best": velocity_misfit(case, solve("nonlocal", law, case, a, k=k), k),
                "u_rel_held": (velocity_misfit(case, solve("nonlocal", law, case, a_ref, k=k), k)
                               if math.isfinite(a_ref) else math.nan)})
    return pl.DataFrame(rows)


@dataclass
class ChannelPrediction:
    """The models against channel runs (:func:`predict_channel`): per run the summary
    (``cases``: the DEM's u_max - u_slip, plug, delta_0.95 and mass against each model's, and
    the whole-channel misfit ``<model>_u_rel``), the per-zone misfits (``zones``), the model
    profiles at the DEM's bins with the calibration bands (``profiles``) and the DEM's bins
    against the local law (``residuals``)."""

    constants: ModelConstants
    cases: pl.DataFrame
    zones: pl.DataFrame
    profiles: pl.DataFrame
    residuals: pl.DataFrame


def _band(case: ChannelCase, laws: Sequence[LocalLaw], model: str, A: float,
          xi: FloatArray, phi: str = "model") -> tuple[dict[str, FloatArray], int]:
    """16th and 84th percentiles of u - u_wall, du/dx and phi over ``laws`` at ``xi``
    (continuum.prediction_band), and how many laws failed to solve; NaN without laws."""
    if not laws:
        nan = np.full(xi.shape, math.nan)
        return {f"{n}_{e}": nan for n in ("du", "dudx", "phi") for e in ("lo", "hi")}, 0
    band = prediction_band(laws, lambda law, prob: solve(model, law, case, A, phi),
                           case.problem(),
                           quantiles=(0.16, 0.84), x=xi)
    out = {}
    for key, name in (("u", "du"), ("dudx", "dudx"), ("phi", "phi")):
        out[f"{name}_lo"], out[f"{name}_hi"] = band[key][0], band[key][1]
    return out, int(band["failed"])


def predict_channel(constants: ModelConstants,
                    source: str | os.PathLike[str] | ChannelCase | Sequence[ChannelCase],
                    n_band: int = 24, models: Sequence[str] = MODELS,
                    log: Any = None, phi: str = "model") -> ChannelPrediction:
    """Predict channel runs with constants fitted once and held (nothing is refitted): every
    steady run of a reproduce_000 dataset, one run's directory of ``granflow run``, or
    :class:`ChannelCase` objects (:func:`cases_of`), with each of ``models``, and bands from
    ``n_band`` laws drawn from the constants' covariances (none without them, or with
    ``n_band = 0``); ``phi`` "model" (the law's phi(I)) or "dem" (each run's own phi
    profile: the DEM's stress, only the flow rule modelled; :func:`solve`). ``log``: a
    callable for one line per run (None: quiet).

        constants = ModelConstants.load("docs/data/cross_scene/model.parquet")
        pred = predict_channel(constants, "runs/my_channel")
        pred.cases["nonlocal_u_rel"]
    """
    bad_models = [m for m in models if m not in MODELS]
    if bad_models or not models:
        raise ParameterError(f"invalid models = {list(models)!r}: allowed a non-empty subset of "
                             f"{MODELS}")
    if int(n_band) != n_band or n_band < 0:
        raise ParameterError(f"invalid n_band = {n_band!r}: allowed an integer >= 0")
    A = constants.A
    rows, zrows, prows, res = [], [], [], []
    for case in cases_of(source):
        p_cal, law = constants.law_for(case.pressure())
        t = case.profile
        xi = t["xi"].to_numpy()
        laws = constants.sample(p_cal, n_band, seed=2) if n_band else []
        row: dict[str, Any] = {
            "W": case.W, "phi_bar": case.phi_bar, "seed": case.seed, "phi": phi, "p_cal": p_cal,
            "sigma_xx_d_kn": case.pressure(), "mu_wall": float(t["mu"][0]), "A": A,
            "dem_du": float(t["u"][-1] - t["u"][0]),
            "dem_plug": plug_half_width(xi, t["I"].to_numpy(), I_PLUG),
            "dem_delta_095": case.delta_095,
            "dem_mass": float(case.phi_bar * case.W / 2)}
        for model in models:
            prof = solve(model, law, case, A, phi)
            m = prof.at(xi)
            band, failed = _band(case, laws, model, A, xi, phi)
            row.update({f"{model}_du": float(m["u"][-1] - m["u"][0]),
                        f"{model}_plug": plug_half_width(xi, m["I"], I_PLUG),
                        # (a local plug that only slides has no delta_0.95)
                        f"{model}_delta_095": (delta_095_profile(xi, m)
                                               if m["u"][-1] > m["u"][0] else math.nan),
                        f"{model}_mass": prof.mass() + float(xi[0] * t["phi"][0]),
                        f"{model}_u_rel": velocity_misfit(case, prof),
                        f"{model}_band_failed": failed})
            zrows += [{**z, "seed": case.seed} for z in zone_misfits(case, prof, model)]
            prows.append(pl.DataFrame({
                "W": case.W, "phi_bar": case.phi_bar, "seed": case.seed, "model": model,
                "xi": xi, "du": m["u"] - m["u"][0], "dudx": m["dudx"], "phi": m["phi"],
                "I": m["I"], **band}))
        rows.append(row)
        res.append(local_law_residuals(case, law))
        if log is not None:
            log(f"  {case.name}: " + ", ".join(f"{m} u_rel {row[f'{m}_u_rel']:.3f}"
                                               for m in models))
    return ChannelPrediction(constants, pl.DataFrame(rows), pl.DataFrame(zrows),
                             pl.concat(prows), pl.concat(res))


@dataclass
class Prediction:
    """Everything the report shows: the calibrations, the constants (the amplitude fitted on
    one run, or given), per channel run the summary (``cases``, with each run's own best A),
    the per-zone misfits (``zones``), the model profiles at the DEM's bins with the
    calibration bands (``profiles``), the DEM's bins against the local law (``residuals``) and
    the boundary-bin sensitivity (``boundary``); the solve time."""

    cal: dict[float, Calibration]
    constants: ModelConstants
    cases: pl.DataFrame
    zones: pl.DataFrame
    profiles: pl.DataFrame
    residuals: pl.DataFrame
    boundary: pl.DataFrame
    seconds: float
    #: nonlocal solves that reached only a relaxed tolerance (solve_nonlocal's warning)
    relaxed: int = 0
    #: the models with each run's own phi profile (:func:`dem_phi_table`)
    dem_phi: pl.DataFrame = field(default_factory=pl.DataFrame)
    #: the run the amplitude was fitted on, (W, phi_bar, seed); None for a given A
    reference: tuple[float, float, int | None] | None = None

    @property
    def A(self) -> float:
        return self.constants.A

    @property
    def A_se(self) -> float:
        return self.constants.A_se


def constants_of(cal: Mapping[float, Calibration], A: float, A_se: float = math.nan,
                 A_from: str = "") -> ModelConstants:
    """The constants of calibrations ``cal`` with the amplitude ``A``."""
    return ModelConstants({p: c.law for p, c in cal.items()}, A, A_se, A_from,
                          {p: c.covariances() for p, c in cal.items()})


def reference_case(cases: Sequence[ChannelCase], reference: tuple[float, float]
                   ) -> ChannelCase:
    """The run of ``cases`` at ``reference`` = (W, phi_bar) to fit the amplitude on (the
    first seed); refused, naming the runs there are, where there is none."""
    at = [c for c in cases if (c.W, c.phi_bar) == tuple(reference)]
    if not at:
        have = sorted({(c.W, c.phi_bar) for c in cases})
        raise ParameterError(
            f"invalid reference = {tuple(reference)!r}: no steady run at W = {reference[0]:g}, "
            f"phi_bar = {reference[1]:g} to fit the amplitude on; allowed one of "
            f"{', '.join(f'({w:g}, {p:g})' for w, p in have)}, or a given A")
    return at[0]


def dem_phi_table(cal: Mapping[float, Calibration], cases: Sequence[ChannelCase],
                  ref: ChannelCase | None) -> pl.DataFrame:
    """The models with each run's own phi profile (``phi = "dem"``: the DEM's stress, only
    the flow rule modelled): per run the local misfit, the nonlocal run's own best A and its
    misfit, and the misfit with the A fitted (so) on ``ref`` held; whole-channel velocity
    misfits (:func:`velocity_misfit`), boundary data at the wall bin."""
    a_ref = (fit_amplitude(law_for(ref, cal).law, ref, 0, "dem") if ref is not None
             else math.nan)
    rows = []
    for case in cases:
        law = law_for(case, cal).law
        a = fit_amplitude(law, case, 0, "dem")
        rows.append({
            "W": case.W, "phi_bar": case.phi_bar, "seed": case.seed,
            "local_u_rel": velocity_misfit(case, solve("local", law, case, 0.0, "dem")),
            "A_best": a,
            "nonlocal_best_u_rel": velocity_misfit(case, solve("nonlocal", law, case, a, "dem")),
            "A_ref": a_ref,
            "nonlocal_u_rel": (velocity_misfit(case, solve("nonlocal", law, case, a_ref, "dem"))
                               if math.isfinite(a_ref) else math.nan)})
    return pl.DataFrame(rows)


def predict(points: pl.DataFrame, channel: str | os.PathLike[str], n_band: int = 24,
            log: Any = print, A: float | None = None, A_se: float = math.nan,
            reference: tuple[float, float] = (A_WIDTH, A_PHI_BAR)) -> Prediction:
    """Calibrate on the cell runs ``points``; fit the amplitude A on the run of ``channel`` at
    ``reference`` (W, phi_bar) (its SE: the spread of A refitted for ``n_band // 3`` laws
    drawn from the calibration), or hold a given ``A`` (with ``A_se``); predict every steady
    run of ``channel`` with the local and the nonlocal model (:func:`predict_channel`, bands
    from ``n_band`` drawn laws), each run's own best A beside it."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        pred = _predict(points, channel, n_band, log, A, A_se, reference)
    pred.relaxed = sum("not reached" in str(w.message) for w in caught)
    return pred


def _predict(points: pl.DataFrame, channel: str | os.PathLike[str], n_band: int, log: Any,
             A: float | None, A_se: float, reference: tuple[float, float]) -> Prediction:
    t0 = time.perf_counter()
    cal = calibrate(points)
    cases = channel_cases(channel)
    if A is None:
        ref: ChannelCase | None = reference_case(cases, reference)
        assert ref is not None
        c_ref = law_for(ref, cal)
        # the amplitudes with the wall bin's data (bin 0): A on ref, and each run's own
        boundary = boundary_sensitivity(cal, cases, ref)
        A = float(boundary.filter(pl.col("bin") == 0)["A_ref"][0])
        a_draws = [fit_amplitude(law, ref) for law in c_ref.sample(max(3, n_band // 3),
                                                                   seed=1)]
        constants = constants_of(cal, A, float(np.std(a_draws, ddof=1)), ref.name)
        log(f"nonlocal amplitude A = {A:.4g} ± {constants.A_se:.2g} (fitted on {ref.name})")
    else:
        ref = None
        boundary = boundary_sensitivity(cal, cases, None, A=A)
        constants = constants_of(cal, A, A_se, "given")
        log(f"nonlocal amplitude A = {A:.4g} (given, held)")
    pc = predict_channel(constants, cases, n_band=n_band)
    own = {(r["W"], r["phi_bar"], r["seed"]): (r["A_best"], r["u_rel_best"])
           for r in boundary.filter(pl.col("bin") == 0).iter_rows(named=True)}
    keys = list(zip(pc.cases["W"], pc.cases["phi_bar"], pc.cases["seed"], strict=True))
    cases_tab = pc.cases.with_columns(
        pl.Series("A_best", [own[k][0] for k in keys], dtype=pl.Float64),
        pl.Series("nonlocal_best_u_rel", [own[k][1] for k in keys], dtype=pl.Float64))
    for r in cases_tab.iter_rows(named=True):
        log(f"  W = {r['W']:g}, phi_bar = {r['phi_bar']:g}: local u_rel {r['local_u_rel']:.3f}"
            f", nonlocal {r['nonlocal_u_rel']:.3f} (own best A = {r['A_best']:.3g}: "
            f"{r['nonlocal_best_u_rel']:.3f})")
    dem = dem_phi_table(cal, cases, ref)
    return Prediction(cal, constants, cases_tab, pc.zones, pc.profiles, pc.residuals, boundary,
                      time.perf_counter() - t0, dem_phi=dem,
                      reference=None if ref is None else (ref.W, ref.phi_bar, ref.seed))
