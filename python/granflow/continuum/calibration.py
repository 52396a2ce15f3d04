"""The calibration of a local rheology from cell runs, stress- or rate-controlled (rows of the
cell campaign with the gradient-frame columns, rheology.GRADIENT_COLUMNS): mu_g(I_g) in Jop et al.'s
form and phi(I_g) in 002's (4.7), each with a fourth constant, per cell pressure, with their
covariances, as a :class:`granflow.continuum.LocalLaw` (granflow.studies.cross_scene runs it);
and which form fits (:func:`form_comparison`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import polars as pl

from granflow.analysis.rheology import (
    JOP_LINEAR,
    PHI_QUADRATIC,
    FitResult,
    fit_four,
    fit_jop,
    fit_law,
)
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
    #: the three-constant forms fitted to the same points, for comparison (not used by the
    #: models): "mu (Jop)", "phi (4.7)" and 002's "mu (4.2)"
    compared: dict[str, FitResult] = field(default_factory=dict)

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
    (effective variance); the law's I range is the pooled points'. The forms are Jop et al.'s
    mu(I) + c I and (4.7) - B I^2 (rheology.fit_four): the three-constant forms fit the
    points within their SEs only over the channel's range (I_g <= FORM_I_MAX), and over the
    whole range trade the slow points against the fast points' curvature (the report's
    :func:`form_comparison`). Jop's form, linear at small I, rather than 002's (4.2), which
    with a1 < 1 continues to a yield ratio below the ratios at which the cell arrests; the
    three-constant fits are kept beside (``compared``). Raises ParameterError when a pressure
    has fewer than 5 steady points."""
    out: dict[float, Calibration] = {}
    pooled = pooled_points(points)
    for p in sorted(set(pooled["p_ext"].to_list())):
        d = pooled.filter(pl.col("p_ext") == p).sort("I_g")
        if d.height < 5:
            raise ParameterError(f"invalid calibration at p_ext = {p:g}: {d.height} steady "
                                 "points, allowed >= 5 (four fitted constants per law)")
        ig, ig_se = d["I_g"].to_numpy(), d["I_g_se"].to_numpy()
        mu, mu_se = d["mu_g"].to_numpy(), d["mu_g_se"].to_numpy()
        phi, phi_se = d["phi"].to_numpy(), d["phi_se"].to_numpy()
        mu_fit = fit_four(JOP_LINEAR, ig, mu, mu_se, I_se=ig_se)
        phi_fit = fit_four(PHI_QUADRATIC, ig, phi, phi_se, I_se=ig_se)
        if not (mu_fit.success and phi_fit.success):
            raise ParameterError(f"invalid calibration at p_ext = {p:g}: the fits failed "
                                 f"({mu_fit.message or phi_fit.message})")
        compared = {"mu (Jop)": fit_jop(ig, mu, mu_se, I_se=ig_se),
                    "phi (4.7)": fit_law("phi", ig, phi, phi_se, I_se=ig_se),
                    "mu (4.2)": fit_law("mu1", ig, mu, mu_se, I_se=ig_se)}
        law = LocalLaw.from_fits(mu_fit, phi_fit, float(ig.min()), float(ig.max()))
        out[float(p)] = Calibration(float(p), mu_fit, phi_fit, law, d, compared)
    return out


def fits_table(cal: Mapping[float, Calibration]) -> pl.DataFrame:
    """One row per (pressure, law): constants c0-c3 (named, in that order, in ``constants``:
    e.g. mu_s, mu_2, I_0, c; c3 null for a three-constant form), their errors and covariance
    (row-major, in the constants' order) both scaled by max(1, red chi^2), red chi^2, the I
    range; the committed ``fits.parquet``. Rows "mu" and "phi" are the models' laws, the others
    :attr:`Calibration.compared`. The models' constants (laws and amplitude) are
    :class:`granflow.continuum.constants.ModelConstants` (``model.parquet``)."""
    rows = []
    for p, c in cal.items():
        for name, f in (("mu", c.mu_fit), ("phi", c.phi_fit), *c.compared.items()):
            e = f.errors_scaled
            row: dict[str, object] = {"p_ext": p, "law": name, "equation": f.equation,
                                      "constants": ", ".join(f.params)}
            keys = list(f.params)
            for k in range(4):
                row[f"c{k}"] = f.params[keys[k]] if k < len(keys) else None
                row[f"c{k}_se"] = e[keys[k]] if k < len(keys) else None
            rows.append({**row, "red_chi2": f.red_chi2, "n": f.n,
                         "cov": [float(v) for v in f.cov_scaled.ravel()],
                         "I_min": c.law.I_min, "I_max": c.law.I_max})
    return pl.DataFrame(rows, schema_overrides={f"c{k}{t}": pl.Float64 for k in range(4)
                                                for t in ("", "_se")})


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


#: a fitter of one form: (I, y, y_se, I_se) -> its FitResult
Fitter = Callable[[FloatArray, FloatArray, FloatArray, FloatArray], FitResult]


def _forms() -> dict[str, tuple[tuple[str, int, Fitter], ...]]:
    """The candidate forms per quantity, (name, constants, fitter): the first of each is the
    form the models use (:func:`calibrate`), the second the same form less its fourth
    constant."""
    return {
        "mu_g": (("Jop + c I", 4, lambda i, y, e, s: fit_four(JOP_LINEAR, i, y, e, I_se=s)),
                 ("Jop (mu_s, mu_2, I_0)", 3, lambda i, y, e, s: fit_jop(i, y, e, I_se=s))),
        "phi": (("(4.7) - B I^2", 4,
                 lambda i, y, e, s: fit_four(PHI_QUADRATIC, i, y, e, I_se=s)),
                ("(4.7) phi_0 - A4 I^a4", 3, lambda i, y, e, s: fit_law("phi", i, y, e, I_se=s))),
    }


#: the candidate forms' names per quantity, the models' first (:func:`_forms`)
FORMS = {q: tuple(name for name, _k, _f in c) for q, c in _forms().items()}


def _z(fit: FitResult, I: FloatArray, y: FloatArray, y_se: FloatArray,  # noqa: E741
       I_se: FloatArray) -> FloatArray:
    """Each point's residual over its effective SE (y_se and the fit's slope times I_se)."""
    h = 1e-6 * I
    slope = (fit(I + h) - fit(I - h)) / (2 * h)
    return np.asarray((y - fit(I)) / np.hypot(y_se, slope * I_se))


def form_comparison(points: pl.DataFrame, i_max: float = FORM_I_MAX) -> pl.DataFrame:
    """Which form fits the pooled calibration points (:func:`pooled_points`), per pressure
    and quantity: each candidate of :data:`FORMS` fitted over all points and over those with
    I_g <= ``i_max`` (the channel's range), with its reduced chi^2 (over the effective SEs),
    largest |z|, the z of the slowest point (a form that misses at low I shows there first)
    and its low-I constant (mu_s or phi_0) with its SE. Points with a non-positive SE are
    left out; a fit with no degree of freedom left is not made."""
    pooled = pooled_points(points)
    forms = _forms()
    rows = []
    for p in sorted(set(pooled["p_ext"].to_list())):
        d = pooled.filter(pl.col("p_ext") == p).sort("I_g")
        ig, ig_se = d["I_g"].to_numpy(), d["I_g_se"].fill_nan(0.0).to_numpy()
        for col, candidates in forms.items():
            y, se = d[col].to_numpy(), d[f"{col}_se"].to_numpy()
            good = np.isfinite(y) & np.isfinite(se) & (se > 0) & (ig > 0)
            for span, keep in (("all", good), (f"I_g <= {i_max:g}", good & (ig <= i_max))):
                for name, k, fitter in candidates:
                    n = int(keep.sum())
                    fit = fitter(ig[keep], y[keep], se[keep], ig_se[keep]) if n > k else None
                    row = {"p_ext": float(p), "quantity": col, "form": name, "range": span,
                           "n": n, "constants": k, "red_chi2": math.nan,
                           "max_abs_z": math.nan, "z_slowest": math.nan,
                           "I_g_slowest": float(ig[keep][0]) if n else math.nan,
                           "low_I": math.nan, "low_I_se": math.nan}
                    if fit is not None and fit.success:
                        z = _z(fit, ig[keep], y[keep], se[keep], ig_se[keep])
                        first = next(iter(fit.params))
                        row.update(red_chi2=float((z**2).sum() / (n - k)),
                                   max_abs_z=float(np.abs(z).max()), z_slowest=float(z[0]),
                                   low_I=fit.params[first],
                                   low_I_se=fit.errors_scaled[first])
                    rows.append(row)
    return pl.DataFrame(rows)
