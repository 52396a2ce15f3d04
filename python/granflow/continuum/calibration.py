"""The calibration of a local rheology from cell runs, stress- or rate-controlled (rows of the
cell campaign with the gradient-frame columns, rheology.GRADIENT_COLUMNS): mu_g(I_g) in Jop et al.'s
form and phi(I_g), per cell pressure, with their covariances, as a
:class:`granflow.continuum.LocalLaw` (granflow.studies.cross_scene runs it)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

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


#: the calibration's I_g below which the channel's dense zone shears (I = 1e-4 to 0.04, times
#: ~2 for I_g), with room: the range on which :func:`form_comparison` also judges each form
FORM_I_MAX = 0.35


def _jop(I: FloatArray, ms: float, m2: float, i0: float) -> FloatArray:  # noqa: E741
    return ms + (m2 - ms) / (1.0 + i0 / I)


def _jop_linear(I: FloatArray, ms: float, m2: float, i0: float,  # noqa: E741
                c: float) -> FloatArray:
    return _jop(I, ms, m2, i0) + c * I


def _phi47(I: FloatArray, p0: float, a: float, e: float) -> FloatArray:  # noqa: E741
    return p0 - a * I**e


def _phi47_quadratic(I: FloatArray, p0: float, a: float, e: float,  # noqa: E741
                     b: float) -> FloatArray:
    return _phi47(I, p0, a, e) - b * I**2


#: the candidate forms per quantity: (name, function, first guess); the first of each is the
#: form the models use (Jop et al.'s mu, 002's (4.7) phi)
FORMS = {
    "mu_g": (("Jop (mu_s, mu_2, I_0)", _jop, (0.36, 0.8, 0.5)),
             ("Jop + c I", _jop_linear, (0.36, 0.8, 0.5, 0.0))),
    "phi": (("(4.7) phi_0 - A4 I^a4", _phi47, (0.59, 0.16, 1.0)),
            ("(4.7) - B I^2", _phi47_quadratic, (0.59, 0.16, 1.0, 0.0))),
}


def _fit_form(f: Any, guess: tuple[float, ...], I: FloatArray, y: FloatArray,  # noqa: E741
              y_se: FloatArray, I_se: FloatArray) -> tuple[FloatArray, FloatArray] | None:
    """Weighted least squares with the SE of I propagated by effective variance (sigma^2 =
    y_se^2 + (f'(I) I_se)^2, refitted twice, as analysis.rheology.fit_law); the parameters
    and each point's z, or None where the fit fails."""
    from scipy.optimize import curve_fit

    sig, pp = y_se, np.asarray(guess, dtype=np.float64)
    try:
        for _ in range(3):
            pp, _cov = curve_fit(f, I, y, p0=pp, sigma=sig, absolute_sigma=True,
                                 maxfev=50_000)
            h = 1e-6 * I
            slope = (f(I + h, *pp) - f(I - h, *pp)) / (2 * h)
            sig = np.hypot(y_se, slope * I_se)
    except (RuntimeError, ValueError):
        return None
    return pp, (y - f(I, *pp)) / sig


def form_comparison(points: pl.DataFrame, i_max: float = FORM_I_MAX) -> pl.DataFrame:
    """Which form fits the pooled calibration points (:func:`pooled_points`), per pressure
    and quantity: each candidate of :data:`FORMS` fitted over all points and over those with
    I_g <= ``i_max`` (the channel's range), with its reduced chi^2, largest |z| and the z of
    the slowest point (a form that misses at low I shows there first). Points with a
    non-positive SE are left out; a fit with no degree of freedom left is not made."""
    pooled = pooled_points(points)
    rows = []
    for p in sorted(set(pooled["p_ext"].to_list())):
        d = pooled.filter(pl.col("p_ext") == p).sort("I_g")
        ig, ig_se = d["I_g"].to_numpy(), d["I_g_se"].fill_nan(0.0).to_numpy()
        for col, forms in FORMS.items():
            y, se = d[col].to_numpy(), d[f"{col}_se"].to_numpy()
            good = np.isfinite(y) & np.isfinite(se) & (se > 0) & (ig > 0)
            for span, keep in (("all", good), (f"I_g <= {i_max:g}", good & (ig <= i_max))):
                for name, f, guess in forms:
                    n, k = int(keep.sum()), len(guess)
                    fit = _fit_form(f, guess, ig[keep], y[keep], se[keep],
                                    ig_se[keep]) if n > k else None
                    row = {"p_ext": float(p), "quantity": col, "form": name, "range": span,
                           "n": n, "constants": k, "red_chi2": math.nan,
                           "max_abs_z": math.nan, "z_slowest": math.nan,
                           "I_g_slowest": float(ig[keep][0]) if n else math.nan}
                    if fit is not None:
                        _pp, z = fit
                        row.update(red_chi2=float((z**2).sum() / (n - k)),
                                   max_abs_z=float(np.abs(z).max()), z_slowest=float(z[0]))
                    rows.append(row)
    return pl.DataFrame(rows)
