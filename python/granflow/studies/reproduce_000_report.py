"""The report of the 000 campaign (:mod:`granflow.studies.reproduce_000`): the fig. 5 numbers
against W and phi_bar beside the paper's statements, figures 4-10, the stiffness test per
zone, error against run time, the coverage audit, the cost of each piece and the paper-scale
recipe (the dataset's rules and point values in reproduce_000_report_values, the verdicts
in _claims, further sections in _cost, _creep, _order and _shape; the figures drawn by
reproduce_000_figures).

Error rules: a point's value is the mean of its steady, stationary replicas with the
larger of the within-run and between-replica SEs (:func:`granflow.analysis.replicas.replica_mean`,
both shown); no SE from fewer than MIN_SE_BLOCKS jackknife blocks ("not enough data");
drifting points are listed and left out of the tables and fits."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl

from granflow.analysis.channel import L_C_PAPER
from granflow.analysis.compare import difference_z, interval_z
from granflow.analysis.coverage import coverage, steady_rows
from granflow.analysis.replicas import mean_profiles as replica_profiles
from granflow.analysis.replicas import replica_mean
from granflow.analysis.stats import MIN_SE_BLOCKS
from granflow.states import FlowState

from ._campaign import (
    ERROR_STATES,
    md_table,
    plot_campaign_se,
    pm,
    point_of,
    sig,
)
from .reproduce_000_figures import (
    plot_fig4,
    plot_fig5,
    plot_fig7,
    plot_fig13,
    plot_profiles,
)
from .reproduce_000_report_claims import (
    PHI_AD_PAPER,
    kinetic_fits,
    ratio_how,
    verdict_lines,
    with_own_ratio,
)
from .reproduce_000_report_cost import cost_section, remaining
from .reproduce_000_report_creep import creep_lines
from .reproduce_000_report_order import order_lines
from .reproduce_000_report_shape import shape_lines
from .reproduce_000_report_values import (
    AUDITED,
    NED,
    PHI_PLUG_PAPER,
    PHI_PLUG_PRINTED,
    POINT_BY,
    RATIO_PAPER,
    REPORTED,
    audit_factors,
    drifting,
    main_depth,
    main_steady,
    point_values,
    pooled,
    refuse_few_blocks,
    with_state_000,
)

#: a difference is significant beyond this many combined SEs; consistent within AGREE
SIGNIFICANT, AGREE = 3.0, 2.0


#: the quantities of the depth check
DEPTH_QUANTITIES = ("u_slip", "u_max", "u_max_over_u_slip", "delta_095", "phi_plug",
                    "wall_friction")


def depth_table(values: pl.DataFrame) -> pl.DataFrame:
    """The depth check: per (W, phi_bar, k_n) run at more than one B, each quantity of
    DEPTH_QUANTITIES per B with its SE and its change from the main depth's value in combined
    SEs (000 runs B = 40; the campaign B = 10)."""
    if not values.height:
        return pl.DataFrame()
    b0 = values["B"].mode().sort()[0]
    rows = []
    for (w, phi, kn), g in values.filter(~pl.col("branch")).group_by(
            ["W", "phi_bar", "kn"], maintain_order=True):
        if g["B"].n_unique() < 2 or b0 not in g["B"].to_list():
            continue
        ref = g.filter(pl.col("B") == b0).row(0, named=True)
        for r in g.sort("B").iter_rows(named=True):
            row: dict[str, Any] = {"W": w, "φ̄": phi, "k_n": kn, "B": r["B"],
                                   "replicas": r["replicas"]}
            for q in DEPTH_QUANTITIES:
                row[q] = pm(r[q], r[f"{q}_se"], 4)
                if r["B"] != b0:
                    row[f"{q} vs B = {b0:g} (SEs)"] = difference_z(
                        r[q], r[f"{q}_se"], ref[q], ref[f"{q}_se"])[2]
            rows.append(row)
    return pl.DataFrame(rows) if rows else pl.DataFrame()


def _depth_section(values: pl.DataFrame) -> list[str]:
    """The depth check as report lines (none without one)."""
    tab = depth_table(values)
    if not tab.height:
        return []
    return ["## Depth (B)", "",
            "000 runs B = 40 d; this campaign B = 10 d. The same W, φ̄ and k_n at other depths: "
            "each quantity with its SE and its change from the main depth in combined SEs "
            "(blank at the main depth).", "",
            md_table(tab, {c: "+.1f" for c in tab.columns if c.endswith("(SEs)")}), ""]


def _se_note(r: dict[str, Any]) -> str:
    """Where a point's SEs come from: its replicas and blocks, or NED."""
    nb = r.get("n_blocks")
    k = r.get("replicas", 1)
    if nb is None or nb < MIN_SE_BLOCKS:
        return f"{NED} ({nb} blocks)"
    return (f"{k} replica{'s' if k > 1 else ''}, ≥ {nb} blocks"
            + (", run SEs × the audit's rms z" if r.get("audit_scaled") else ""))


def with_scaled(d: pl.DataFrame) -> pl.DataFrame:
    """u_slip/sqrt(W), u_max/sqrt(W), delta_095/W and sigma_xx/W with their SEs."""
    out = d
    for col, scale in (("u_slip", pl.col("W").sqrt()), ("u_max", pl.col("W").sqrt()),
                       ("delta_095", pl.col("W")), ("sigma_xx_mean", pl.col("W"))):
        out = out.with_columns((pl.col(col) / scale).alias(f"{col}_scaled"),
                               (pl.col(f"{col}_se") / scale).alias(f"{col}_scaled_se"))
    return out


def fig5_table(steady: pl.DataFrame) -> pl.DataFrame:
    """One row per steady point: the section 3.1 numbers, each ``value ± SE``."""
    d = with_scaled(steady)
    cols = (("u_slip", 2), ("u_max", 2), ("u_max_over_u_slip", 3), ("delta_095", 2),
            ("u_slip_scaled", 3), ("u_max_scaled", 3), ("delta_095_scaled", 3),
            ("mean_velocity_ratio", 4), ("wall_friction", 3))
    names = {"u_max_over_u_slip": "u_max/u_slip", "u_slip_scaled": "u_slip/√W",
             "u_max_scaled": "u_max/√W", "delta_095_scaled": "δ0.95/W", "delta_095": "δ0.95",
             "mean_velocity_ratio": "ū / (3.2)", "wall_friction": "μ_wall"}
    rows = []
    for r in d.iter_rows(named=True):
        row: dict[str, Any] = {"W": r["W"], "φ̄": r["phi_bar"]}
        for c, dig in cols:
            row[names.get(c, c)] = pm(r[c], r[f"{c}_se"], dig)
        row["SEs"] = _se_note(r)
        rows.append(row)
    return pl.DataFrame(rows)


def se_parts_table(steady: pl.DataFrame, cols: Sequence[str] = REPORTED) -> pl.DataFrame:
    """Per point and reported quantity: the SE within runs and between replicas
    (:func:`granflow.analysis.replicas.replica_mean`; ``-``: none, one replica or NED)."""
    rows = []
    for r in steady.iter_rows(named=True):
        row: dict[str, Any] = {"W": r["W"], "φ̄": r["phi_bar"], "replicas": r["replicas"]}
        for c in cols:
            w, b = r.get(f"{c}_se_within", math.nan), r.get(f"{c}_se_between", math.nan)
            row[c] = " / ".join(sig(v) for v in (w, b))
        rows.append(row)
    return pl.DataFrame(rows)


def ratio_by_width(steady: pl.DataFrame) -> pl.DataFrame:
    """u_max/u_slip per W of ``steady`` (with_own_ratio's points: the value says how it was
    got) (inverse-variance mean over phi_bar, rheology.pool_realizations;
    the plain mean, without an SE, where a phi_bar has none) and its distance from 000's range
    1.37-1.40, in SEs where there are SEs."""
    rows = []
    for (w,), g in steady.sort("W").group_by(["W"], maintain_order=True):
        if g["u_max_over_u_slip_se"].is_finite().all():
            m, e = pooled(g, "u_max_over_u_slip")
        else:
            m, e = float(g["u_max_over_u_slip"].mean()), math.nan  # type: ignore[arg-type]
        # (signed: above 1.40 > 0, below 1.37 < 0, inside 0)
        gap = (m - RATIO_PAPER[1] if m > RATIO_PAPER[1] else
               m - RATIO_PAPER[0] if m < RATIO_PAPER[0] else 0.0)
        rows.append({"W": w, "phi_bar": ", ".join(f"{p:g}" for p in g["phi_bar"]),
                     "u_max/u_slip": pm(m, e, 4) + ratio_how(g), "outside 1.37-1.40 by": gap,
                     "in SEs": interval_z(m, e, *RATIO_PAPER),
                     "SE": "" if math.isfinite(e) else NED})
    return pl.DataFrame(rows)


def ratio_trend(steady: pl.DataFrame) -> pl.DataFrame:
    """Per phi_bar with two or more widths: u_max/u_slip = r_inf - c/W fitted over the widths
    (weighted by the SEs; exact through two), r_inf with its SE, and whether it reaches 000's
    1.37-1.40 within two SEs."""
    rows = []
    for (phi,), g in steady.group_by(["phi_bar"], maintain_order=True):
        if g.height < 2:
            continue
        x = 1 / g["W"].to_numpy()
        y, e = g["u_max_over_u_slip"].to_numpy(), g["u_max_over_u_slip_se"].to_numpy()
        known = bool(np.all(np.isfinite(e)))
        # (without SEs: the unweighted line, and no SE of its intercept)
        e = e if known else np.ones_like(y)
        a = np.vstack([np.ones_like(x), -x]).T / e[:, None]
        cov = np.linalg.inv(a.T @ a)
        coef = cov @ (a.T @ (y / e))
        chi2 = float(np.sum(((y - coef[0] + coef[1] * x) / e) ** 2))
        dof = g.height - 2
        se = (math.sqrt(cov[0, 0] * (max(1.0, chi2 / dof) if dof > 0 else 1.0)) if known
              else math.nan)
        gap = max(RATIO_PAPER[0] - coef[0], coef[0] - RATIO_PAPER[1], 0.0)
        rows.append({"φ̄": phi, "widths": ", ".join(f"{w:g}" for w in g["W"]),
                     "r_inf (W → ∞)": pm(float(coef[0]), se, 3),
                     "c": float(coef[1]),
                     "reaches 1.37-1.40": (NED if not known
                                           else "yes" if gap <= 2 * se else "no")})
    return pl.DataFrame(rows)


def collapse(steady: pl.DataFrame) -> pl.DataFrame:
    """Per phi_bar: u_slip/sqrt(W), u_max/sqrt(W) and delta_095/W at the two widest W with a
    steady flow, their relative change and its distance from zero in SEs; and the exponent n
    of u ~ W^n (delta ~ W^n) between them, with its SE (000: u ~ W^1/2 and delta ~ W for
    W >= 100; a local mu(I) law, Cawthorn 2011 quoted in 000 §3.1: u ~ W^3/2)."""
    d = with_scaled(steady)
    rows = []
    for (phi,), g in d.group_by(["phi_bar"], maintain_order=True):
        g = g.sort("W")
        if g.height < 2:
            continue
        a, b = g.row(-2, named=True), g.row(-1, named=True)
        span = math.log(b["W"] / a["W"])
        for raw, name in (("u_slip", "u_slip/√W"), ("u_max", "u_max/√W"),
                          ("delta_095", "δ0.95/W")):
            col = f"{raw}_scaled"
            diff = b[col] - a[col]
            se = math.hypot(a[f"{col}_se"], b[f"{col}_se"])
            n = math.log(b[raw] / a[raw]) / span
            n_se = math.hypot(a[f"{raw}_se"] / a[raw], b[f"{raw}_se"] / b[raw]) / span
            rows.append({"φ̄": phi, "quantity": name, "widths": f"{a['W']:g} → {b['W']:g}",
                         "relative change": diff / a[col], "in SEs": diff / se,
                         "exponent n (∝ W^n)": pm(n, n_se, 2),
                         "SE": "" if math.isfinite(se) else NED})
    return pl.DataFrame(rows)


#: the zone table's quantities with an SE (their within and between parts are shown)
ZONE_SE = ("xi_ad", "phi_plug", "l_c", "omega_ratio_shearing", "sigma_xx_mean")


def zone_table(steady: pl.DataFrame) -> pl.DataFrame:
    """Zones (§3.2), plug phi, conduction length and Omega_z/omega_z per steady point."""
    rows = []
    for r in steady.iter_rows(named=True):
        ph, ph_se = r["phi_plug"], r["phi_plug_se"]
        if not math.isfinite(ph):
            vs = NED if not math.isfinite(r["xi_plug"]) else "-"
        elif not math.isfinite(ph_se):
            vs = NED
        else:
            # 000's ~0.63 printed with two decimals: any value in 0.625-0.635 is "0.63"
            lo, hi = PHI_PLUG_PRINTED
            gap = max(lo - ph, ph - hi, 0.0)
            vs = "inside" if gap == 0.0 else f"{'below' if ph < lo else 'above'} by " \
                f"{gap:.4f} ({gap / ph_se:.1f} SEs)"
        rows.append({"W": r["W"], "φ̄": r["phi_bar"],
                     "xi_plug": NED if not math.isfinite(r["xi_plug"]) else f"{r['xi_plug']:.4g}",
                     "xi_ad": pm(r["xi_ad"], r["xi_ad_se"], 1),
                     "φ plug": NED if not math.isfinite(ph) else pm(ph, ph_se, 4),
                     "φ plug vs 0.625-0.635": vs,
                     "l_c": ("at bound" if r["l_c_at_bound"] else pm(r["l_c"], r["l_c_se"], 1)),
                     "Ω/ω (shearing)": pm(r["omega_ratio_shearing"],
                                          r["omega_ratio_shearing_se"], 4),
                     "σxx/W": pm(r["sigma_xx_mean"] / r["W"], r["sigma_xx_mean_se"] / r["W"],
                                 3),
                     "SEs": _se_note(r)})
    return pl.DataFrame(rows)


def phi_ad_fits(profiles: pl.DataFrame) -> pl.DataFrame:
    """Fit A/(phi_ad - phi) (granflow.analysis.channel.fit_phi_ad) to each kinetic coefficient
    over the loose-zone bins of every steady k_n = 1e5 point (pass only those), pooled
    (fig. 13); the fit needs each bin's SE (fewer than three bins with one: NaN)."""
    rows = []
    for name, f in kinetic_fits(profiles):
        rows.append({"coefficient": name, "bins with an SE": f["n"],
                     "φ_ad": pm(f["phi_ad"], f["phi_ad_se"], 4) if math.isfinite(f["phi_ad"])
                     else NED, "χ²/dof": f["chi2_per_dof"],
                     "from 0.59 ± 0.002 (SEs)": (f["phi_ad"] - PHI_AD_PAPER[0])
                     / math.hypot(f["phi_ad_se"], PHI_AD_PAPER[1])})
    return pl.DataFrame(rows)


# --------------------------------------------------------------------------------------------
# stiffness (fig. 10)
# --------------------------------------------------------------------------------------------
STIFF_QUANTITIES = (("phi", "φ"), ("u", "u"), ("gamma_dot", "du/dx"), ("T", "T"))


def stiffness_table(profiles: pl.DataFrame, points: pl.DataFrame) -> pl.DataFrame:
    """For each branch against its k_n = 1e5 parent (the same seed), per zone of the parent and
    quantity: the mean relative difference over the zone's bins, the median and largest |z|
    (difference / combined SE per bin) and the fraction of bins with |z| > SIGNIFICANT (NaN
    where a bin has no SE: not enough data)."""
    rows = []
    for b in points.filter(pl.col("parent").str.len_chars() > 0).iter_rows(named=True):
        key = {k: b[k] for k in ("W", "phi_bar", "seed", "B", "H")}
        par = profiles.filter(*(pl.col(k) == v for k, v in key.items()),
                              pl.col("parent") == "").sort("xi")
        br = profiles.filter(*(pl.col(k) == v for k, v in key.items()),
                             (pl.col("kn") / b["kn"] - 1).abs() < 1e-9).sort("xi")
        if par.height == 0 or par.height != br.height:
            continue
        for zone in ("plug", "dense", "loose", "wall"):
            m = (par["zone"] == zone).to_numpy()
            if not m.any():
                continue
            for q, name in STIFF_QUANTITIES:
                a, c = par[q].to_numpy()[m], br[q].to_numpy()[m]
                se = np.hypot(par[f"{q}_se"].to_numpy()[m], br[f"{q}_se"].to_numpy()[m])
                z = np.abs(c - a) / se
                known = bool(np.all(np.isfinite(z)))
                rows.append({"k_n": f"{b['kn']:.0e} vs 1e+05", "seed": b["seed"], "zone": zone,
                             "bins": int(m.sum()), "quantity": name,
                             "mean rel. diff.": float(np.mean((c - a) / np.abs(a))),
                             "median |z|": float(np.median(z)) if known else math.nan,
                             "max |z|": float(np.max(z)) if known else math.nan,
                             f"bins |z|>{SIGNIFICANT:g}": (float(np.mean(z > SIGNIFICANT))
                                                           if known else math.nan)})
    return pl.DataFrame(rows)


def stiffness_zone_means(zones: pl.DataFrame, W: float, phi_bar: float) -> pl.DataFrame:
    """Zone means (each run's own zones; granflow.analysis.channel.zone_means) of phi, u,
    |du/dx| and T at every k_n of (W, phi_bar), ``value ± SE`` over the replicas (pass the
    steady ones; replica_mean), a row per zone and quantity."""
    qs = ["phi", "u", "abs_dudx", "T"]
    z0 = zones.filter(pl.col("W") == W, pl.col("phi_bar") == phi_bar)
    if not z0.height:
        return pl.DataFrame()
    by = [*POINT_BY, "zone"]
    fam = replica_mean(z0.with_columns(*(pl.col(c).cast(pl.Float64) for c in
                                         (*qs, *(f"{q}_se" for q in qs)))), by, qs).join(
        z0.group_by(by).agg(pl.col("n_bins").min()), on=by).sort("kn")
    rows = []
    for zone in ("plug", "dense", "loose", "wall"):
        z = fam.filter(pl.col("zone") == zone)
        if not z.height:
            continue
        for q, name in (("phi", "φ"), ("u", "u"), ("abs_dudx", "|du/dx|"), ("T", "T")):
            row: dict[str, Any] = {"zone": zone, "quantity": name}
            for r in z.iter_rows(named=True):
                digits = 4 if q == "phi" else max(2, 3 - int(math.floor(math.log10(
                    max(abs(r[q]), 1e-12)))))
                w, b = r[f"{q}_se_within"], r[f"{q}_se_between"]
                parts = (f" [within {w:.2g} / between {b:.2g}]"
                         if math.isfinite(w) and math.isfinite(b) else "")
                row[f"k_n = {r['kn']:.0e} (bins)"] = f"{pm(r[q], r[f'{q}_se'], digits)} " \
                    f"({r['n_bins']}){parts}"
            rows.append(row)
    return pl.DataFrame(rows)


def stiffness_verdict(tab: pl.DataFrame) -> list[str]:
    """000 §3.2 (fig. 10) in numbers: per k_n and quantity, the bin-weighted mean relative
    change in the dense shearing and plug zones against that in the loose and wall zones.
    The paper's statement holds where du/dx and T change more in the first than in the
    second and phi and u change little in both."""
    if tab.height == 0:
        return ["No branch with a steady, stationary parent in this dataset."]
    out = []
    for (kn,), g0 in tab.group_by(["k_n"], maintain_order=True):
        # (each seed's branch against its own parent; their relative changes averaged)
        g = g0.group_by(["zone", "quantity"], maintain_order=True).agg(
            pl.col("bins").first(), pl.col("mean rel. diff.").mean())
        parts = []
        for _, name in STIFF_QUANTITIES:
            q = g.filter(pl.col("quantity") == name)

            def mean(zs: tuple[str, ...], q: pl.DataFrame = q) -> float:
                z = q.filter(pl.col("zone").is_in(zs))
                if not z.height:
                    return math.nan
                w = z["bins"].to_numpy()
                return float(np.sum(z["mean rel. diff."].to_numpy() * w) / np.sum(w))

            # (du/dx in the plug is zero within its SE: its relative change is noise)
            zs = ("dense",) if name == "du/dx" else ("dense", "plug")
            inner, outer = mean(zs), mean(("loose", "wall"))
            parts.append(f"{name} {inner:+.1%} ({', '.join(zs)}) against {outer:+.1%} "
                         "(loose, wall)")
        out.append(f"- {kn}: " + "; ".join(parts) + ".")
    return out


def mean_profiles(profiles: pl.DataFrame) -> pl.DataFrame:
    """The half profiles of each point (POINT_BY) over its replicas (pass the steady ones):
    per bin ``xi`` every profile quantity's replica mean and SE
    (granflow.analysis.replicas.mean_profiles)."""
    return replica_profiles(profiles, POINT_BY)


# --------------------------------------------------------------------------------------------
# the report
# --------------------------------------------------------------------------------------------
def _read(out: Path, stem: str) -> pl.DataFrame:
    f = out / f"{stem}.parquet"
    return pl.read_parquet(f) if f.exists() else pl.DataFrame()


def _run_table(points: pl.DataFrame) -> pl.DataFrame:
    return points.sort(["kn", "W", "phi_bar", "seed"]).select(
        "W", "phi_bar", pl.col("kn").map_elements(lambda k: f"{k:.0e}", return_dtype=pl.String),
        "B", "H", "seed", "n", "state", "converged", "t_start", "T_avg", "t_run",
        pl.col("n_blocks").alias("blocks"),
        pl.col("prep_seconds").alias("prep (s)"), pl.col("wall_seconds").alias("wall (s)"))


Section = tuple[list[str], list[Path]]


def stop_rule(plan: Any) -> str:
    """The plan's stop rule in words (reproduce_000's module docstring)."""
    seeds: dict[tuple[Any, ...], int] = {}
    for p in plan.points:
        key = tuple(getattr(p, c) for c in POINT_BY)
        seeds[key] = seeds.get(key, 0) + 1
    k = max(seeds.values()) if seeds else 0
    fewer = sorted({(key[0], key[3]) for key, n in seeds.items() if n < k}, reverse=True)
    # (POINT_BY's W and B: the wide runs and the depth check's, where one seed is planned;
    # B named where it is not the plan's main depth)
    depths = [p.B for p in plan.points]
    main_b = max(set(depths), key=depths.count) if depths else math.nan
    short = (" (one at " + ", ".join(f"W = {w:g}" + (f", B = {b:g}" if b != main_b else "")
                                     for w, b in fewer) + ")") if fewer else ""
    return (f"Each point runs with {k} seed{'s' if k != 1 else ''}{short}, in stints of "
            f"{plan.stint:g} √(d/g). It stops when it is steady (the last half of |v_cm| "
            "steady or fluctuating by granflow.analysis.channel_profiles.flow_state), "
            "stationary (the thirds test of u_slip, u_max, the mean velocity and the mean σxx "
            "per window, granflow.analysis.channel.steady_check: a drifting run is "
            "\"drifting\" and runs on) and its steady part ("
            + (f"from t = {plan.t_dev:g}, 000's development time" if plan.t_dev
               else "MSER start") + ") spans at least "
            f"{plan.min_average:g} √(d/g) and {plan.min_taus:g} integrated correlation times "
            "of the slowest of those quantities; only then are the SE targets consulted "
            f"(the jackknife SEs of u_slip and u_max within {plan.se_target:.0%}; no SE from "
            f"fewer than {MIN_SE_BLOCKS} blocks). Or it arrests for two stints, or "
            f"reaches t = {plan.t_max:g}."
            + (f" So every run that flows is {plan.t_max:g} long (000's protocol): no SE "
               "decides when it stops, and one that misses its SE target or drifts is "
               "reported as it is." if plan.t_dev and plan.t_dev + plan.min_average
               >= plan.t_max else ""))


def _runs_section(points: pl.DataFrame, plan: Any) -> list[str]:
    per = (points.filter(pl.col("parent") == "").group_by(list(POINT_BY)).len()["len"]
           .to_numpy() if points.height else np.zeros(1, dtype=np.int64))
    lo, hi = int(per.min()), int(per.max())
    lines = ["## What was run", "",
             f"{points.height} channel runs (granflow.scenes.channel.Channel: 000's material "
             "and contact law, e_n = 0.82, μ_p = 0.5, k_t = 2/7 k_n, the 0.9/1.0/1.1 mix; "
             "fill and release), at reduced depth and height (B, H below; 000: B = 40, "
             "H = 60 + ΔH) and k_n = 1e5 with dt = 1.2e-4 √(1e6/k_n), ten times fewer steps "
             "than 000's k_n = 1e6 (what that costs in accuracy: the k_n line of the findings "
             "and the stiffness section).", "",
             "The rule (`--" + plan.name + "`): " + stop_rule(plan), ""]
    if "tau_max" not in points.columns:
        # (a dataset written before the stationarity test and the minimum length has no
        # tau_max column)
        lines += ["**This dataset was run under the earlier rule**: "
                  + ("1 seed per point" if hi == lo == 1 else f"{lo}-{hi} seeds per point")
                  + ", no stationarity test, and "
                  "each point stopped as soon as the SEs of u_slip and u_max met their target "
                  "after the minimum averaging time, without a minimum in correlation times "
                  "(optional stopping: its SEs are biased small). It is re-run under the rule "
                  "above in a later issue (000 at the paper's widths). Below, its SEs from "
                  f"fewer than {MIN_SE_BLOCKS} jackknife blocks (`blocks`) are refused "
                  f"({NED}).", ""]
    lines += ["States: " + ", ".join(f"{k} {v}" for k, v in sorted(
                  points["state"].value_counts().iter_rows())) + ". " + _drift_line(points)
              + _earlier_cap_line(points, plan)
              + " `prep (s)` is the wall time of the fill and release, `wall (s)` all of the "
              "point's (both on one core shared with one other point).", "",
              md_table(_run_table(points), {"t_start": ".0f", "T_avg": ".0f", "t_run": ".0f",
                                            "prep (s)": ".1f", "wall (s)": ".0f"}), ""]
    return lines


def _earlier_cap_line(points: pl.DataFrame, plan: Any) -> str:
    """The runs that stopped, unconverged, more than a stint short of their present cap
    (:meth:`Plan.limits`): run under an earlier, lower cap (their rows stay; their copies
    cannot go on), or ""."""
    if not points.height or "converged" not in points.columns or not plan.points:
        return ""
    cls = type(plan.points[0])
    short = [r for r in points.iter_rows(named=True)
             if not r["converged"] and r["state"] not in (FlowState.ARRESTED.value, *ERROR_STATES)
             and r["t_end"] < plan.limits(point_of(cls, r))[0] - plan.stint]
    if not short:
        return ""
    return (" Ended at an earlier cap (t = " + ", ".join(
        f"{t:.0f}" for t in sorted({round(r["t_end"], -1) for r in short})) + "), unconverged, "
        f"where the cap is now t = {plan.t_max:g}: " + "; ".join(
        f"W = {r['W']:g}, φ̄ = {r['phi_bar']:g}, seed {r['seed']} ({r['state']})"
        for r in short) + ".")


def _drift_line(points: pl.DataFrame) -> str:
    """The drifting runs, by name, or why none are known."""
    if "drift_z" not in points.columns:
        return ("Drifting runs: not tested (the dataset predates the stationarity test; its "
                "runs carry no drift_z).")
    d = drifting(points)
    if not d.height:
        return "Drifting runs (left out of the tables and fits): none."
    return "Drifting runs (left out of the tables and fits): " + "; ".join(
        f"W = {r['W']:g}, φ̄ = {r['phi_bar']:g}, k_n = {r['kn']:.0e}, seed {r['seed']} "
        f"({r['drift_quantity']}: |z| = {r['drift_z']:.1f})"
        for r in d.iter_rows(named=True)) + "."


def _fig5_section(steady: pl.DataFrame, ratios: pl.DataFrame, profiles: pl.DataFrame,
                  figdir: Path) -> Section:
    # (``ratios``: ``steady`` with_own_ratio, for the ratio's table and trend)
    figs = [plot_fig4(steady, profiles, POINT_BY, figdir / "fig4_velocity.png"),
            plot_fig5(with_scaled(steady), figdir / "fig5_scaling.png", RATIO_PAPER),
            plot_fig7(with_scaled(steady), figdir / "fig7_stress_wall_friction.png")]
    lines = ["## Fig. 5: velocity scaling against W and φ̄", "",
             md_table(fig5_table(steady)), "",
             "Each value is the mean over a point's steady replicas; its SE the larger of the "
             "SE within runs and the SE between replicas (granflow.analysis.replicas."
             "replica_mean), both below (within / between; `-`: one replica, or "
             f"{NED}); with one replica, its run SE times the coverage audit's rms z where "
             "the audit finds the run SEs too small (the SEs column says so):", "",
             md_table(se_parts_table(steady)), "",
             "u_max/u_slip per width (000: 1.37-1.40 for W = 60-150 and every φ̄):", "",
             md_table(ratio_by_width(ratios),
                      {"outside 1.37-1.40 by": "+.3f", "in SEs": ".1f"}), ""]
    trend = ratio_trend(ratios)
    if trend.height:
        lines += ["Does it approach 1.37-1.40 as W grows? u_max/u_slip = r_inf - c/W "
                  "fitted per φ̄ over the widths with a steady flow (two widths: the line "
                  "through them; an extrapolation, not a measurement):", "",
                  md_table(trend, {"c": ".2f"}), ""]
    col = collapse(steady)
    if col.height:
        lines += ["Collapse (000: u/√W and δ0.95/W independent of W for W ≥ 100, not "
                  "quite at 60; a local μ(I) law gives u ∝ W^3/2, Cawthorn 2011 in 000 §3.1): "
                  "the change between the two widest steady widths per φ̄ and the exponent "
                  "of W between them", "",
                  md_table(col, {"relative change": "+.3f", "in SEs": "+.1f"}), ""]
        if not col["in SEs"].is_finite().all():
            lines += [f"`in SEs` is `-` where a width's SE is {NED}: those changes are "
                      "values without an error, not significant differences.", ""]
    return lines, figs


def _zones_section(steady: pl.DataFrame, profiles: pl.DataFrame, means: pl.DataFrame,
                   order: pl.DataFrame, figdir: Path) -> Section:
    lines = ["## Zones, plug and conduction length (§3.2, figs 8-9, B13)", "",
             f"000: φ in the plug ~{PHI_PLUG_PAPER} (two decimals: 0.625-0.635), Ω_z/ω_z = 1/2 "
             f"in the shearing zones, l_c ≈ {L_C_PAPER} d, σxx ∝ W (fig. 7a), μ_wall "
             "independent of W and falling with φ̄ (fig. 7b). xi_plug, xi_ad: the plug edge "
             "and the φ = φ_ad crossing (distance from the wall). The plug edge needs the SE "
             "of du/dx (zero shear within its error): where that SE is "
             f"{NED}, xi_plug, φ plug and l_c are too.", "",
             md_table(zone_table(steady)), "",
             "Their SEs within runs and between replicas (as for fig. 5):", "",
             md_table(se_parts_table(steady, ZONE_SE)), "",
             "φ_ad from fig. 13 (000: the loose-zone coefficients diverge as "
             "(φ_ad - φ)^-1 with φ_ad = 0.59 ± 0.002): a fit to the loose-zone bins with an "
             "SE of every steady point, pooled:", "",
             md_table(phi_ad_fits(profiles), {"χ²/dof": ".2f",
                                              "from 0.59 ± 0.002 (SEs)": "+.1f"}), "",
             "Each φ_ad's SE is widened by √(χ²/dof) where that exceeds 1; a χ²/dof far "
             "above 1 says the form does not describe the bins at their SEs, so the φ_ad it "
             "places is no measured divergence (the verdicts judge the claim at 000's widths "
             "on that ground).", "",
             *order_lines(order, profiles, steady, POINT_BY)]
    wide = steady.filter(pl.col("W") == steady["W"].max())
    w = f"W = {wide['W'][0]:g}"
    # units: lengths d, velocities √(gd), stresses ρ_p g d (granflow.analysis.channel_profiles)
    figs = [plot_fig13(profiles, figdir / "fig13_kinetic.png"),
            plot_profiles(wide, means, POINT_BY, figdir / "fig6_stress.png",
                          f"fig. 6: stresses, {w}",
                          (("sigma_xx", "σxx (ρ_p g d)", False),
                           ("sigma_xy", "σxy (ρ_p g d)", False))),
            plot_profiles(wide, means, POINT_BY, figdir / "fig8_profiles.png",
                          f"fig. 8: φ, |du/dx|, T, production, dissipation, {w}",
                          (("phi", "φ", False), ("gamma_dot", "|du/dx| (√(g/d))", True),
                           ("T", "T (g d)", True),
                           ("production", "σxy du/dx (ρ_p g^3/2 d^1/2)", True),
                           ("Gamma", "dissipation Γ (ρ_p g^3/2 d^1/2)", True))),
            plot_profiles(wide, means, POINT_BY, figdir / "fig9_rotation.png",
                          f"fig. 9: Ω_z/ω_z and (du/dx)/√T, {w} (y-range: sheared bins)",
                          (("omega_ratio", "Ω_z/ω_z", False),
                           ("gamma_over_sqrtT", "|du/dx| d/√T", False)),
                          shear_only=("omega_ratio", "gamma_over_sqrtT"),
                          refs={"omega_ratio": (0.5, "000: 1/2")})]
    return lines, figs


def _stiffness_section(points: pl.DataFrame, values: pl.DataFrame, profiles: pl.DataFrame,
                       means: pl.DataFrame, zones: pl.DataFrame, figdir: Path) -> Section:
    branches = points.filter(pl.col("parent").str.len_chars() > 0)
    if not branches.height or not values.height:
        return [], []
    tab = stiffness_table(profiles, points)
    if not tab.height:
        return ["## Stiffness (fig. 10)", "", *stiffness_verdict(tab), ""], []
    fam = values.filter(pl.col("W") == branches["W"][0],
                        pl.col("phi_bar") == branches["phi_bar"][0]).sort("kn")
    fig = plot_profiles(fam, means, POINT_BY, figdir / "fig10_stiffness.png",
                        f"fig. 10: k_n, W = {fam['W'][0]:g}, φ̄ = {fam['phi_bar'][0]:g}",
                        (("phi", "φ", False), ("u", "u", False),
                         ("gamma_dot", "|du/dx|", True), ("T", "T", True)),
                        label=lambda r: f"k_n = {r['kn']:.0e}")
    lines = ["## Stiffness (fig. 10)", "",
             "000 §3.2 (fig. 10): φ, u, du/dx and T are independent of k_n in the wall and loose "
             "zones; du/dx, and T more strongly, depend on k_n in the dense shearing and "
             "plug zones (T in the plug falls as k_n grows). Here: the k_n = 1e5 run's "
             "final state run on at each k_n (module docstring), compared bin by bin in "
             "the zones of the k_n = 1e5 run:", "",
             md_table(tab, {"mean rel. diff.": "+.3f", "median |z|": ".1f", "max |z|": ".1f"}),
             "", f"(median and max |z| are `-` where a bin's SE is {NED}: those relative "
             "differences are values without an error.)", "", *stiffness_verdict(tab), "",
             "Zone means over the replicas with their SEs (each run's own zones; "
             f"without an SE where it is {NED}):", "",
             md_table(stiffness_zone_means(zones, fam["W"][0], fam["phi_bar"][0])), ""]
    return lines, [fig]


#: the quarter's SE over the whole part's at least this fraction of T^-1/2's 2: converged
SE_CONVERGED = 0.75


def _se_section(se: pl.DataFrame, figdir: Path, ruled: bool = False) -> Section:
    """The error against run time from ``se`` (se_vs_time.parquet, less the drifting runs).
    ``ruled``: the dataset's runs followed the present stop rule (its minimum length in
    correlation times and the 10-block rule)."""
    if not se.height:
        return [], []
    key = [*POINT_BY, "seed"]

    def ratio(c: str) -> pl.Expr:
        # (over the points with both SEs: a stretch under 10 blocks has none)
        r = pl.col(f"{c}_se") / pl.col(f"{c}_se_all")
        return r.filter(r.is_finite()).median().fill_null(math.nan).alias(f"SE({c})/SE(all)")

    shrink = se.join(se.filter(pl.col("fraction") == 1.0), on=key, suffix="_all").group_by(
        "fraction").agg(
        ratio("u_slip"), ratio("u_max"),
        pl.col("n_blocks").median().alias("blocks (median)"),
        pl.len().alias("points"),
    ).sort("fraction").with_columns((1 / pl.col("fraction").sqrt()).alias("expected (T^-1/2)"))
    lines = ["## Error against run time", "",
             "The jackknife SEs of u_slip and u_max from the first quarter, half and all "
             "of each point's steady part, as the campaign computed them (whatever their "
             "number of blocks), as a ratio to the SE from all of it (median over points). "
             "A converged SE of a stationary series shrinks as T^-1/2 (last column).", "",
             md_table(shrink, {"blocks (median)": ".0f"}), ""]
    # (the shortest stretch with SEs: a null ratio had no point with the blocks for one)
    has = shrink.filter((pl.col("fraction") < 1.0) & pl.col("SE(u_slip)/SE(all)").is_finite()
                        & pl.col("SE(u_max)/SE(all)").is_finite())
    if not has.height:
        lines += [f"No stretch shorter than a whole steady part has {MIN_SE_BLOCKS} blocks "
                  "for an SE yet: the error against run time needs longer averages.", ""]
        has = shrink.tail(1)
    q = has.row(0, named=True)
    want = q["expected (T^-1/2)"]
    got = (q["SE(u_slip)/SE(all)"], q["SE(u_max)/SE(all)"])
    if all(math.isfinite(g) for g in got) and min(got) < SE_CONVERGED * want:
        lines += [f"**The SEs had not converged.** The SE from the first {q['fraction']:g} of "
                  f"a steady part is {got[0]:.2f} (u_slip) and {got[1]:.2f} (u_max) times the "
                  f"SE from all of it, where converged SEs give {want:.2g}: a run "
                  f"{1 / q['fraction']:g} times longer did not shrink its SE. Each SE saw only "
                  "the fluctuations shorter than its blocks; the flow wanders more slowly "
                  "than that, so every SE of this dataset, the whole part's included, is an "
                  + ("underestimate. These runs followed the minimum length in correlation "
                     f"times and the {MIN_SE_BLOCKS}-block rule, and that was not enough: the "
                     "replicas' spread (the coverage audit below) measures what the run SEs "
                     "miss, and each point's SE takes it where it is larger."
                     if ruled else
                     "underestimate of unknown size. The minimum length in correlation times, "
                     f"the {MIN_SE_BLOCKS}-block rule and the replicas' spread "
                     "(the rule above) are the remedy; this dataset predates them."), ""]
    elif all(math.isfinite(g) for g in got):
        lines += [f"The SE from the first {q['fraction']:g} of a steady part is "
                  f"{got[0]:.2f} (u_slip) and {got[1]:.2f} (u_max) times the whole part's, "
                  f"within {1 - SE_CONVERGED:.0%} of T^-1/2's {want:.2g}.", ""]
    return (lines,
            [plot_campaign_se(se, figdir / "se_vs_time.png", ("u_slip", "u_max"), key,
                              xlabel="steady averaging time T (√(d/g))", relative=True,
                              target=0.01, label=lambda r: f"W = {r['W']:g}, φ̄ = "
                              f"{r['phi_bar']:g}, k_n = {r['kn']:.0e}, seed {r['seed']}")])


def coverage_table(points: pl.DataFrame) -> pl.DataFrame:
    """The coverage audit (granflow.analysis.coverage.coverage) of the reported quantities
    over the steady replicas of ``points``, grouped by the point's fields less the seed
    (POINT_BY; the parent key names its parent's seed, so it is left out)."""
    obs = [c for c in (*REPORTED, *AUDITED) if c in points.columns]
    return coverage(steady_rows(points), POINT_BY, obs)


def coverage_verdicts(tab: pl.DataFrame) -> list[str]:
    """What the audit ``tab`` (:func:`coverage_table`) says of each observable with pairs:
    its run SEs too small (the 95 % interval of rms z above 1), too large (below 1), or
    consistent with honest ones."""
    small: list[str] = []
    large: list[str] = []
    fine: list[str] = []
    for r in tab.filter(pl.col("pairs") > 0).iter_rows(named=True):
        label = f"{r['observable']} ({r['rms_z']:.2f})"
        (small if r["rms_z_lo"] > 1 else large if r["rms_z_hi"] < 1 else fine).append(label)
    out = []
    if small:
        out.append("**The run SEs are too small** for " + ", ".join(small) + ": the "
                   "replicas differ by more than their SEs allow: a mode slower than the runs, "
                   "or each run's own preparation (φ plug, which no shear rearranges once the "
                   "plug has formed, is among them). The points' SEs above are the larger of "
                   "the within-run and between-replica ones, so there they rest on the "
                   "replicas' spread; a point with one replica has no spread to rest on, so "
                   "its SEs of these quantities are its run SEs times that rms z (an "
                   "assumption: that its run falls short by as much as the replicated "
                   "points' runs do).")
    if large:
        out.append("The run SEs are too large for " + ", ".join(large) + ".")
    if fine:
        out.append("Consistent with honest SEs (rms z within its 95 % interval of 1): "
                   + ", ".join(fine) + ".")
    return out


def _coverage_section(points: pl.DataFrame, out: Path, tab: pl.DataFrame) -> list[str]:
    """The audit ``tab`` (:func:`coverage_table` of ``points``) and what it says."""
    per = steady_rows(points).group_by(list(POINT_BY)).len()["len"] if points.height else None
    cmd = (f"python -m granflow.analysis.coverage {out} --by {','.join(POINT_BY)} "
           f"--observables {','.join(tab['observable'])}")
    lines = ["## Coverage audit", "",
             "For every pair of steady replicas of a point and each reported quantity, "
             "z = (x_a - x_b)/√(SE_a² + SE_b²); the rms of z over the pairs is 1 for honest "
             "SEs, with its 95 % interval (chi-squared, one degree of freedom per replica "
             f"beyond the first). The command: `{cmd}` (this table applies the "
             f"{MIN_SE_BLOCKS}-block rule to the dataset first).", "",
             md_table(tab, {"rms_z": ".2f", "rms_z_lo": ".2f", "rms_z_hi": ".2f",
                            "max_abs_z": ".1f"}), ""]
    lines += [x for v in coverage_verdicts(tab) for x in (v, "")] if tab.height else []
    lines += creep_lines(points, POINT_BY)
    pairs = int(tab["pairs"].sum()) if tab.height else 0
    if pairs == 0:
        k = int(per.to_numpy().max()) if per is not None and per.len() else 0
        lines += [f"**No pairs: coverage cannot be audited on this dataset.** It holds at most "
                  f"{k} steady replica{'s' if k != 1 else ''} of a point"
                  + (f" (or their SEs are {NED})" if k > 1 else "")
                  + "; the audit needs the re-run with 3 seeds.", ""]
    return lines


#: the states of a run whose flow still speeds up or slows down (flow_state's trend test)
MOVING = (FlowState.ACCELERATING.value, FlowState.DECELERATING.value)


def unsettled_lines(flow: pl.DataFrame) -> list[str]:
    """A line per run of ``flow`` whose last state is accelerating or decelerating: how much
    |v_cm| changed over the last half of the run (``rel_drift``, the trend over that half),
    since such a run has no steady value and so is in no table, fit or verdict."""
    if not flow.height or "rel_drift" not in flow.columns:
        return []
    moving = flow.filter(pl.col("state").is_in(MOVING)).sort("W", "phi_bar", "seed")
    return [f"- W = {r['W']:g}, φ̄ = {r['phi_bar']:g}, seed {r['seed']}: still {r['state']} "
            f"at t = {r['t_end']:.0f}, |v_cm| {r['rel_drift']:+.1%} over its last half "
            f"(t = {r['t_end'] / 2:.0f}-{r['t_end']:.0f}): no steady value, so in no table, "
            "fit or verdict." for r in moving.iter_rows(named=True)]


def findings(points: pl.DataFrame, values: pl.DataFrame) -> list[str]:
    """The answers to the paper's claims, in words, from the tables below (``values``:
    :func:`point_values`)."""
    steady = main_steady(values)
    out = ["## Findings", ""]
    # (a drifting run with its v_cm state, 000's)
    flow = with_state_000(points.filter(pl.col("parent") == "")).with_columns(
        pl.when((pl.col("state") == FlowState.DRIFTING.value)
                & pl.col("state_000").is_not_null())
        .then(pl.format("{} (v_cm {})", "state", "state_000"))
        .otherwise(pl.col("state")).alias("state"))
    for (w,), g in flow.sort("phi_bar", "seed").group_by(["W"], maintain_order=True):
        states = "; ".join(
            f"φ̄ {p:g}: " + ", ".join(f"{s}{f' x{n}' if n > 1 else ''}"
                                    for s, n in h.group_by("state", maintain_order=True)
                                    .len().iter_rows())
            for (p,), h in g.group_by(["phi_bar"], maintain_order=True))
        out.append(f"- W = {w:g}: {states} (000, W = 60-150: steady for φ̄ = 0.59-0.61, "
                   "fluctuating at 0.62, jammed above).")
    out += unsettled_lines(flow)
    ratios = with_own_ratio(steady, points)
    ratio_rows = ratio_by_width(ratios) if steady.height else pl.DataFrame()
    for r in ratio_rows.iter_rows(named=True):
        gap = r["outside 1.37-1.40 by"]
        where = (f"{gap:.3f} above 000's 1.40" if gap > 0 else
                 f"{-gap:.3f} below 000's 1.37" if gap < 0 else "inside 000's 1.37-1.40")
        out.append(f"- u_max/u_slip at W = {r['W']:g}: {r['u_max/u_slip']} (φ̄ = "
                   f"{r['phi_bar']}), {where}"
                   + (f" (SE: {NED})." if r["SE"] else f", {r['in SEs']:.1f} SEs."))
    for r in (ratio_trend(ratios) if steady.height else pl.DataFrame()).iter_rows(named=True):
        verdict = {"yes": "within 2 SEs of 000's 1.37-1.40.",
                   "no": "outside 000's 1.37-1.40 by more than 2 SEs."}.get(
            r["reaches 1.37-1.40"], f"no SE ({NED}): whether it reaches 1.37-1.40 is not "
            "tested.")
        out.append(f"- φ̄ = {r['φ̄']:g}: extrapolated to W → ∞ over W = {r['widths']}, "
                   f"u_max/u_slip → {r['r_inf (W → ∞)']}: " + verdict)
    branches = points.filter(pl.col("parent") != "")
    fam = pl.DataFrame()
    if branches.height and values.height:
        b0 = branches.row(0, named=True)
        fam = values.filter(pl.col("W") == b0["W"], pl.col("phi_bar") == b0["phi_bar"]
                            ).sort("kn")
        known = fam["u_slip_se"].is_finite().all() and fam["u_max_over_u_slip_se"].is_finite(
        ).all()
        out.append(f"- k_n at W = {b0['W']:g}, φ̄ = {b0['phi_bar']:g}: u_slip "
                   + ", ".join(f"{pm(r['u_slip'], r['u_slip_se'], 2)} ({r['kn']:.0e})"
                               for r in fam.iter_rows(named=True))
                   + "; u_max/u_slip "
                   + ", ".join(f"{pm(r['u_max_over_u_slip'], r['u_max_over_u_slip_se'], 3)}"
                               for r in fam.iter_rows(named=True))
                   + ("" if known else f" (SEs: {NED})")
                   + " (the stiffness section has the zones).")
    for r in (collapse(steady) if steady.height else pl.DataFrame()).iter_rows(named=True):
        rel, z = r["relative change"], r["in SEs"]
        if math.isfinite(z):
            ok = abs(z) < SIGNIFICANT or abs(rel) < 0.02
            said = f"{rel:+.1%} ({z:+.1f} SEs)"
            verdict = "collapses (within 2 % or 3 SEs)." if ok else "does not collapse."
        else:
            said = f"{rel:+.1%} (SE: {NED})"
            verdict = ("within 2 %, but without an SE whether it collapses is not tested."
                       if abs(rel) < 0.02 else
                       "a change without an error: whether it collapses is not tested.")
        out.append(f"- {r['quantity']} at φ̄ = {r['φ̄']:g}, W {r['widths']}: {said}, the "
                   f"unscaled quantity ∝ W^n with n = {r['exponent n (∝ W^n)']}: " + verdict)
    widest = (f"W = {float(np.max(steady['W'].to_numpy())):g}" if steady.height
              else "none (no steady point)")
    out += ["", "Why the numbers differ from 000's, as far as this campaign can tell:", "",
            f"- Width: 000's ratio and collapse claims are for W = 60-150 (collapse only for "
            f"W >= 100); the widest steady channel here: {widest}."
            + (" u_max/u_slip (the per-width lines above) rises with W, from "
               f"{ratio_rows['u_max/u_slip'][0].split(' ')[0]} at W = {ratio_rows['W'][0]:g} to "
               f"{ratio_rows['u_max/u_slip'][-1].split(' ')[0]} at W = {ratio_rows['W'][-1]:g} "
               "(000: 1.37-1.40 at every W)"
               + (f" (values; their SEs: {NED})." if any(ratio_rows["SE"]) else ".")
               if ratio_rows.height > 1 and bool(np.all(np.diff(
                   [float(x.split(" ")[0]) for x in ratio_rows["u_max/u_slip"]]) > 0))
               else "")]
    if fam.height > 1:
        base = fam.filter((pl.col("kn") / 1e5 - 1).abs() < 1e-9)
        if base.height:
            b = base.row(0, named=True)
            others = fam.filter((pl.col("kn") / 1e5 - 1).abs() >= 1e-9)
            du = ", ".join(f"{r['u_slip'] / b['u_slip'] - 1:+.1%} at {r['kn']:.0e}"
                           for r in others.iter_rows(named=True))
            dr = max(abs(r["u_max_over_u_slip"] - b["u_max_over_u_slip"])
                     for r in others.iter_rows(named=True))
            out.append(f"- Stiffness: against k_n = 1e5, u_slip is {du}; u_max/u_slip moves "
                       f"by at most {dr:.3f} (measured here: the k_n line above"
                       + ("" if known else f"; SEs {NED}") + ").")
    bh = ", ".join(f"B = {b:g}, H = {h:g}" for b, h in
                   points.select("B", "H").unique().sort("B", "H").iter_rows()) \
        if points.height else "-"
    out.append(f"- Depth and height: {bh} instead of B = 40 and H = 60 + ΔH (the cost: "
               "the particle count scales with B H). Not tested here; one W = 60 point at "
               "B = 40 is the next check (the paper-scale recipe below runs B = 40).")
    return out + [""]


def _of_steady(points: pl.DataFrame, table: pl.DataFrame) -> pl.DataFrame:
    """The rows of ``table`` (profiles, zones) that belong to a steady replica of ``points``."""
    if not table.height:
        return table
    key = [*POINT_BY, "seed"]
    return table.join(steady_rows(points).select(key), on=key, how="semi")


def write_report(out: Path, path: Path, plan: Any, paper: Any) -> Path:
    """Write the markdown report for the dataset in ``out`` (campaign ``plan``) to ``path``
    (figures beside it, in ``<path stem>_figures/``), with the cost of the ``paper`` plan."""
    raw = _read(out, "points")
    if not raw.height:
        path.parent.mkdir(parents=True, exist_ok=True)
        n = len(plan.points) + len(getattr(plan, "branches", ())) + len(getattr(plan, "later",
                                                                              ()))
        path.write_text(f"# Reproducing 000 ({plan.name} campaign)\n\nNo finished point yet "
                        f"in {out}: {n} planned. Run `python -m granflow.studies.reproduce_000 "
                        f"--{plan.name} --out {out} --report {path}`; it resumes from what is "
                        "there.\n\n" + "\n".join(remaining(out, plan)))
        return path
    # (a drifting run's steady part is not stationary: T^-1/2 is not what its SE should do)
    se = _read(out, "se_vs_time")
    if se.height and raw.height:
        se = se.join(drifting(raw).select(*POINT_BY, "seed"), on=[*POINT_BY, "seed"],
                     how="anti")
    # the 10-block rule, applied to the dataset as the analysis now applies it
    points = refuse_few_blocks(raw) if raw.height else raw
    profiles = _of_steady(points, refuse_few_blocks(raw, _read(out, "profiles")))
    zones = _of_steady(points, refuse_few_blocks(raw, _read(out, "zones")))
    audit = coverage_table(points) if points.height else pl.DataFrame()
    factors = audit_factors(audit)
    every_depth = point_values(points, factors) if points.height else pl.DataFrame()
    values = main_depth(every_depth)
    steady = main_steady(values)
    means = mean_profiles(profiles)
    figdir = path.parent / f"{path.stem}_figures"
    lines = [f"# Reproducing 000: the channel across W and φ̄ ({plan.name} campaign)", "",
             "Generated by `python -m granflow.studies.reproduce_000 "
             f"--{plan.name} --out {out} --report {path}` (from the committed data: add "
             "`--only-report`); the datasets read back with "
             f"`pl.read_parquet('{out}/points.parquet')` (one row per run; also "
             "`profiles.parquet`, half profiles with SEs and zone labels, `zones.parquet`, "
             "zone means, and `se_vs_time.parquet`). Section numbers (§) are 000's.", "",
             *verdict_lines(points, values, profiles, factors), *findings(points, values),
             *_depth_section(every_depth), *_runs_section(points, plan)]
    figs: list[Path] = []
    sections = [_stiffness_section(points, values, profiles, means, zones, figdir),
                _se_section(se, figdir, ruled=bool(
                    "tau_max" in points.columns and points["tau_max"].null_count() == 0)),
                (_coverage_section(points, out, audit), [])]
    if steady.height:
        sections[:0] = [_fig5_section(steady, with_own_ratio(steady, points), means, figdir),
                        _zones_section(steady, profiles, means,
                                       _of_steady(points, _read(out, "order")), figdir)]
    for text, f in sections:
        lines += text
        figs += f
    lines += shape_lines(points, POINT_BY)
    lines += ["## Figures", ""] + [f"![{p.stem}]({p.relative_to(path.parent)})"
                                   for p in figs] + [""]
    if points.height and points["steps"].sum():
        lines += cost_section(points, paper)[0]
    lines += remaining(out, plan)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    return path
