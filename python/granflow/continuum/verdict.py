"""Does a cell calibration predict the channel? Per run, model and zone, the misfit of
u - u_slip (relative to the DEM's u_max - u_slip) and of phi, each with its uncertainty; per
width and zone the worst run against the targets; and the one-line answer for the wide runs.

Targets (the cross-scene study's): u - u_slip within ``U_TARGET`` = 10 % of u_max - u_slip
in every zone, phi within ``PHI_TARGET`` = 0.01 outside the plug (the models carry the
cell's critical-state phi into the plug, which no phi(I) law can compact:
docs/cross_scene.md).

Uncertainty of a misfit e = sqrt(mean r_i^2), r_i the residual of bin i: linear propagation,
se(e)^2 = sum_i (r_i / (n e))^2 (s_model,i^2 + s_dem,i^2), with s_model the half-width of
the calibration band (16-84 % over laws drawn from the fits' covariance) and s_dem the
DEM bin's SE (for u - u_slip also the wall bin's, in quadrature). Where e is below the
noise's own RMS, sqrt(mean s_i^2), the residuals are not resolved and that RMS is the SE.
A verdict is "within" if e + 2 se <= target, "outside" if e - 2 se > target, else "at the
target" (the data cannot tell at 2 SEs).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import polars as pl

from ._checks import FloatArray, bad
from .channel_model import zone_residuals

#: u - u_slip within this fraction of u_max - u_slip (the cross-scene target)
U_TARGET = 0.10
#: phi within this, outside the plug (the cross-scene target)
PHI_TARGET = 0.01
#: the runs the target is set for: W >= WIDE ("every wide run")
WIDE = 60.0
#: a verdict's margin, in SEs of the misfit
SIGMAS = 2.0


def misfit_with_error(residual: FloatArray, se: FloatArray) -> tuple[float, float]:
    """The RMS of ``residual`` and its SE from the residuals' own SEs ``se`` (module
    docstring); NaN for no bins."""
    r = np.asarray(residual, dtype=np.float64)
    s = np.nan_to_num(np.asarray(se, dtype=np.float64), nan=0.0)
    if r.shape != s.shape:
        raise bad("se", f"shape {s.shape}", f"the residuals' shape {r.shape}")
    if r.size == 0:
        return math.nan, math.nan
    e = float(np.sqrt(np.mean(r**2)))
    noise = float(np.sqrt(np.mean(s**2)))
    if e <= noise:
        return e, noise
    return e, float(np.sqrt(np.sum((r * s) ** 2)) / (r.size * e))


def classify(misfit: float, se: float, target: float) -> str:
    """"within", "outside" or "at the target" (module docstring); "" for no misfit."""
    if not math.isfinite(misfit):
        return ""
    if not (math.isfinite(target) and target > 0):
        raise bad("target", target, "a finite number > 0")
    s = se if math.isfinite(se) else 0.0
    if misfit + SIGMAS * s <= target:
        return "within"
    if misfit - SIGMAS * s > target:
        return "outside"
    return "at the target"


def _half_band(prof: pl.DataFrame, name: str) -> FloatArray:
    """Half the calibration band of ``name`` (0 where the run has no band)."""
    lo, hi = f"{name}_lo", f"{name}_hi"
    if lo not in prof.columns:
        return np.zeros(prof.height)
    return np.nan_to_num((prof[hi].to_numpy() - prof[lo].to_numpy()) / 2.0, nan=0.0)


def zone_errors(cases: Sequence[Any], profiles: pl.DataFrame) -> pl.DataFrame:
    """One row per run, model and zone: the misfits of u - u_slip (``u_rel``) and phi
    (``phi_abs``) with their SEs (module docstring). ``cases``: the runs
    (:class:`granflow.continuum.channel_model.ChannelCase`: the DEM's bins with SEs and
    zones); ``profiles``: the models at those bins with their bands (a ChannelPrediction's
    ``profiles``). The residuals of each zone are
    :func:`channel_model.zone_residuals`'s."""
    rows = []
    for case in cases:
        t = case.profile
        u_se = t["u_se"].to_numpy() if "u_se" in t.columns else np.zeros(t.height)
        phi_se = t["phi_se"].to_numpy() if "phi_se" in t.columns else np.zeros(t.height)
        span = abs(t["u"][-1] - t["u"][0])
        sel = (pl.col("W") == case.W) & (pl.col("phi_bar") == case.phi_bar)
        if case.seed is not None and "seed" in profiles.columns:
            sel = sel & (pl.col("seed") == case.seed)
        for model, m in profiles.filter(sel).group_by("model", maintain_order=True):
            m = m.sort("xi")
            if m.height != t.height:
                raise bad("profiles", f"{m.height} bins for {case.name}",
                          f"the DEM run's {t.height} bins")
            s_du, s_phi = _half_band(m, "du"), _half_band(m, "phi")
            zones = zone_residuals(t, m["du"].to_numpy(), m["phi"].to_numpy())
            for zone, (idx, r_u, r_phi) in zones.items():
                eu, su = misfit_with_error(
                    r_u, np.sqrt(s_du[idx] ** 2 + u_se[idx] ** 2 + u_se[0] ** 2) / span)
                ep, sp = misfit_with_error(r_phi, np.sqrt(s_phi[idx] ** 2 + phi_se[idx] ** 2))
                rows.append({"W": case.W, "phi_bar": case.phi_bar, "seed": case.seed,
                             "model": model[0], "zone": zone, "n_bins": int(idx.size),
                             "u_rel": eu, "u_rel_se": su, "phi_abs": ep, "phi_abs_se": sp})
    return pl.DataFrame(rows)


def verdict_table(errors: pl.DataFrame, u_target: float = U_TARGET,
                  phi_target: float = PHI_TARGET) -> pl.DataFrame:
    """Per width, model and zone, the worst run's misfits (by misfit less ``SIGMAS`` SEs:
    the run that most surely misses) with their SEs, how many runs, and the verdicts
    against the targets (:func:`classify`; no phi verdict in the plug)."""
    for name, v in (("u_target", u_target), ("phi_target", phi_target)):
        if not (math.isfinite(v) and v > 0):
            raise bad(name, v, "a finite number > 0")
    rows = []
    for (w, model, zone), g in errors.group_by(["W", "model", "zone"], maintain_order=True):
        ru = g.sort(pl.col("u_rel") - SIGMAS * pl.col("u_rel_se")).row(-1, named=True)
        rp = g.sort(pl.col("phi_abs") - SIGMAS * pl.col("phi_abs_se")).row(-1, named=True)
        rows.append({
            "W": w, "model": model, "zone": zone, "runs": g.height,
            "u_rel": ru["u_rel"], "u_rel_se": ru["u_rel_se"], "u_at_phi_bar": ru["phi_bar"],
            "u": classify(ru["u_rel"], ru["u_rel_se"], u_target),
            "phi_abs": rp["phi_abs"], "phi_abs_se": rp["phi_abs_se"],
            "phi": "" if zone == "plug" else classify(rp["phi_abs"], rp["phi_abs_se"],
                                                      phi_target)})
    return pl.DataFrame(rows).sort("W", "model", "zone")


def answer(table: pl.DataFrame, wide: float = WIDE) -> str:
    """The one-line answer to "does a cell calibration predict the channel?" over the
    widths >= ``wide``, per model, from :func:`verdict_table`."""
    t = table.filter(pl.col("W") >= wide)
    if not t.height:
        return (f"Cannot tell: no run at W >= {wide:g} (the wide runs the target is set "
                "for).")
    parts, good, missed = [], [], []
    for (model,), g in t.group_by(["model"], maintain_order=True):
        verdicts = [v for v in [*g["u"].to_list(), *g["phi"].to_list()] if v]
        out = sum(v == "outside" for v in verdicts)
        unsure = sum(v == "at the target" for v in verdicts)
        parts.append(f"{model}: {len(verdicts) - out - unsure} of {len(verdicts)} zone "
                     f"verdicts within, {out} outside, {unsure} at the target")
        if out == 0 and unsure == 0:
            good.append(str(model))
        if out:
            missed.append(str(model))
    head = (f"Yes, with {' and '.join(good)}" if good
            else "No" if len(missed) == len(parts)
            else "Cannot tell at 2 SEs")
    widths = ", ".join(f"{w:g}" for w in sorted(set(t["W"].to_list())))
    return f"{head}: at W >= {wide:g} ({widths}), {'; '.join(parts)}."
