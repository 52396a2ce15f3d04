"""Figures (matplotlib, Agg, PNG).  Every function writes ``path`` and returns it.

Figures are built on :class:`matplotlib.figure.Figure` directly (no pyplot state, no backend
switch), which renders with Agg.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from granflow.states import FlowState

from . import channel as ch
from . import rheology as rh
from ._numerics import quiet
from .estimate import Estimate
from .stats import SEvsTime
from .tables import TableLike, to_polars

PathLike = str | os.PathLike[str]
#: a colour per channel zone (analysis.channel.zones), shared by the reports
ZONE_COLOURS = {"plug": "tab:gray", "dense": "tab:brown", "loose": "black", "wall": "tab:red"}


def save_figure(fig: Figure, path: PathLike, dpi: int = 110) -> Path:
    """Lay out ``fig`` and write it to ``path`` as PNG (its folder made if missing)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    with np.errstate(under="ignore"):  # log axes spanning many decades
        fig.tight_layout()
        fig.savefig(p, dpi=dpi, format="png")
    return p


def _as_runs(
    summaries: Mapping[str, Any] | Sequence[tuple[str, Mapping[str, Any]]],
) -> list[tuple[str, Mapping[str, Any]]]:
    """A single channel summary dict, or a list of (label, summary)."""
    if isinstance(summaries, Mapping):
        return [("", summaries)]
    return list(summaries)


def _val(s: Mapping[str, Any], key: str) -> float:
    v = s.get(key, math.nan)
    return float(v.value) if isinstance(v, Estimate) else float(v)


def _zone_lines(ax: Axes, s: Mapping[str, Any]) -> None:
    z = s.get("zones", {})
    if not z:
        return
    ax.axvline(z.get("xi_plug", math.nan), color="black", lw=0.8, ls=":")
    xa = z.get("xi_ad", math.nan)
    xa = xa.value if isinstance(xa, Estimate) else xa
    if xa is not None and np.isfinite(xa):
        ax.axvline(xa, color="tab:blue", lw=0.8, ls=":")
    ax.axvline(z.get("xi_wall", math.nan), color="tab:red", lw=0.8, ls=":")


# --------------------------------------------------------------------------------------------
# channel
# --------------------------------------------------------------------------------------------
@quiet
def plot_channel_velocity(
    summaries: Mapping[str, Any] | Sequence[tuple[str, Mapping[str, Any]]], path: PathLike
) -> Path:
    """Paper 000 fig. 4: (a) u vs x/d; (b) (u - u_slip)/(u_max - u_slip) vs x/delta_0.95 with
    (3.1).  ``summaries``: a :func:`channel.summary` dict or a list of (label, summary)."""
    fig = Figure(figsize=(10, 4))
    a1, a2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for label, s in _as_runs(summaries):
        p: pl.DataFrame = s["profile"]
        xi, u, use = p["xi"].to_numpy(), p["u"].to_numpy(), p["u_se"].to_numpy()
        a1.errorbar(xi, u, yerr=use, fmt="o-", ms=3, capsize=2, label=label or None)
        us, um, dl = _val(s, "u_slip"), _val(s, "u_max"), _val(s, "delta_095")
        if all(np.isfinite([us, um, dl])) and um != us:
            a2.errorbar(
                xi / dl,
                (u - us) / (um - us),
                yerr=use / abs(um - us),
                fmt="o",
                ms=3,
                capsize=2,
                label=label or None,
            )
    xs = np.linspace(0.0, max(2.5, a2.get_xlim()[1]), 200)
    a2.plot(xs, ch.scaled_profile_31(xs, 1.0), "r--", label="(3.1)")
    a1.set_xlabel("x / d")
    a1.set_ylabel("u (flow direction)")
    a1.set_title("(a) velocity")
    a2.set_xlabel("x / delta_0.95")
    a2.set_ylabel("(u - u_slip) / (u_max - u_slip)")
    a2.set_title("(b) scaled velocity")
    for a in (a1, a2):
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=7)
    return save_figure(fig, path)


@quiet
def plot_channel_fields(
    summaries: Mapping[str, Any] | Sequence[tuple[str, Mapping[str, Any]]], path: PathLike
) -> Path:
    """Paper 000 fig. 8: (a) phi, (b) shear rate du/dx, (c) granular temperature T with the
    (B13) conduction fit in the plug, (d) shear production |sigma_xy du_y/dx| (solid) and
    dissipation Gamma (dashed); zone boundaries as dotted lines (plug: black, phi_ad: blue,
    wall zone: red)."""
    fig = Figure(figsize=(10, 8))
    ax = [fig.add_subplot(2, 2, i + 1) for i in range(4)]
    for label, s in _as_runs(summaries):
        p: pl.DataFrame = s["profile"]
        xi = p["xi"].to_numpy()
        kw: dict[str, Any] = {"fmt": "o-", "ms": 3, "capsize": 2, "label": label or None}
        ax[0].errorbar(xi, p["phi"].to_numpy(), yerr=p["phi_se"].to_numpy(), **kw)
        ax[1].errorbar(
            xi, np.abs(p["gamma_dot"].to_numpy()), yerr=p["gamma_dot_se"].to_numpy(), **kw
        )
        ax[2].errorbar(xi, p["T"].to_numpy(), yerr=p["T_se"].to_numpy(), **kw)
        line = ax[3].errorbar(
            xi, p["production"].to_numpy(), yerr=p["production_se"].to_numpy(), **kw
        )
        ax[3].errorbar(
            xi,
            np.abs(p["Gamma"].to_numpy()),
            yerr=p["Gamma_se"].to_numpy(),
            fmt="s--",
            ms=3,
            capsize=2,
            color=line[0].get_color(),
        )
        cond = s.get("conduction", {})
        lc, tc = _val(cond, "l_c") if cond else math.nan, _val(cond, "T_c") if cond else math.nan
        zn = s.get("zones", {})
        W = s.get("steady", {}).get("W", math.nan)
        if np.isfinite(lc) and np.isfinite(tc) and zn:
            xx = np.linspace(zn["xi_plug"], W / 2, 100)
            ax[2].plot(xx, ch.conduction_profile_B13(W / 2 - xx, tc, lc), "k--", lw=1)
        for a in ax:
            _zone_lines(a, s)
    ax[0].axhline(ch.PHI_AD, color="tab:blue", lw=0.6)
    titles = ["(a) phi", "(b) |du/dx|", "(c) T", "(d) production (-), dissipation (--)"]
    for a, tl in zip(ax, titles, strict=True):
        a.set_xlabel("x / d")
        a.set_title(tl)
    for a in ax[1:]:
        a.set_yscale("log")
    if ax[0].get_legend_handles_labels()[0]:
        ax[0].legend(fontsize=7)
    return save_figure(fig, path)


@quiet
def plot_channel_mu_phi_I(
    summaries: Mapping[str, Any] | Sequence[tuple[str, Mapping[str, Any]]], path: PathLike
) -> Path:
    """Paper 000 fig. 11: (a) mu = |sigma_xy/sigma_xx| vs I (log I) with (B3); (b) 0.64 - phi
    vs I (log-log) with (B4) and a slope-1 guide.  Points coloured by zone (dense: brown,
    loose: black, wall: red; plug bins are omitted since I is zero within error there)."""
    fig = Figure(figsize=(10, 4))
    a1, a2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    imin, imax = math.inf, 0.0
    anchor = (math.nan, math.nan)  # (I, 0.64 - phi) at the largest I, for the slope-1 guide
    for _label, s in _as_runs(summaries):
        r: pl.DataFrame = s["rheology"]
        for zone in ("dense", "loose", "wall"):
            d = r.filter((pl.col("zone") == zone) & (pl.col("I") > 0))
            if d.height == 0:
                continue
            inum = d["I"].to_numpy()
            if float(inum.max()) > imax:
                k = int(np.argmax(inum))
                anchor = (float(inum[k]), float(d["rcp_minus_phi"].to_numpy()[k]))
            imin, imax = min(imin, float(inum.min())), max(imax, float(inum.max()))
            c = ZONE_COLOURS[zone]
            a1.errorbar(
                inum,
                d["mu"].to_numpy(),
                xerr=d["I_se"].to_numpy(),
                yerr=d["mu_se"].to_numpy(),
                fmt="o-",
                ms=3,
                color=c,
                capsize=2,
            )
            a2.errorbar(
                inum,
                d["rcp_minus_phi"].to_numpy(),
                xerr=d["I_se"].to_numpy(),
                yerr=d["phi_se"].to_numpy(),
                fmt="o-",
                ms=3,
                color=c,
                capsize=2,
            )
    if not np.isfinite(imin):
        imin, imax = 1e-5, 1.0
    ii = np.logspace(np.log10(imin) - 0.3, np.log10(imax) + 0.3, 200)
    a1.plot(ii, ch.mu_B3(ii), "b:", label="(B3)")
    a2.plot(ii, ch.PHI_RCP - ch.phi_B4(ii), "b:", label="(B4)")
    if not all(np.isfinite(anchor)) or anchor[1] <= 0:
        anchor = (float(ii[-1]), 0.1)
    a2.plot(ii, anchor[1] * ii / anchor[0], "k:", lw=0.8, label="slope 1")
    a1.set_xscale("log")
    a2.set_xscale("log")
    a2.set_yscale("log")
    a1.set_xlabel("I")
    a1.set_ylabel("mu = |sigma_xy / sigma_xx|")
    a2.set_xlabel("I")
    a2.set_ylabel("0.64 - phi")
    a1.legend(fontsize=7)
    a2.legend(fontsize=7)
    return save_figure(fig, path)


# --------------------------------------------------------------------------------------------
# cell
# --------------------------------------------------------------------------------------------
@quiet
def plot_cell_rheology(
    runs: TableLike,
    path: PathLike,
    *,
    fits: Mapping[str, rh.FitResult] | None = None,
    mu_s: float | None = None,
    group: str | None = None,
) -> Path:
    """Paper 002 figs. 3-7: mu1(I), mu2(I^2), mu3(I^2), phi(I), N0/tau(I), N1/tau(I) with SE
    bars, our fits (solid) and the paper's curves for ``mu_s`` (dashed; mu3 uses the fitted
    mu3_0 since the paper gives none).  ``runs``: :func:`rheology.collect_runs` frame (only
    averaged, flowing rows are drawn); ``group`` optionally colours by a parameter column."""
    d = to_polars(runs)
    if "state" in d.columns:
        d = d.filter(pl.col("state") == FlowState.FLOWING)
    panels = [
        ("mu1", 1, "mu1"),
        ("mu2", 2, "mu2"),
        ("mu3", 2, "mu3"),
        ("phi", 1, "phi"),
        ("N0_tau", 1, "N0 / tau"),
        ("N1_tau", 1, "N1 / tau"),
    ]
    fig = Figure(figsize=(12, 7))
    groups = (
        [(None, d)]
        if group is None or group not in d.columns
        else [(k[0], g) for k, g in d.group_by([group], maintain_order=True)]
    )
    for i, (col, power, lab) in enumerate(panels):
        ax = fig.add_subplot(2, 3, i + 1)
        if col not in d.columns or "I" not in d.columns:
            ax.set_title(f"{lab}: no data")
            continue
        for gk, g in groups:
            inum = g["I"].to_numpy().astype(float)
            ise = g["I_se"].to_numpy().astype(float) if "I_se" in g.columns else None
            x = inum**power
            xe = None if ise is None else power * inum ** (power - 1) * ise
            ye = g[f"{col}_se"].to_numpy().astype(float) if f"{col}_se" in g.columns else None
            ax.errorbar(
                x,
                g[col].to_numpy().astype(float),
                xerr=xe,
                yerr=ye,
                fmt="o",
                ms=3,
                capsize=2,
                label=None if gk is None else f"{group}={gk}",
            )
        if d.height:
            imax = float(np.nanmax(d["I"].to_numpy().astype(float)))
            imin = float(np.nanmin(d["I"].to_numpy().astype(float)))
            ii = np.logspace(np.log10(max(imin, 1e-8)) - 0.2, np.log10(imax) + 0.1, 200)
            if fits is not None and col in fits and fits[col].success:
                ax.plot(ii**power, fits[col](ii), "k-", lw=1, label="fit")
            if mu_s is not None and col in rh.LAWS:
                off = None
                if col == "mu3" and fits is not None and "mu3" in fits:
                    off = fits["mu3"].params["mu3_0"]
                try:
                    ax.plot(
                        ii**power,
                        rh.reference_curve(col, ii, mu_s, offset=off),
                        "r--",
                        lw=1,
                        label=f"paper, mu_s={mu_s:g}",
                    )
                except ValueError:
                    pass
        ax.set_xscale("log")
        ax.set_xlabel("I" if power == 1 else "I^2")
        ax.set_ylabel(lab)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    return save_figure(fig, path)


# --------------------------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------------------------
@quiet
def plot_se_vs_time(
    results: SEvsTime | Mapping[str, SEvsTime],
    path: PathLike,
    *,
    ylabel: str = "standard error",
    target: float | None = None,
) -> Path:
    """SE vs simulated averaging time (log-log) with the fitted ``C / sqrt(T)`` line; open
    symbols mark prefixes whose blocking did not converge.  A top axis shows wall-clock time
    when the wall rate is known (first result); ``target`` draws a dashed horizontal line."""
    res = {"": results} if isinstance(results, SEvsTime) else dict(results)
    fig = Figure(figsize=(6, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    wall = None
    for label, r in res.items():
        tab = r.table
        if tab.height == 0:
            continue
        T, se, err = tab["T"].to_numpy(), tab["se"].to_numpy(), tab["se_err"].to_numpy()
        conv = tab["converged"].to_numpy()
        eb = ax.errorbar(T[conv], se[conv], yerr=err[conv], fmt="o", capsize=2, label=label or None)
        col = eb[0].get_color()
        if (~conv).any():
            ax.errorbar(
                T[~conv], se[~conv], yerr=err[~conv], fmt="o", mfc="none", color=col, capsize=2
            )
        if np.isfinite(r.C):
            tt = np.logspace(np.log10(T.min()), np.log10(T.max()), 50)
            ax.plot(
                tt,
                r.predict_se(tt),
                "-",
                color=col,
                lw=1,
                label=f"{label + ': ' if label else ''}{r.C:.3g}/sqrt(T)",
            )
        if wall is None and r.wall_time_per_unit_t:
            wall = float(r.wall_time_per_unit_t)
    if target is not None and target > 0:
        ax.axhline(target, color="k", ls="--", lw=0.8, label=f"target {target:.3g}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("simulated averaging time T")
    ax.set_ylabel(ylabel)
    if wall:
        w = wall

        def to_wall(t: Any) -> Any:
            return t * w

        def from_wall(s: Any) -> Any:
            return s / w

        sec = ax.secondary_xaxis("top", functions=(to_wall, from_wall))
        sec.xaxis.set_minor_formatter(NullFormatter())  # labelled minor ticks overlap
        sec.set_xlabel("wall-clock time [s]")
    handles = ax.get_legend_handles_labels()[0]
    if handles:
        ax.legend(fontsize=6 if len(handles) > 6 else 7, ncol=2 if len(handles) > 6 else 1)
    return save_figure(fig, path)


@quiet
def plot_work_precision(table: TableLike, path: PathLike) -> Path:
    """Work-precision diagram: deviation vs wall time (log-log), one line per observable,
    points labelled by ``dt_label``.  ``table`` needs columns dt_label, wall_time, observable,
    deviation (any table type accepted by :func:`tables.as_columns`; text columns are read
    through polars)."""
    df = to_polars(table)
    fig = Figure(figsize=(6, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    for (obs,), g in df.group_by(["observable"], maintain_order=True):
        g = g.sort("wall_time")
        w = g["wall_time"].to_numpy().astype(float)
        dev = np.abs(g["deviation"].to_numpy().astype(float))
        ax.plot(w, dev, "o-", label=str(obs))
        for xw, yd, lab in zip(w, dev, g["dt_label"].to_list(), strict=True):
            ax.annotate(str(lab), (xw, yd), textcoords="offset points", xytext=(3, 3), fontsize=6)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("|deviation|")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    return save_figure(fig, path)


def plot_run(directory: PathLike) -> list[Path]:
    """Write the scene's figures for the run in ``directory`` (``granflow plot DIR``) as PNG
    files in DIR/plots; returns the PNG paths."""
    import pyarrow.parquet as pq

    from granflow.errors import GranflowIOError

    d = Path(directory)
    man = d / "manifest.json"
    if not man.exists():
        raise GranflowIOError(f"{d}: no manifest.json (not a granflow run directory)")
    scene = json.loads(man.read_text())["spec"]["scene"]
    out = d / "plots"
    out.mkdir(exist_ok=True)
    paths: list[Path] = []
    series = pq.read_table(d / "series.parquet") if (d / "series.parquet").exists() else None
    if scene == "channel" and (d / "bins.parquet").exists():
        bins = pq.read_table(d / "bins.parquet")
        s = ch.summary(bins, series)
        paths.append(plot_channel_velocity(s, out / "velocity.png"))
        paths.append(plot_channel_fields(s, out / "fields.png"))
        paths.append(plot_channel_mu_phi_I(s, out / "mu_phi_I.png"))
    if series is not None and "t" in series.column_names:
        t = series["t"].to_numpy()
        cols = [c for c in ("vcm_y", "ke_trans", "mu1", "phi", "p") if c in series.column_names]
        if cols:
            fig = Figure(figsize=(6, 2.2 * len(cols)))
            axes = fig.subplots(len(cols), 1, sharex=True, squeeze=False)[:, 0]
            for ax, c in zip(axes, cols, strict=True):
                ax.plot(t, series[c].to_numpy(), lw=0.8)
                ax.set_ylabel(c)
            axes[-1].set_xlabel("t")
            fig.tight_layout()
            p = out / "series.png"
            fig.savefig(p, dpi=120)
            paths.append(p)
    return paths
