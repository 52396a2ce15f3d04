"""The calibration of a local rheology from cell runs, stress- or rate-controlled (rows of the
cell campaign with the gradient-frame columns, rheology.GRADIENT_COLUMNS): mu_g(I_g) in Jop et al.'s
form and phi(I_g), per cell pressure, with their covariances, as a
:class:`granflow.continuum.LocalLaw` (granflow.studies.cross_scene runs it)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import polars as pl

from granflow.analysis.rheology import FitResult
from granflow.analysis.tables import FloatArray
from granflow.continuum.laws import LocalLaw
from granflow.errors import ParameterError


@dataclass
class Calibration:
    """The local law fitted at one cell pressure: the fits (with covariance, scaled by
    max(1, red chi^2) where the scatter exceeds the SEs) and the points they used
    (:func:`pooled_points`)."""

    p_ext: float
    mu_fit: FitResult
    phi_fit: FitResult
    law: LocalLaw
    points: pl.DataFrame
    #: 002's (4.2) form fitted to the same points, for comparison (not used by the models)
    mu_power: FitResult | None = None

    def covariances(self) -> tuple[FloatArray, FloatArray]:
        """The fits' covariances in the law's parameter order (LocalLaw.mu_covariance),
        scaled by max(1, red chi^2)."""
        mu, phi = self.mu_fit.cov_scaled, self.phi_fit.cov_scaled
        return LocalLaw.mu_covariance(mu, self.law.mu_form == "jop"), phi

    def sample(self, n: int, seed: int = 0) -> list[LocalLaw]:
        """``n`` laws drawn from the fits' covariances (the prediction band)."""
        mu_cov, phi_cov = self.covariances()
        return self.law.sample(mu_cov, phi_cov, n, np.random.default_rng(seed))


#: a calibration point: runs with these fields equal and different seeds are its replicas
#: (stress-controlled at tau_ratio, or rate-controlled at inertial_number)
POINT = ("p_ext", "N", "tau_ratio", "inertial_number")
#: the quantities a calibration point keeps
POINT_OBSERVABLES = ("I_g", "mu_g", "phi", "sigma_g_p")


def steady_points(points: pl.DataFrame) -> pl.DataFrame:
    """The calibration runs that count: flowing and converged."""
    return points.filter((pl.col("state") == "flowing") & pl.col("converged"))


def pooled_points(points: pl.DataFrame) -> pl.DataFrame:
    """One row per calibration point (:data:`POINT`: the cell sizes stay apart, they are not
    replicas) from its steady runs (:func:`steady_points`): ``replicas`` and, per quantity of
    :data:`POINT_OBSERVABLES`, the replicas' mean with ``X_se`` (the larger of the within-run
    and between-replica SEs), ``X_se_within`` and ``X_se_between``
    (analysis.replicas.replica_mean)."""
    from granflow.analysis.replicas import replica_mean

    if "inertial_number" not in points.columns:  # (a dataset from before rate points)
        points = points.with_columns(inertial_number=pl.lit(0.0))
    return replica_mean(steady_points(points), POINT, POINT_OBSERVABLES)


def calibrate(points: pl.DataFrame) -> dict[float, Calibration]:
    """Fit mu_g(I_g) and phi(I_g) per cell pressure, with the SE of I_g propagated
    (effective variance); the law's I range is the pooled points'. mu(I) takes Jop et al.'s
    form, linear at small I: 002's (4.2), fitted beside it, fits these points worse (its chi^2
    is in the report) and, with a1 < 1, continues to a yield ratio below the ratios at which
    the cell arrests. Raises ParameterError when a pressure has fewer than 4 steady points."""
    from granflow.analysis.rheology import fit_jop, fit_law

    out: dict[float, Calibration] = {}
    pooled = pooled_points(points)
    for p in sorted(set(pooled["p_ext"].to_list())):
        d = pooled.filter(pl.col("p_ext") == p).sort("I_g")
        if d.height < 4:
            raise ParameterError(f"invalid calibration at p_ext = {p:g}: {d.height} steady "
                                 "points, allowed >= 4 (three fitted constants per law)")
        ig, ig_se = d["I_g"].to_numpy(), d["I_g_se"].to_numpy()
        mu_fit = fit_jop(ig, d["mu_g"].to_numpy(), d["mu_g_se"].to_numpy(), I_se=ig_se)
        power = fit_law("mu1", ig, d["mu_g"].to_numpy(), d["mu_g_se"].to_numpy(), I_se=ig_se)
        phi_fit = fit_law("phi", ig, d["phi"].to_numpy(), d["phi_se"].to_numpy(), I_se=ig_se)
        if not (mu_fit.success and phi_fit.success):
            raise ParameterError(f"invalid calibration at p_ext = {p:g}: the fits failed "
                                 f"({mu_fit.message or phi_fit.message})")
        law = LocalLaw.from_fits(mu_fit, phi_fit, float(ig.min()), float(ig.max()))
        out[float(p)] = Calibration(float(p), mu_fit, phi_fit, law, d, power)
    return out


def fits_table(cal: Mapping[float, Calibration]) -> pl.DataFrame:
    """One row per (pressure, law): constants c0, c1, c2 (named, in that order, in
    ``constants``: e.g. mu_s, mu_2, I_0), their errors and covariance (row-major, in the
    constants' order) both scaled by max(1, red chi^2), red chi^2, the I range; the committed
    ``fits.parquet``. The models' constants (laws and amplitude) are
    :class:`granflow.continuum.constants.ModelConstants` (``model.parquet``)."""
    rows = []
    for p, c in cal.items():
        for name, f in (("mu", c.mu_fit), ("phi", c.phi_fit), ("mu (4.2)", c.mu_power)):
            if f is None:
                continue
            (k0, k1, k2) = f.params
            e = f.errors_scaled
            rows.append({"p_ext": p, "law": name, "equation": f.equation,
                         "constants": ", ".join(f.params),
                         "c0": f.params[k0], "c0_se": e[k0], "c1": f.params[k1],
                         "c1_se": e[k1], "c2": f.params[k2], "c2_se": e[k2],
                         "red_chi2": f.red_chi2, "n": f.n,
                         "cov": [float(v) for v in f.cov_scaled.ravel()],
                         "I_min": c.law.I_min, "I_max": c.law.I_max})
    return pl.DataFrame(rows)


#: the checked quantities of a rate-controlled point against the stress-controlled law
CHECKED = (("mu_g", "mu"), ("phi", "phi"))


def continuation_check(points: pl.DataFrame, n_draws: int = 400,
                       seed: int = 0) -> pl.DataFrame:
    """The rate-controlled calibration points against the law fitted to the stress-controlled
    points alone, per pressure: one row per rate point and quantity (mu_g, phi) with the
    point's replica mean and SE, the stress law's value at the point's I_g and its band (the
    SD over ``n_draws`` laws drawn from the fits' covariance), the difference's z over the
    combined SE, and whether I_g lies inside the stress points' range ("overlap": the two
    drives measure the same flow, so they must agree to be pooled) or below it
    ("continuation": the rate point tests the stress law's continuation, which the models
    used before there were rate points). Empty where a pressure lacks either drive."""
    pooled = pooled_points(points)
    rows = []
    for p in sorted(set(pooled["p_ext"].to_list())):
        at = pooled.filter(pl.col("p_ext") == p)
        rate = at.filter(pl.col("inertial_number") > 0)
        stress = points.filter((pl.col("p_ext") == p) & (pl.col("tau_ratio") > 0))
        if rate.is_empty() or stress.is_empty():
            continue
        try:
            cal = calibrate(stress)[float(p)]
        except ParameterError:
            continue
        draws = cal.sample(n_draws, seed)
        ig = rate["I_g"].to_numpy()
        for col, fn in CHECKED:
            law = getattr(cal.law, fn)(ig)
            band = np.std([getattr(d, fn)(ig) for d in draws], axis=0)
            for k, r in enumerate(rate.iter_rows(named=True)):
                se = float(np.hypot(r[f"{col}_se"], band[k]))
                diff = float(r[col] - law[k])
                rows.append({
                    "p_ext": float(p), "inertial_number": r["inertial_number"],
                    "replicas": r["replicas"], "I_g": r["I_g"], "quantity": col,
                    "measured": r[col], "measured_se": r[f"{col}_se"],
                    "stress_law": float(law[k]), "band": float(band[k]), "diff": diff,
                    "z": diff / se if se > 0 else float("nan"),
                    "where": ("overlap" if r["I_g"] >= cal.law.I_min else "continuation")})
    return pl.DataFrame(rows)
