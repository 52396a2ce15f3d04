"""The report of the 000 campaign (:mod:`granflow.studies.reproduce_000`): the fig. 5 numbers
against W and phi_bar beside the paper's statements, figures 4-10, the stiffness test per
zone, error against run time, the cost of each piece and the paper-scale recipe."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl

from granflow.analysis.channel import L_C_PAPER, PHI_AD, PHI_RCP, fit_phi_ad, scaled_profile_31
from granflow.analysis.plots import save_figure

from ._campaign import cost, dask_recipe, md_table, paper_scale_estimate, plot_campaign_se, pm

#: 000 §3.1: u_max/u_slip "varying by about 2 % in a very small range 1.37-1.40"
RATIO_PAPER = (1.37, 1.40)
#: 000 §3.2: phi in the plug "~0.63"
PHI_PLUG_PAPER = 0.63
#: a difference is significant beyond this many combined SEs; consistent within AGREE
SIGNIFICANT, AGREE = 3.0, 2.0
MARKERS = {0.59: "D", 0.6: "v", 0.61: "^", 0.62: "o"}


def _steady(points: pl.DataFrame, kn: float | None = 1e5) -> pl.DataFrame:
    d = points.filter(pl.col("state").is_in(["steady", "fluctuating"]))
    if kn is not None:
        d = d.filter((pl.col("kn") / kn - 1).abs() < 1e-9)
    return d.sort(["W", "phi_bar"])


def _with_scaled(d: pl.DataFrame) -> pl.DataFrame:
    """u_slip/sqrt(W), u_max/sqrt(W), delta_095/W and sigma_xx/W with their SEs."""
    out = d
    for col, scale in (("u_slip", pl.col("W").sqrt()), ("u_max", pl.col("W").sqrt()),
                       ("delta_095", pl.col("W")), ("sigma_xx_mean", pl.col("W"))):
        out = out.with_columns((pl.col(col) / scale).alias(f"{col}_scaled"),
                               (pl.col(f"{col}_se") / scale).alias(f"{col}_scaled_se"))
    return out


def fig5_table(steady: pl.DataFrame) -> pl.DataFrame:
    """One row per steady point: the section 3.1 numbers, each ``value ± SE``."""
    d = _with_scaled(steady)
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
        rows.append(row)
    return pl.DataFrame(rows)


def ratio_by_width(steady: pl.DataFrame) -> pl.DataFrame:
    """u_max/u_slip per W (inverse-variance mean over phi_bar, rheology.pool_realizations)
    and its distance from 000's range 1.37-1.40 in SEs."""
    from granflow.analysis.rheology import pool_realizations

    cols = ["W", "u_max_over_u_slip", "u_max_over_u_slip_se"]
    pooled = pool_realizations(steady.select(cols), by=["W"])
    rows = []
    for r in pooled.iter_rows(named=True):
        m, e = r["u_max_over_u_slip"], r["u_max_over_u_slip_se"]
        phis = steady.filter(pl.col("W") == r["W"])["phi_bar"]
        gap = max(RATIO_PAPER[0] - m, m - RATIO_PAPER[1], 0.0)
        rows.append({"W": r["W"], "phi_bar": ", ".join(f"{p:g}" for p in phis),
                     "u_max/u_slip": pm(m, e, 4), "below 1.37 by": gap,
                     "in SEs": gap / e if e > 0 else math.nan})
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
        a = np.vstack([np.ones_like(x), -x]).T / e[:, None]
        cov = np.linalg.inv(a.T @ a)
        coef = cov @ (a.T @ (y / e))
        chi2 = float(np.sum(((y - coef[0] + coef[1] * x) / e) ** 2))
        dof = g.height - 2
        se = math.sqrt(cov[0, 0] * (max(1.0, chi2 / dof) if dof > 0 else 1.0))
        gap = max(RATIO_PAPER[0] - coef[0], coef[0] - RATIO_PAPER[1], 0.0)
        rows.append({"φ̄": phi, "widths": ", ".join(f"{w:g}" for w in g["W"]),
                     "r_inf (W → ∞)": pm(float(coef[0]), se, 3),
                     "c": float(coef[1]),
                     "reaches 1.37-1.40": "yes" if gap <= 2 * se else "no"})
    return pl.DataFrame(rows)


def collapse(steady: pl.DataFrame) -> pl.DataFrame:
    """Per phi_bar: u_slip/sqrt(W), u_max/sqrt(W) and delta_095/W at the two widest W with a
    steady flow, their relative change and its distance from zero in SEs; and the exponent n
    of u ~ W^n (delta ~ W^n) between them, with its SE (000: u ~ W^1/2 and delta ~ W for
    W >= 100; a local mu(I) law, Cawthorn 2011 quoted in 000 §3.1: u ~ W^3/2)."""
    d = _with_scaled(steady)
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
                         "exponent n (∝ W^n)": pm(n, n_se, 2)})
    return pl.DataFrame(rows)


def zone_table(steady: pl.DataFrame) -> pl.DataFrame:
    """Zones (§3.2), plug phi, conduction length and Omega_z/omega_z per steady point."""
    rows = []
    for r in steady.iter_rows(named=True):
        rows.append({"W": r["W"], "φ̄": r["phi_bar"], "xi_plug": r["xi_plug"],
                     "xi_ad": pm(r["xi_ad"], r["xi_ad_se"], 1),
                     "φ plug": pm(r["phi_plug"], r["phi_plug_se"], 4),
                     "l_c": ("at bound" if r["l_c_at_bound"] else pm(r["l_c"], r["l_c_se"], 1)),
                     "Ω/ω (shearing)": pm(r["omega_ratio_shearing"],
                                          r["omega_ratio_shearing_se"], 3),
                     "σxx/W": pm(r["sigma_xx_mean"] / r["W"], r["sigma_xx_mean_se"] / r["W"],
                                 3)})
    return pl.DataFrame(rows)


#: the kinetic coefficients of fig. 13 (B8-B10), column and label
KINETIC = (("p_phi", "p_φ = σxx/T (B8)"), ("mu_phi", "μ_φ = σxy/(|du/dx| T^1/2) (B9)"),
           ("D_phi", "D_φ = Γ/T^3/2 (B10)"))
#: 000 §3.3: the fig. 13 divergence fits give phi_ad = 0.59 +- 0.002
PHI_AD_PAPER = (0.59, 0.002)


def phi_ad_fits(profiles: pl.DataFrame) -> pl.DataFrame:
    """Fit A/(phi_ad - phi) (granflow.analysis.channel.fit_phi_ad) to each kinetic coefficient
    over the loose-zone bins of every steady k_n = 1e5 point, pooled (fig. 13)."""
    loose = profiles.filter(pl.col("zone") == "loose", pl.col("parent") == "")
    rows = []
    for col, name in KINETIC:
        f = fit_phi_ad(loose["phi"].to_numpy(), loose[col].to_numpy(),
                       loose[f"{col}_se"].to_numpy())
        rows.append({"coefficient": name, "bins": f["n"], "φ_ad": pm(f["phi_ad"],
                     f["phi_ad_se"], 4), "χ²/dof": f["chi2_per_dof"],
                     "from 0.59 (SEs)": (f["phi_ad"] - PHI_AD_PAPER[0])
                     / math.hypot(f["phi_ad_se"], PHI_AD_PAPER[1])})
    return pl.DataFrame(rows)


def plot_fig13(profiles: pl.DataFrame, path: Path) -> Path:
    """The kinetic coefficients against 0.64 - phi, by zone, all steady k_n = 1e5 points."""
    from matplotlib.figure import Figure

    d = profiles.filter(pl.col("parent") == "")
    fig = Figure(figsize=(12, 3.8))
    colours = {"dense": "k", "loose": "tab:brown", "wall": "r", "plug": "0.6"}
    for k, (col, name) in enumerate(KINETIC):
        ax = fig.add_subplot(1, 3, k + 1)
        for zone, c in colours.items():
            z = d.filter(pl.col("zone") == zone, pl.col(col) > 0)
            ax.plot(PHI_RCP - z["phi"], z[col], "o", ms=3, color=c, label=f"{zone} zone")
        ax.axvline(PHI_RCP - PHI_AD, color="b", ls=":", lw=0.8, label=f"φ = φ_ad = {PHI_AD}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("0.64 - φ")
        ax.set_ylabel(name)
        ax.set_title(f"fig. 13: {col}")
        ax.legend(fontsize=6)
    return save_figure(fig, path, dpi=100)


# --------------------------------------------------------------------------------------------
# stiffness (fig. 10)
# --------------------------------------------------------------------------------------------
STIFF_QUANTITIES = (("phi", "φ"), ("u", "u"), ("gamma_dot", "du/dx"), ("T", "T"))


def stiffness_table(profiles: pl.DataFrame, points: pl.DataFrame) -> pl.DataFrame:
    """For each branch against its k_n = 1e5 parent, per zone of the parent and quantity: the
    mean relative difference over the zone's bins, the median and largest |z| (difference /
    combined SE per bin) and the fraction of bins with |z| > SIGNIFICANT."""
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
                rows.append({"k_n": f"{b['kn']:.0e} vs 1e+05", "zone": zone, "bins": int(m.sum()),
                             "quantity": name,
                             "mean rel. diff.": float(np.mean((c - a) / np.abs(a))),
                             "median |z|": float(np.median(z)), "max |z|": float(np.max(z)),
                             f"bins |z|>{SIGNIFICANT:g}": float(np.mean(z > SIGNIFICANT))})
    return pl.DataFrame(rows)


def stiffness_zone_means(zones: pl.DataFrame, W: float, phi_bar: float) -> pl.DataFrame:
    """Zone means (each run's own zones; granflow.analysis.channel.zone_means) of phi, u,
    |du/dx| and T at every k_n of (W, phi_bar), ``value ± SE``, a row per zone and quantity."""
    fam = zones.filter(pl.col("W") == W, pl.col("phi_bar") == phi_bar).sort("kn")
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
                row[f"k_n = {r['kn']:.0e} (bins)"] = f"{pm(r[q], r[f'{q}_se'], digits)} " \
                    f"({r['n_bins']})"
            rows.append(row)
    return pl.DataFrame(rows)


def stiffness_verdict(tab: pl.DataFrame) -> list[str]:
    """000 §3.3 in numbers: per k_n and quantity, the bin-weighted mean relative change in the
    dense shearing and plug zones against that in the loose and wall zones. The paper's
    statement holds where du/dx and T change more in the first than in the second and phi
    and u change little in both."""
    if tab.height == 0:
        return ["No stiffness branches in this dataset."]
    out = []
    for (kn,), g in tab.group_by(["k_n"], maintain_order=True):
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


# --------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------
def _lbl(r: dict[str, Any]) -> str:
    return f"W = {r['W']:g}, φ̄ = {r['phi_bar']:g}"


def plot_fig4(steady: pl.DataFrame, profiles: pl.DataFrame, path: Path) -> Path:
    """(a) u against the distance from the wall; (b) the scaled profile against
    x/delta_0.95 with (3.1)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4))
    a, b = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for r in steady.iter_rows(named=True):
        p = profiles.filter(*(pl.col(k) == r[k] for k in ("W", "phi_bar", "kn", "seed")))
        if p.height == 0:
            continue
        mk = MARKERS.get(round(r["phi_bar"], 2), "o")
        a.errorbar(p["xi"], p["u"], yerr=p["u_se"], fmt=mk + "-", ms=3, lw=0.8, label=_lbl(r))
        s = (p["u"] - r["u_slip"]) / (r["u_max"] - r["u_slip"])
        b.plot(p["xi"] / r["delta_095"], s, mk, ms=3, label=_lbl(r))
    x = np.linspace(0, 3, 200)
    b.plot(x, scaled_profile_31(x, 1.0), "r--", label="000 (3.1): 1 - exp(-3x/δ0.95)")
    a.set_xlabel("distance from the wall x/d")
    a.set_ylabel("u (√(gd))")
    a.set_title("fig. 4(a): velocity")
    b.set_xlabel("x/δ0.95")
    b.set_ylabel("(u - u_slip)/(u_max - u_slip)")
    b.set_xlim(0, 3)
    b.set_title("fig. 4(b): scaled velocity")
    a.legend(fontsize=6)
    b.legend(fontsize=6)
    return save_figure(fig, path, dpi=100)


def plot_fig5(steady: pl.DataFrame, path: Path) -> Path:
    """u_slip/sqrt(W), u_max/sqrt(W), u_max/u_slip (with 000's 1.37-1.40) and delta_095/W
    against phi_bar, a line per W."""
    from matplotlib.figure import Figure

    d = _with_scaled(steady)
    fig = Figure(figsize=(12, 3.6))
    panels = (("u_slip_scaled", "u_slip/√W"), ("u_max_scaled", "u_max/√W"),
              ("u_max_over_u_slip", "u_max/u_slip"), ("delta_095_scaled", "δ0.95/W"))
    for k, (col, name) in enumerate(panels):
        ax = fig.add_subplot(1, 4, k + 1)
        for (w,), g in d.group_by(["W"], maintain_order=True):
            ax.errorbar(g["phi_bar"], g[col], yerr=g[f"{col}_se"], fmt="o-", ms=4,
                        capsize=2, label=f"W = {w:g} (granflow, B = {g['B'][0]:g})")
        if col == "u_max_over_u_slip":
            ax.axhspan(*RATIO_PAPER, color="r", alpha=0.2, label="000: 1.37-1.40 (W = 60-150)")
        ax.set_xlabel("φ̄")
        ax.set_ylabel(name)
        ax.set_title(f"fig. 5: {name}")
        ax.legend(fontsize=6)
    return save_figure(fig, path, dpi=100)


def plot_fig7(steady: pl.DataFrame, path: Path) -> Path:
    """sigma_xx/W and the wall friction coefficient against phi_bar, a line per W."""
    from matplotlib.figure import Figure

    d = _with_scaled(steady)
    fig = Figure(figsize=(9, 3.6))
    for k, (col, name) in enumerate((("sigma_xx_mean_scaled", "σxx/W (ρ g)"),
                                     ("wall_friction", "μ_wall"))):
        ax = fig.add_subplot(1, 2, k + 1)
        for (w,), g in d.group_by(["W"], maintain_order=True):
            ax.errorbar(g["phi_bar"], g[col], yerr=g[f"{col}_se"], fmt="o-", ms=4, capsize=2,
                        label=f"W = {w:g}")
        ax.set_xlabel("φ̄")
        ax.set_ylabel(name)
        ax.set_title(f"fig. 7: {name}")
        ax.legend(fontsize=7)
    return save_figure(fig, path, dpi=100)


def plot_profiles(rows: pl.DataFrame, profiles: pl.DataFrame, path: Path, title: str,
                  panels: Sequence[tuple[str, str, bool]], label: Any = _lbl) -> Path:
    """Half profiles of ``rows`` (one line each, error bars), a panel per (column, axis label,
    log scale); the zone boundaries of each row as dotted lines (plug: black, phi_ad: blue,
    wall: red)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3.4 * len(panels), 3.6))
    axes = [fig.add_subplot(1, len(panels), k + 1) for k in range(len(panels))]
    for r in rows.iter_rows(named=True):
        p = profiles.filter(*(pl.col(k) == r[k] for k in ("W", "phi_bar", "kn", "seed")))
        if p.height == 0:
            continue
        for ax, (col, name, log) in zip(axes, panels, strict=True):
            y, e = p[col].to_numpy(), p[f"{col}_se"].to_numpy()
            if col == "gamma_dot":
                y = np.abs(y)
            yerr: Any = e
            if log:  # positive values only; a lower bar reaching zero is cut at y/10
                y = np.where(y > 0, y, np.nan)
                yerr = np.vstack([np.minimum(e, 0.9 * y), e])
            with np.errstate(under="ignore"):
                ax.errorbar(p["xi"], y, yerr=yerr, fmt=".-", ms=3, lw=0.8, label=label(r))
                if log:
                    ax.set_yscale("log")
            ax.set_xlabel("x/d")
            ax.set_ylabel(name)
    for ax in axes:
        lo, hi = ax.get_ylim()
        for r in rows.iter_rows(named=True):
            for x, c in ((r.get("xi_plug"), "k"), (r.get("xi_ad"), "b"), (r.get("xi_wall"), "r")):
                if x is not None and math.isfinite(x):
                    ax.axvline(x, color=c, ls=":", lw=0.6)
        ax.set_ylim(lo, hi)
    axes[0].plot([], [], "k:", label="plug edge")
    axes[0].plot([], [], "b:", label=f"φ = φ_ad = {PHI_AD}")
    axes[0].plot([], [], "r:", label="wall zone")
    axes[0].legend(fontsize=6)
    fig.suptitle(title, fontsize=9)
    return save_figure(fig, path, dpi=100)


# --------------------------------------------------------------------------------------------
# cost
# --------------------------------------------------------------------------------------------
def _particle_steps(plan: Any) -> Callable[[Any], float]:
    """A point of ``plan`` (reproduce_000.paper_plan) to its t_max at its dt: its particle
    count from W H B phi_bar / <pi d^3/6> of 000's mix, times its steps."""
    from granflow.sizes import CHANNEL_MIX

    v = CHANNEL_MIX.mean_volume
    return lambda p: p.W * p.H * p.B * p.phi_bar / v * plan.t_max / p.dt


# --------------------------------------------------------------------------------------------
# the report
# --------------------------------------------------------------------------------------------
def _read(out: Path, stem: str) -> pl.DataFrame:
    f = out / f"{stem}.parquet"
    return pl.read_parquet(f) if f.exists() else pl.DataFrame()


def _run_table(points: pl.DataFrame) -> pl.DataFrame:
    return points.sort(["kn", "W", "phi_bar"]).select(
        "W", "phi_bar", pl.col("kn").map_elements(lambda k: f"{k:.0e}", return_dtype=pl.String),
        "n", "state", "converged", "t_start", "T_avg", "t_run",
        pl.col("prep_seconds").alias("prep (s)"), pl.col("wall_seconds").alias("wall (s)"))


Section = tuple[list[str], list[Path]]


def _runs_section(points: pl.DataFrame, plan: Any) -> list[str]:
    return ["## What was run", "",
            f"{points.height} channel runs (granflow.scenes.channel.Channel: 000's material "
            "and contact law, e_n = 0.82, μ_p = 0.5, k_t = 2/7 k_n, the 0.9/1.0/1.1 mix; "
            "fill and release), at reduced depth and height (B, H below; 000: B = 40, "
            "H = 60 + ΔH) and k_n = 1e5 with dt = 1.2e-4 √(1e6/k_n), ten times fewer steps "
            "than 000's k_n = 1e6 (what that costs in accuracy: the k_n line of the findings "
            "and the stiffness section). Each runs in stints of "
            f"{plan.stint:g} √(d/g) until it is steady (the last half of |v_cm| steady or "
            "fluctuating by granflow.analysis.channel_profiles.flow_state), its steady part "
            f"(MSER start) spans at least {plan.min_average:g} and the jackknife SEs of "
            f"u_slip and u_max are within {plan.se_target:.0%}, or it arrests for two stints, "
            f"or reaches t = {plan.t_max:g}. States: "
            + ", ".join(f"{k} {v}" for k, v in sorted(
                points["state"].value_counts().iter_rows())) + ". `prep (s)` is the wall "
            "time of the fill and release, `wall (s)` all of the point's (both on one core "
            "shared with one other point).", "",
            md_table(_run_table(points), {"t_start": ".0f", "T_avg": ".0f", "t_run": ".0f",
                                          "prep (s)": ".1f", "wall (s)": ".0f"}), ""]


def _fig5_section(steady: pl.DataFrame, profiles: pl.DataFrame, figdir: Path) -> Section:
    figs = [plot_fig4(steady, profiles, figdir / "fig4_velocity.png"),
            plot_fig5(steady, figdir / "fig5_scaling.png"),
            plot_fig7(steady, figdir / "fig7_stress_wall_friction.png")]
    lines = ["## Fig. 5: velocity scaling against W and φ̄", "",
             md_table(fig5_table(steady)), "",
             "u_max/u_slip per width (000: 1.37-1.40 for W = 60-150 and every φ̄):", "",
             md_table(ratio_by_width(steady), {"below 1.37 by": ".3f", "in SEs": ".1f"}), ""]
    trend = ratio_trend(steady)
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
    return lines, figs


def _zones_section(steady: pl.DataFrame, profiles: pl.DataFrame, figdir: Path) -> Section:
    lines = ["## Zones, plug and conduction length (§3.2, figs 8-9, B13)", "",
             f"000: φ in the plug ~{PHI_PLUG_PAPER}, Ω_z/ω_z = 1/2 in the shearing zones, "
             f"l_c ≈ {L_C_PAPER} d, σxx ∝ W (fig. 7a), μ_wall independent of W and "
             "falling with φ̄ (fig. 7b). xi_plug, xi_ad: the plug edge and the "
             "φ = φ_ad crossing (distance from the wall).", "",
             md_table(zone_table(steady)), "",
             "φ_ad from fig. 13 (000: the loose-zone coefficients diverge as "
             "(φ_ad - φ)^-1 with φ_ad = 0.59 ± 0.002): a fit to the loose-zone bins of "
             "every steady point, pooled:", "",
             md_table(phi_ad_fits(profiles), {"χ²/dof": ".2f", "from 0.59 (SEs)": "+.1f"}),
             ""]
    wide = steady.filter(pl.col("W") == steady["W"].max())
    w = f"W = {wide['W'][0]:g}"
    figs = [plot_fig13(profiles, figdir / "fig13_kinetic.png"),
            plot_profiles(wide, profiles, figdir / "fig6_stress.png", f"fig. 6: stresses, {w}",
                          (("sigma_xx", "σxx", False), ("sigma_xy", "σxy", False))),
            plot_profiles(wide, profiles, figdir / "fig8_profiles.png",
                          f"fig. 8: φ, |du/dx|, T, production, dissipation, {w}",
                          (("phi", "φ", False), ("gamma_dot", "|du/dx|", True),
                           ("T", "T", True), ("production", "σxy du/dx", True),
                           ("Gamma", "dissipation Γ", True))),
            plot_profiles(wide, profiles, figdir / "fig9_rotation.png",
                          f"fig. 9: Ω_z/ω_z and (du/dx)/√T, {w}",
                          (("omega_ratio", "Ω_z/ω_z", False),
                           ("gamma_over_sqrtT", "|du/dx| d/√T", False)))]
    return lines, figs


def _stiffness_section(points: pl.DataFrame, profiles: pl.DataFrame, zones: pl.DataFrame,
                       figdir: Path) -> Section:
    branches = points.filter(pl.col("parent").str.len_chars() > 0)
    if not branches.height:
        return [], []
    tab = stiffness_table(profiles, points)
    fam = points.filter(pl.col("W") == branches["W"][0],
                        pl.col("phi_bar") == branches["phi_bar"][0]).sort("kn")
    fig = plot_profiles(fam, profiles, figdir / "fig10_stiffness.png",
                        f"fig. 10: k_n, W = {fam['W'][0]:g}, φ̄ = {fam['phi_bar'][0]:g}",
                        (("phi", "φ", False), ("u", "u", False),
                         ("gamma_dot", "|du/dx|", True), ("T", "T", True)),
                        label=lambda r: f"k_n = {r['kn']:.0e}")
    lines = ["## Stiffness (fig. 10)", "",
             "000 §3.3: φ, u, du/dx and T are independent of k_n in the wall and loose "
             "zones; du/dx, and T more strongly, depend on k_n in the dense shearing and "
             "plug zones (T in the plug falls as k_n grows). Here: the k_n = 1e5 run's "
             "final state run on at each k_n (module docstring), compared bin by bin in "
             "the zones of the k_n = 1e5 run:", "",
             md_table(tab, {"mean rel. diff.": "+.3f", "median |z|": ".1f", "max |z|": ".1f"}),
             "", *stiffness_verdict(tab), "",
             "Zone means with their jackknife SEs (each run's own zones):", "",
             md_table(stiffness_zone_means(zones, fam["W"][0], fam["phi_bar"][0])), ""]
    return lines, [fig]


def _se_section(se: pl.DataFrame, figdir: Path) -> Section:
    if not se.height:
        return [], []
    shrink = se.join(se.filter(pl.col("fraction") == 1.0), on=["W", "phi_bar", "kn", "seed"],
                     suffix="_all").group_by("fraction").agg(
        (pl.col("u_slip_se") / pl.col("u_slip_se_all")).median().alias("SE(u_slip)/SE(all)"),
        (pl.col("u_max_se") / pl.col("u_max_se_all")).median().alias("SE(u_max)/SE(all)"),
    ).sort("fraction").with_columns((1 / pl.col("fraction").sqrt()).alias("expected (T^-1/2)"))
    return (["## Error against run time", "",
             "The jackknife SEs of u_slip and u_max from the first quarter, half and all "
             "of each point's steady part, as a ratio to the SE from all of it (median "
             "over points). A stationary series' SE shrinks as T^-1/2 (last column); where "
             "the ratios fall short of it, or below 1, the shorter stretch's SE is too "
             "small: its few blocks do not see the flow's slow wandering (the channel's "
             "mean velocity drifts by a few % over hundreds of √(d/g), flow_state's "
             "rel_drift), which the whole part's SE contains. The SEs reported above are "
             "the whole part's; a point's first quarter alone would claim a smaller error "
             "than it has.", "", md_table(shrink, {}), ""],
            [plot_campaign_se(se, figdir / "se_vs_time.png", ("u_slip", "u_max"),
                              ("W", "phi_bar", "kn", "seed"),
                              xlabel="steady averaging time T (√(d/g))", relative=True,
                              target=0.01, label=lambda r: f"W = {r['W']:g}, φ̄ = "
                              f"{r['phi_bar']:g}, k_n = {r['kn']:.0e}")])


def _cost_section(points: pl.DataFrame, paper: Any) -> list[str]:
    # (per W: points, particles, preparation and run wall time, core-hours; the throughput
    # of the runs only)
    per, rate = cost(points, ["W", "kn"], "n", "steps",
                     columns=[pl.col("n").max().alias("particles"),
                              pl.col("prep_seconds").max().alias("longest preparation (s)")],
                     sort=["kn", "W"], prep="prep_seconds")
    est = paper_scale_estimate(paper.points, _particle_steps(paper), rate)
    return ["## Cost", "",
            f"Measured throughput {rate:.3g} particle-steps per core-second (one thread "
            "a point, two points at a time on this 2-core machine; preparation not "
            "counted), from each point's wall time: when the machine ran more than the two "
            "points (tests, builds), that overstates its core time, so the core-hours here "
            "and below are upper bounds.", "",
            md_table(per, {"core-hours": ".3f", "longest point (s)": ".0f",
                           "longest preparation (s)": ".1f", "kn": ".0e"}), "",
            f"Total: {points['wall_seconds'].sum() / 3600:.2f} core-hours.", "",
            "## The paper-scale campaign (recipe)", "",
            "000 runs W = 60-150, B = 40, H = 60 + ΔH, φ̄ = 0.59-0.62 at k_n = 1e6 and "
            "averages over t = 2000-2600. `--paper` (reproduce_000.paper_plan) is that "
            f"campaign, W = 60, 80, 100, 125, 150 x four φ̄ x 3 seeds: {est['runs']:.0f} "
            f"runs to t = {paper.t_max:g}, {est['particle-steps']:.3g} particle-steps, "
            f"about {est['core-hours']:,.0f} core-hours at the measured throughput "
            f"({est['core-hours'] / 64:,.0f} hours on 64 cores; fewer where a run "
            "arrests or meets its SE target early).", "",
            *dask_recipe("granflow.studies.reproduce_000", "results/paper_000", "24:00:00")]


def findings(points: pl.DataFrame, steady: pl.DataFrame) -> list[str]:
    """The answers to the paper's claims, in words, from the tables above."""
    out = ["## Findings", ""]
    flow = points.filter(pl.col("parent") == "")
    for (w,), g in flow.sort("phi_bar").group_by(["W"], maintain_order=True):
        states = ", ".join(f"{p:g}: {s}" for p, s in zip(g["phi_bar"], g["state"],
                                                          strict=True))
        out.append(f"- W = {w:g}: {states} (000, W = 60-150: steady for φ̄ = 0.59-0.61, "
                   "fluctuating at 0.62, jammed above).")
    for r in ratio_by_width(steady).iter_rows(named=True):
        out.append(f"- u_max/u_slip at W = {r['W']:g}: {r['u_max/u_slip']} (φ̄ = "
                   f"{r['phi_bar']}), {r['below 1.37 by']:.3f} below 000's 1.37.")
    for r in ratio_trend(steady).iter_rows(named=True):
        out.append(f"- φ̄ = {r['φ̄']:g}: extrapolated to W → ∞ over W = {r['widths']}, "
                   f"u_max/u_slip → {r['r_inf (W → ∞)']}: "
                   + ("within 2 SEs of 000's 1.37-1.40." if r["reaches 1.37-1.40"] == "yes"
                      else "outside 000's 1.37-1.40 by more than 2 SEs."))
    branches = points.filter(pl.col("parent") != "")
    if branches.height:
        b0 = branches.row(0, named=True)
        fam = _steady(points, kn=None).filter(pl.col("W") == b0["W"],
                                              pl.col("phi_bar") == b0["phi_bar"]).sort("kn")
        out.append(f"- k_n at W = {b0['W']:g}, φ̄ = {b0['phi_bar']:g}: u_slip "
                   + ", ".join(f"{pm(r['u_slip'], r['u_slip_se'], 2)} ({r['kn']:.0e})"
                               for r in fam.iter_rows(named=True))
                   + "; u_max/u_slip "
                   + ", ".join(f"{pm(r['u_max_over_u_slip'], r['u_max_over_u_slip_se'], 3)}"
                               for r in fam.iter_rows(named=True))
                   + " (the stiffness section has the zones).")
    for r in collapse(steady).iter_rows(named=True):
        ok = abs(r["in SEs"]) < SIGNIFICANT or abs(r["relative change"]) < 0.02
        out.append(f"- {r['quantity']} at φ̄ = {r['φ̄']:g}, W {r['widths']}: "
                   f"{r['relative change']:+.1%} ({r['in SEs']:+.1f} SEs), the unscaled "
                   f"quantity ∝ W^n with n = {r['exponent n (∝ W^n)']}: "
                   + ("collapses (within 2 % or 3 SEs)." if ok else "does not collapse."))
    widest = float(np.max(steady["W"].to_numpy())) if steady.height else math.nan
    out += ["", "Why the numbers differ from 000's, as far as this campaign can tell:", "",
            f"- Width: 000's ratio and collapse claims are for W = 60-150 (collapse only for "
            f"W >= 100); the widest channel here is W = {widest:g}. The exponent n of u ∝ W^n "
            "falls as W grows (the collapse table), from the local μ(I) value 3/2 toward "
            "000's 1/2, and u_max/u_slip rises toward 1.37-1.40: the trend is the paper's, "
            "the widths are not yet its.",
            "- Stiffness: k_n = 1e5 slows the flow by the fraction in the k_n line above "
            "against k_n = 1e6 and 1e7, which agree with each other; u_max/u_slip moves by "
            "less than 0.005. The campaign's u and u/√W are low by about that fraction, its "
            "ratios are not.",
            "- Depth and height: B = 10 and H = 20 instead of 40 and 60 + ΔH (the cost: "
            "the particle count scales with B H). Not tested here; one W = 60 point at "
            "B = 40 is the next check (the paper-scale recipe below runs B = 40)."]
    return out + [""]


def write_report(out: Path, path: Path, plan: Any, paper: Any) -> Path:
    """Write the markdown report for the dataset in ``out`` (campaign ``plan``) to ``path``
    (figures beside it, in ``<path stem>_figures/``), with the cost of the ``paper`` plan."""
    points = _read(out, "points")
    profiles, se, zones = _read(out, "profiles"), _read(out, "se_vs_time"), _read(out, "zones")
    steady = _steady(points)
    figdir = path.parent / f"{path.stem}_figures"
    lines = [f"# Reproducing 000: the channel across W and φ̄ ({plan.name} campaign)", "",
             "Generated by `python -m granflow.studies.reproduce_000 "
             f"--{plan.name} --out {out} --report {path}`; the datasets read back with "
             f"`pl.read_parquet('{out}/points.parquet')` (one row per run; also "
             "`profiles.parquet`, half profiles with SEs and zone labels, `zones.parquet`, "
             "zone means, and `se_vs_time.parquet`).", "",
             *findings(points, steady), *_runs_section(points, plan)]
    figs: list[Path] = []
    sections = [_stiffness_section(points, profiles, zones, figdir), _se_section(se, figdir)]
    if steady.height:
        sections[:0] = [_fig5_section(steady, profiles, figdir),
                        _zones_section(steady, profiles, figdir)]
    for text, f in sections:
        lines += text
        figs += f
    lines += ["## Figures", ""] + [f"![{p.stem}]({p.relative_to(path.parent)})"
                                   for p in figs] + [""]
    if points.height and points["steps"].sum():
        lines += _cost_section(points, paper)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    return path
