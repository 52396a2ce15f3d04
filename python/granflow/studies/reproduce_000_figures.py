"""The 000 campaign's figures (figs 4-10 and 13 of 000), drawn from the report's tables
(:mod:`granflow.studies.reproduce_000_report`): steady points, one row each with the
section 3.1 numbers, and their replica-mean half profiles."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl

from granflow.analysis.channel import PHI_AD, PHI_RCP, scaled_profile_31
from granflow.analysis.plots import save_figure

#: a marker per phi_bar
MARKERS = {0.59: "D", 0.6: "v", 0.61: "^", 0.62: "o"}
#: the kinetic coefficients of fig. 13 (B8-B10), column and label
KINETIC = (("p_phi", "p_φ = σxx/T (B8)"), ("mu_phi", "μ_φ = σxy/(|du/dx| T^1/2) (B9)"),
           ("D_phi", "D_φ = Γ/T^3/2 (B10)"))


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


def label_point(r: dict[str, Any]) -> str:
    """A point's legend label: its W and phi_bar."""
    return f"W = {r['W']:g}, φ̄ = {r['phi_bar']:g}"


def plot_fig4(steady: pl.DataFrame, profiles: pl.DataFrame, by: Sequence[str],
              path: Path) -> Path:
    """(a) u against the distance from the wall; (b) the scaled profile against
    x/delta_0.95 with (3.1); a point's profile is the one whose fields ``by`` are its own."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4))
    a, b = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for r in steady.iter_rows(named=True):
        p = profiles.filter(*(pl.col(k) == r[k] for k in by))
        if p.height == 0:
            continue
        mk = MARKERS.get(round(r["phi_bar"], 2), "o")
        a.errorbar(p["xi"], p["u"], yerr=p["u_se"], fmt=mk + "-", ms=3, lw=0.8,
                   label=label_point(r))
        s = (p["u"] - r["u_slip"]) / (r["u_max"] - r["u_slip"])
        b.plot(p["xi"] / r["delta_095"], s, mk, ms=3, label=label_point(r))
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


def _against_phi_bar(d: pl.DataFrame, path: Path, fig_no: int, width: float,
                     panels: Sequence[tuple[str, str]], label: Any, fontsize: int,
                     bands: Mapping[str, tuple[tuple[float, float], str]] | None = None) -> Path:
    """A panel per (column, axis label): the column with its ``_se`` against phi_bar, a line
    per W (``label(W, rows)``); ``bands`` shades a (range, label) in a column's panel."""
    from matplotlib.figure import Figure

    bands = bands or {}
    fig = Figure(figsize=(width, 3.6))
    for k, (col, name) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1)
        for (w,), g in d.group_by(["W"], maintain_order=True):
            ax.errorbar(g["phi_bar"], g[col], yerr=g[f"{col}_se"], fmt="o-", ms=4, capsize=2,
                        label=label(w, g))
        if col in bands:
            ax.axhspan(*bands[col][0], color="r", alpha=0.2, label=bands[col][1])
        ax.set_xlabel("φ̄")
        ax.set_ylabel(name)
        ax.set_title(f"fig. {fig_no}: {name}")
        ax.legend(fontsize=fontsize)
    return save_figure(fig, path, dpi=100)


def plot_fig5(scaled: pl.DataFrame, path: Path, ratio_band: tuple[float, float]) -> Path:
    """u_slip/sqrt(W), u_max/sqrt(W), u_max/u_slip (with 000's range ``ratio_band``) and
    delta_095/W against phi_bar, a line per W; ``scaled``: the steady points with the report's
    scaled columns (``*_scaled``, ``*_scaled_se``)."""
    return _against_phi_bar(
        scaled, path, 5, 12, (("u_slip_scaled", "u_slip/√W"), ("u_max_scaled", "u_max/√W"),
                              ("u_max_over_u_slip", "u_max/u_slip"),
                              ("delta_095_scaled", "δ0.95/W")),
        lambda w, g: f"W = {w:g} (granflow, B = {g['B'][0]:g})", 6,
        {"u_max_over_u_slip": (ratio_band, f"000: {ratio_band[0]:.2f}-{ratio_band[1]:.2f} "
                                           "(W = 60-150)")})


def plot_fig7(scaled: pl.DataFrame, path: Path) -> Path:
    """sigma_xx/W and the wall friction coefficient against phi_bar, a line per W (``scaled``
    as for :func:`plot_fig5`)."""
    return _against_phi_bar(scaled, path, 7, 9, (("sigma_xx_mean_scaled", "σxx/W (ρ g)"),
                                                 ("wall_friction", "μ_wall")),
                            lambda w, g: f"W = {w:g}", 7)


#: bins whose |du/dx| is below this fraction of the largest set no y-range of the panels named
#: in plot_profiles' ``shear_only`` (there Omega_z/(du/dx) is 0/0: +-8000 in the plug)
SHEAR_RANGE_FRACTION = 0.01


def plot_profiles(rows: pl.DataFrame, profiles: pl.DataFrame, by: Sequence[str], path: Path,
                  title: str, panels: Sequence[tuple[str, str, bool]], label: Any = label_point,
                  shear_only: Sequence[str] = (),
                  refs: Mapping[str, tuple[float, str]] | None = None) -> Path:
    """Half profiles of ``rows`` (one line each, error bars; ``profiles`` as the report's
    ``mean_profiles`` gives them; a row's profile is the one whose fields ``by`` are its own),
    a panel per (column, axis label, log scale); the zone
    boundaries of each row as dotted lines (plug: black, phi_ad: blue, wall: red). The panels
    of ``shear_only`` take their y-range from the sheared bins (|du/dx| at least
    SHEAR_RANGE_FRACTION of its largest); ``refs`` draws a horizontal line (value, label) in
    a column's panel."""
    from matplotlib.figure import Figure

    refs = refs or {}
    yr: dict[str, list[float]] = {c: [] for c in shear_only}

    fig = Figure(figsize=(3.4 * len(panels), 3.6))
    axes = [fig.add_subplot(1, len(panels), k + 1) for k in range(len(panels))]
    for r in rows.iter_rows(named=True):
        p = profiles.filter(*(pl.col(k) == r[k] for k in by))
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
            if col in yr:
                g = np.abs(p["gamma_dot"].to_numpy())
                sheared = g >= SHEAR_RANGE_FRACTION * np.nanmax(g)
                yr[col] += [float(v) for v in y[sheared] if math.isfinite(v)]
            ax.set_xlabel("distance from the wall x/d")
            ax.set_ylabel(name)
    for ax, (col, _, _) in zip(axes, panels, strict=True):
        if yr.get(col):
            vals = yr[col] + ([refs[col][0]] if col in refs else [])
            lo, hi = min(vals), max(vals)
            pad = 0.1 * (hi - lo) if hi > lo else 0.5
            ax.set_ylim(lo - pad, hi + pad)
        if col in refs:
            v, name = refs[col]
            ax.axhline(v, color="g", ls="--", lw=0.8, label=name)
            ax.legend(fontsize=6)
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
