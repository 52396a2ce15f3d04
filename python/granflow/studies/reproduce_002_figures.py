"""The figures of the 002 report (:mod:`granflow.studies.reproduce_002_report`): 002's figures
3-8 from the campaign's pooled points, with our fits and the paper's curves.

Every mu_s has a colour, every pressure p_ext a marker; points at a system size other than the
fits' are open symbols. Figures 3-6 have 002's pressure-collapse panel (b): the distance
from the quasi-static value (mu1 - mu1_0, phi_0 - phi) against I on log axes, all pressures, at
the frictions where 002 draws it (mu_s = 0 and 0.3); and its panels (c) and (d): the fitted
quasi-static value and exponent against mu_s, with 002's where it gives them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import polars as pl

from granflow.analysis import rheology as rh

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["COLLAPSE_MU", "FIGURES", "Panel", "plot_figures"]


@dataclass(frozen=True)
class Panel:
    """One panel of ``column``, y-axis ``label``, by ``kind``: "law", the column against
    I**``power`` (log axis); "collapse", 002's panel (b), its distance from our fitted
    quasi-static value against I**power on log axes for the frictions :data:`COLLAPSE_MU`,
    all pressures; "c0" and "exponent", 002's panels (c) and (d), that fitted value and the
    law's exponent against mu_s."""

    column: str
    power: int
    label: str
    kind: str = "law"


#: figures: (file, title, panels)
FIGURES: tuple[tuple[str, str, tuple[Panel, ...]], ...] = (
    ("fig3_mu1.png", "fig. 3: mu1 = tau/p against I, (4.2)",
     (Panel("mu1", 1, "mu1 = tau/p"),
      Panel("mu1", 1, "mu1 - mu1_0 (mu1_0: our fit)", "collapse"),
      Panel("mu1", 1, "mu1_0", "c0"), Panel("mu1", 1, "a1", "exponent"))),
    ("fig4_mu2.png", "fig. 4: mu2 = -N0/p against I^2, (4.4)",
     (Panel("mu2", 2, "mu2"),
      Panel("mu2", 2, "mu2 - mu2_0 (mu2_0: our fit)", "collapse"),
      Panel("mu2", 2, "mu2_0", "c0"), Panel("mu2", 2, "a2", "exponent"))),
    ("fig5_mu3.png", "fig. 5: mu3 against I^2, (4.6)",
     (Panel("mu3", 2, "mu3"),
      Panel("mu3", 2, "mu3_0 - mu3 (mu3_0: our fit)", "collapse"),
      Panel("mu3", 2, "mu3_0", "c0"), Panel("mu3", 2, "a3", "exponent"))),
    ("fig6_phi.png", "fig. 6: phi against I, (4.7)",
     (Panel("phi", 1, "phi"),
      Panel("phi", 1, "phi_0 - phi (phi_0: our fit)", "collapse"),
      Panel("phi", 1, "phi_0", "c0"), Panel("phi", 1, "a4", "exponent"))),
    ("fig7_normal_stress.png", "fig. 7: normal stress differences",
     (Panel("N0_tau", 1, "N0/tau (5.3)"), Panel("N1_tau", 1, "N1/tau (5.4)"))),
    ("fig8_fabric.png", "fig. 8: fabric and contacts",
     (Panel("A_xy", 1, "fabric A_xy (5.1)"), Panel("Z2", 1, "Z2"),
      Panel("theta_c", 1, "theta_c (degrees)"))),
)
#: the frictions of 002's collapse panels (figs. 3(b)-6(b)); where the data hold neither, the
#: smallest and largest mu_s of the data stand in
COLLAPSE_MU = (0.0, 0.3)
#: one marker per pressure, highest pressure first
MARKERS = ("o", "^", "s", "v", "D", "P", "X")


#: N0/tau and N1/tau from the flow laws: (numerator law, factor), N = factor * law / mu1.
#: With tau = p mu1 (4.1), (4.3) gives sigma : (D^2 - tr(D^2) I / 3) = 2 gdot^2 p mu2 / 3 and
#: (4.5) gives sigma : (DW - WD) = 8 gdot^2 p mu3, and sigma : D = 2 gdot tau; so (5.3) is
#: N0/tau = -mu2/mu1 and (5.4) is N1/tau = 4 mu3/mu1 (as 002 states below each), with mu1 from
#: (4.2), mu2 from (4.4) and mu3 from (4.6). Our N0_tau, N1_tau are time means of the per-sample
#: ratio, so at low I, where tau fluctuates most, they need not equal the ratio of the means.
RATIOS: dict[str, tuple[str, float]] = {"N0_tau": ("mu2", -1.0), "N1_tau": ("mu3", 4.0)}


def _ok(f: rh.FitResult | None) -> bool:
    return f is not None and f.success


def _curves(col: str, grid: np.ndarray, mu: float,
            fit: Mapping[str, rh.FitResult]) -> list[tuple[np.ndarray, str]]:
    """(values at ``grid``, line style) of our fit ("-") and the paper's curve ("--") for
    ``col`` at ``mu``, where they exist. 002 gives no mu3_0 (§4.3 only its sign): its mu3 curve
    (and so its N1/tau) takes our fitted mu3_0, to compare shapes."""
    law, factor = RATIOS.get(col, (col, 1.0))
    if law not in rh.LAWS:
        return []
    f = fit.get(law)
    off = f.params["mu3_0"] if (law == "mu3" and f is not None and _ok(f)) else None
    if law == "mu3" and off is None:
        return []
    out: list[tuple[np.ndarray, str]] = []
    try:
        paper = rh.reference_curve(law, grid, mu, offset=off)
        if col in RATIOS:
            paper = factor * paper / rh.reference_curve("mu1", grid, mu)
    except ValueError:
        paper = None  # the paper gives no complete parameter set at this mu_s
    if col in RATIOS:
        f1 = fit.get("mu1")
        if f is not None and f1 is not None and _ok(f) and _ok(f1):
            out.append((np.asarray(factor * f(grid) / f1(grid)), "-"))
    elif f is not None and _ok(f):
        out.append((np.asarray(f(grid)), "-"))
    if paper is not None:
        out.append((np.asarray(paper), "--"))
    return out


@dataclass(frozen=True)
class _Style:
    """The figures' encoding: a colour per mu_s, a marker per pressure, filled symbols at the
    fits' N (``n``), open ones at any other N."""

    colours: dict[float, str]
    markers: dict[float, str]
    n: int

    def size(self, p: float) -> float:
        """The symbol size of pressure ``p``: 4 at the highest, 1.5 more per lower one."""
        return 4.0 + 1.5 * MARKERS.index(self.markers[p])

    @classmethod
    def of(cls, pool: pl.DataFrame, n: int) -> _Style:
        mus = sorted(set(pool["mu_s"].to_list()))
        ps = sorted(set(pool["p_ext"].to_list()), reverse=True)
        return cls({float(m): f"C{i % 10}" for i, m in enumerate(mus)},
                   {float(p): MARKERS[i % len(MARKERS)] for i, p in enumerate(ps)}, n)


def _errorbars(ax: Axes, g: pl.DataFrame, x: np.ndarray, y: np.ndarray, xerr: np.ndarray,
               yerr: np.ndarray, mu: float, style: _Style) -> tuple[set[float], set[int]]:
    """Draw the points of ``g`` (one mu_s; coordinates given), a marker per pressure; the
    pressures and sizes drawn. Lower pressures get larger symbols and are drawn first, so
    that points that collapse onto each other stay visible as nested symbols."""
    ps: set[float] = set()
    ns: set[int] = set()
    for (nn, p), idx in _groups(g):
        if not idx.size:
            continue
        ax.errorbar(x[idx], y[idx], xerr=xerr[idx], yerr=yerr[idx], fmt=style.markers[p],
                    ms=style.size(p), capsize=2, color=style.colours[mu],
                    mfc=None if nn == style.n else "none", ls="none")
        ps.add(p)
        ns.add(nn)
    return ps, ns


def _groups(g: pl.DataFrame) -> list[tuple[tuple[int, float], np.ndarray]]:
    """Row indices of ``g`` per (N, p_ext)."""
    nn = g["N"].to_numpy()
    pp = g["p_ext"].to_numpy()
    keys = sorted({(int(a), float(b)) for a, b in zip(nn, pp, strict=True)})
    return [((a, b), np.flatnonzero((nn == a) & (pp == b))) for a, b in keys]


def _grid(g: pl.DataFrame) -> np.ndarray | None:
    """A log grid of I a little beyond the points of ``g``."""
    ii = g["I"].to_numpy()
    ii = ii[np.isfinite(ii) & (ii > 0)]
    if not ii.size:
        return None
    return np.logspace(np.log10(ii.min()) - 0.15, np.log10(ii.max()) + 0.1, 100)


def _legend(ax: Axes, style: _Style, mus: Sequence[float], ps: set[float], ns: set[int],
            lines: Mapping[str, str]) -> None:
    """A legend of the encoding: colours (mu_s), markers (p_ext), open symbols (N) and the
    line styles drawn (``lines``: style -> label)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    h: list[Any] = [Patch(color=style.colours[m], label=f"mu_s = {m:g}") for m in mus]
    h += [Line2D([], [], color="0.35", marker=style.markers[p], ms=style.size(p), ls="none",
                 label=f"p_ext = {p:.0e}") for p in sorted(ps, reverse=True)]
    if ns - {style.n}:
        h += [Line2D([], [], color="0.35", marker="o", ms=4, ls="none",
                     mfc=None if nn == style.n else "none", label=f"N = {nn}")
              for nn in sorted(ns)]
    h += [Line2D([], [], color="0.35", ls=s, lw=1, label=lab) for s, lab in lines.items()]
    ax.legend(handles=h, fontsize=6, ncol=2 if len(h) > 8 else 1)


def _main_panel(ax: Axes, pool: pl.DataFrame, fits: Mapping[float, Mapping[str, rh.FitResult]],
                panel: Panel, style: _Style) -> None:
    """``panel.column`` against I**power for every mu_s, with our fit and the paper's curve."""
    col, power = panel.column, panel.power
    ps: set[float] = set()
    ns: set[int] = set()
    drawn: set[str] = set()
    mus = sorted(style.colours)
    for mu in mus:
        g = pool.filter(pl.col("mu_s") == mu)
        ii = g["I"].to_numpy()
        a, b = _errorbars(ax, g, ii**power, g[col].to_numpy(),
                          power * ii ** (power - 1) * g["I_se"].to_numpy(),
                          g[f"{col}_se"].to_numpy(), mu, style)
        ps |= a
        ns |= b
        grid = _grid(g.filter(pl.col("N") == style.n))
        if grid is None:
            continue
        for y, ls in _curves(col, grid, mu, fits.get(mu, {})):
            ax.plot(grid**power, y, ls, color=style.colours[mu], lw=1)
            drawn.add(ls)
    ax.set_xscale("log")
    ax.set_xlabel("I" if power == 1 else "I^2")
    ax.set_ylabel(panel.label)
    law, factor = RATIOS.get(col, (col, 1.0))
    if col in RATIOS:
        what = f"{'-' if factor < 0 else f'{factor:g} '}{law}/mu1"
    else:
        what = rh.LAWS[col].equation.split()[0] if col in rh.LAWS else ""
    labels = {"-": f"our fit{'s' if col in RATIOS else ''} {what}",
              "--": f"paper 002 {what}" + (" (mu3_0: our fit)" if law == "mu3" else "")}
    _legend(ax, style, mus, ps, ns, {k: v for k, v in labels.items() if k in drawn})


def _collapse_panel(ax: Axes, pool: pl.DataFrame,
                    fits: Mapping[float, Mapping[str, rh.FitResult]], panel: Panel,
                    style: _Style) -> str:
    """002's panel (b): sign * (column - c0) against I**power on log axes, c0 our fitted
    quasi-static value (mu1_0, phi_0) at each of :data:`COLLAPSE_MU`, every pressure, with the
    power laws of our fit and of the paper. The error bars are the points' SEs (the fitted
    c0's error moves all points of a mu_s together). Returns the panel's title."""
    col, power = panel.column, panel.power
    law = rh.LAWS[col]
    c0n, an, en = law.params
    have = sorted(style.colours)
    mus = [m for m in COLLAPSE_MU if m in style.colours] or sorted({have[0], have[-1]})
    ps: set[float] = set()
    ns: set[int] = set()
    drawn: set[str] = set()
    hidden = 0
    unfitted = []
    for mu in mus:
        f = fits.get(mu, {}).get(col)
        if f is None or not _ok(f):
            unfitted.append(mu)
            continue
        g = pool.filter(pl.col("mu_s") == mu)
        ii = g["I"].to_numpy()
        d = law.sign * (g[col].to_numpy() - f.params[c0n])
        # a point at or below the fitted c0 has no place on a log axis: counted, not drawn
        pos = d > 0
        hidden += int((~pos).sum())
        a, b = _errorbars(ax, g.filter(pl.Series(pos)), ii[pos] ** power, d[pos],
                          (power * ii ** (power - 1) * g["I_se"].to_numpy())[pos],
                          g[f"{col}_se"].to_numpy()[pos], mu, style)
        ps |= a
        ns |= b
        grid = _grid(g)
        if grid is None:
            continue
        x = grid**law.x_power
        ax.plot(grid**power, f.params[an] * x ** f.params[en], "-", color=style.colours[mu],
                lw=1)
        drawn.add("-")
        ref = rh.reference_parameters(mu)
        if np.isfinite(ref[an]) and np.isfinite(ref[en]):
            ax.plot(grid**power, ref[an] * x ** ref[en], "--", color=style.colours[mu], lw=1)
            drawn.add("--")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("I" if power == 1 else "I^2")
    ax.set_ylabel(panel.label)
    notes = []
    if hidden:
        notes.append(f"{hidden} point(s) at or beyond {c0n} not shown (log axis)")
    if unfitted:
        notes.append("no fit of " + col + " at mu_s = " + ", ".join(f"{m:g}" for m in unfitted))
    if notes:
        ax.text(0.02, 0.02, "\n".join(notes), transform=ax.transAxes, fontsize=6, va="bottom")
    lines = {"-": f"our fit: {an} I^{en}" if law.x_power == 1 else f"our fit: {an} (I^2)^{en}",
             "--": "paper 002 (its own " + c0n + ")"}
    _legend(ax, style, [m for m in mus if m not in unfitted], ps, ns,
            {k: v for k, v in lines.items() if k in drawn})
    pressures = ", ".join(f"{p:.0e}" for p in sorted(ps, reverse=True))
    over = (f"p_ext = {pressures}" if len(ps) > 1
            else f"one pressure in the data: p_ext = {pressures}" if ps else "no points")
    return f"pressure collapse, mu_s = {', '.join(f'{m:g}' for m in mus)}\n({over})"


def _constant_panel(ax: Axes, fits: Mapping[float, Mapping[str, rh.FitResult]], panel: Panel,
                    style: _Style) -> str:
    """002's panels (c) and (d): our fitted quasi-static value (``panel.kind`` "c0") or
    exponent ("exponent") of ``panel.column``'s law against mu_s, with its error (scaled by
    sqrt(chi2/dof) where that exceeds 1), and 002's value where it gives one (§4: mu_s = 0
    and 0.3; a3 = 0.5 for all). A value that is not determined (:func:`rh.undetermined`) is
    drawn open, and the axis is scaled to the determined ones. Returns the panel's title."""
    from matplotlib.lines import Line2D

    law = rh.LAWS[panel.column]
    name = law.params[0] if panel.kind == "c0" else law.params[2]
    kept: list[tuple[float, float, float]] = []
    loose: list[tuple[float, float, float]] = []
    paper: list[tuple[float, float]] = []
    for mu in sorted(fits):
        f = fits[mu].get(panel.column)
        if f is not None and _ok(f):
            v, e = f.params[name], f.errors_scaled[name]
            (loose if rh.undetermined(v, e) else kept).append((mu, v, e))
        ref = rh.reference_parameters(mu).get(name, np.nan)
        if np.isfinite(ref):
            paper.append((mu, ref))
    for rows, fill in ((kept, True), (loose, False)):
        for mu, v, e in rows:
            ax.errorbar([mu], [v], yerr=[e], fmt="o", ms=5, capsize=2,
                        color=style.colours.get(mu, "0.3"), mfc=None if fill else "none")
    if paper:
        ax.plot(*zip(*paper, strict=True), "s", ms=8, mfc="none", mec="k", mew=1.2)
    shown = [y for _, v, e in kept for y in (v - e, v + e)] + [v for _, v in paper]
    if shown and loose:
        pad = 0.15 * (max(shown) - min(shown) or abs(max(shown)) or 1.0)
        ax.set_ylim(min(shown) - pad, max(shown) + pad)
        ax.text(0.02, 0.02, "not determined (error > "
                f"{rh.UNDETERMINED:.0%} of the value), open: mu_s = "
                + ", ".join(f"{mu:g}" for mu, _, _ in loose), transform=ax.transAxes,
                fontsize=6, va="bottom")
    ax.set_xlabel("mu_s")
    ax.set_ylabel(panel.label)
    h = [Line2D([], [], color="0.35", marker="o", ls="none", label="our fit, all pressures")]
    if paper:
        h.append(Line2D([], [], color="k", marker="s", mfc="none", ls="none",
                        label="paper 002 (§4)"))
    ax.legend(handles=h, fontsize=6)
    return f"{name} against mu_s"


def plot_figures(pool: pl.DataFrame, fits: Mapping[float, Mapping[str, rh.FitResult]],
                 directory: Path, n: int = 2000) -> list[Path]:
    """Figures 3-8 (:data:`FIGURES`) as PNG files in ``directory``; returns their paths.

    ``pool``: one row per point (mu_s, N, p_ext, tau_ratio) with ``X`` and ``X_se`` per
    observable, every pressure and size to be drawn; ``fits``: ``{mu_s: {law: FitResult}}``,
    the laws fitted at ``N = n`` (whose points are filled symbols; others open). Every mu_s a
    colour, every p_ext a marker; our fit solid, the paper's curve dashed where 002 gives its
    constants (mu_s = 0 and 0.3; N1/tau and mu3 with our fitted mu3_0, which 002 does not
    give)."""
    from matplotlib.figure import Figure

    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    style = _Style.of(pool, n) if pool.height else _Style({}, {}, n)
    for fname, title, panels in FIGURES:
        # four panels as 002's: two rows of two
        rows = 2 if len(panels) == 4 else 1
        cols = len(panels) // rows
        fig = Figure(figsize=(5.6 * cols, 4.8 * rows))
        for k, panel in enumerate(panels):
            ax = fig.add_subplot(rows, cols, k + 1)
            tag = f"({chr(ord('a') + k)}) " if len(panels) > 1 else ""
            if not pool.height or panel.column not in pool.columns:
                ax.set_title(f"{tag}{panel.label}: no data", fontsize=9)
                ax.set_xlabel("I" if panel.power == 1 else "I^2")
                ax.set_ylabel(panel.label)
                continue
            if panel.kind == "collapse":
                sub = _collapse_panel(ax, pool, fits, panel, style)
            elif panel.kind in ("c0", "exponent"):
                sub = _constant_panel(ax, fits, panel, style)
            else:
                _main_panel(ax, pool, fits, panel, style)
                sub = f"{panel.label} against {'I' if panel.power == 1 else 'I^2'}"
            ax.set_title(tag + sub, fontsize=9)
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        p = directory / fname
        fig.savefig(p, dpi=100)
        paths.append(p)
    return paths
