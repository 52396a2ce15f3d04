"""The report of the cross-scene study (:mod:`granflow.studies.cross_scene`): the calibration in
the cell, the local and nonlocal predictions of every steady channel run with their calibration
bands, the misfit per zone, the nonlocal amplitude fitted on one width predicting the others,
the DEM's bins against the cell's law, and the time it took."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
from matplotlib.figure import Figure

from granflow.analysis.coverage import coverage, steady_rows
from granflow.analysis.plots import ZONE_COLOURS, save_figure
from granflow.continuum.calibration import (
    FORM_I_MAX,
    FORMS,
    POINT,
    continuation_check,
    fits_table,
    form_comparison,
    steady_points,
)
from granflow.continuum.channel_model import (
    A_PHI_BAR,
    A_WIDTH,
    I_PLUG,
    ZONES,
    ChannelCase,
    Prediction,
    channel_cases,
    left_out_runs,
    predict,
)
from granflow.continuum.verdict import (
    PHI_TARGET,
    U_TARGET,
    WIDE,
    answer,
    verdict_table,
    zone_errors,
)

from ._campaign import core_seconds, md_table, pm, pm_column, sig_text, span_of
from ._campaign.cell import STUDY, Point, channel_material
from ._campaign.engine import is_current, with_defaults
from .cross_scene_report_bulk import bulk_lines

MODELS = ("local", "nonlocal")
COLOURS = {"local": "tab:blue", "nonlocal": "tab:red"}


def plot_width(pred: Prediction, W: float, phi_bar: float, dem: pl.DataFrame,
               path: Path, seed: int | None = None) -> Path:
    """u - u_slip, |du/dx| (log) and phi across the half channel of one run (``seed`` among
    the replicas of (W, phi_bar)): the DEM with its SE bars, the local and the nonlocal
    prediction with their calibration bands (16-84 %)."""
    run = (pl.col("W") == W) & (pl.col("phi_bar") == phi_bar)
    if seed is not None:
        run = run & (pl.col("seed") == seed)
    fig = Figure(figsize=(15, 4.2))
    axes = fig.subplots(1, 3)
    xi = dem["xi"].to_numpy()
    cols = (("u", "du", "u - u_slip  [sqrt(g d)]"), ("gamma_dot", "dudx", "|du/dx|  [sqrt(g/d)]"),
            ("phi", "phi", "phi"))
    for ax, (dcol, mcol, label) in zip(axes, cols, strict=True):
        y = dem[dcol].to_numpy()
        y = y - y[0] if dcol == "u" else np.abs(y)
        ax.errorbar(xi, y, yerr=2 * dem[f"{dcol}_se"].to_numpy(), fmt="ko", ms=3,
                    capsize=2, label="DEM (2 SE)")
        for model in MODELS:
            m = pred.profiles.filter(run & (pl.col("model") == model)).sort("xi")
            x = m["xi"].to_numpy()
            ax.plot(x, m[mcol].to_numpy(), color=COLOURS[model], label=model)
            ax.fill_between(x, m[f"{mcol}_lo"].to_numpy(), m[f"{mcol}_hi"].to_numpy(),
                            color=COLOURS[model], alpha=0.2, label=f"{model}: calibration band")
        ax.set_xlabel("distance from the wall x  [d]")
        ax.set_ylabel(label)
        if mcol == "dudx":
            ax.set_yscale("log")
            ax.set_ylim(bottom=1e-6)
    row = pred.cases.filter(run).row(0, named=True)
    for key, colour, name in (("dem", "k", "DEM"), ("local", COLOURS["local"], "local"),
                              ("nonlocal", COLOURS["nonlocal"], "nonlocal")):
        for ax in axes:
            if math.isfinite(row[f"{key}_delta_095"]):
                ax.axvline(row[f"{key}_delta_095"], color=colour, ls="--", lw=0.8,
                           label=f"delta_0.95, {name}" if ax is axes[0] else None)
            ax.axvline(W / 2 - row[f"{key}_plug"], color=colour, ls=":", lw=0.8,
                       label=f"plug edge, {name}" if ax is axes[0] else None)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"W = {W:g} d, phi_bar = {phi_bar:g}"
                 + (f", seed {seed}" if seed is not None else "")
                 + ": DEM against the cell-calibrated models "
                 + (f"(A = {pred.A:.3g} fitted on {pred.constants.A_from})"
                    if pred.constants.A_from not in ("", "given") else
                    f"(A = {pred.A:.3g}, given)"))
    return save_figure(fig, path)


def plot_law(pred: Prediction, path: Path) -> Path:
    """The cell's pooled points and fits, mu(I) and phi(I), with the DEM channel's bins
    (every steady run) coloured by zone."""
    fig = Figure(figsize=(12, 4.5))
    axes = fig.subplots(1, 2)
    for z in ZONES:
        r = pred.residuals.filter(pl.col("zone") == z)
        for ax, col in zip(axes, ("mu", "phi"), strict=True):
            ax.plot(r["I"].to_numpy(), r[col].to_numpy(), ".", color=ZONE_COLOURS[z], ms=4,
                    label=f"channel DEM bins: {z}")
    for (p, c), colour in zip(pred.cal.items(), ("tab:blue", "tab:purple", "tab:green"),
                              strict=False):
        d = c.points
        ii = np.logspace(-5, math.log10(c.law.I_max), 200)
        for ax, col, f in ((axes[0], "mu_g", c.law.mu), (axes[1], "phi", c.law.phi)):
            ax.errorbar(d["I_g"].to_numpy(), d[col].to_numpy(), xerr=2 * d["I_g_se"].to_numpy(),
                        yerr=2 * d[f"{col}_se"].to_numpy(), fmt="s", ms=4, capsize=2,
                        color=colour, mfc="none", label=f"cell, p d/kn = {p:g} (2 SE)")
            ax.plot(ii, f(ii), "-", lw=1, color=colour, label=f"fit, p d/kn = {p:g}")
    for ax, lab in zip(axes, ("mu = |sigma_xy|/sigma_xx", "phi"), strict=True):
        ax.set_xscale("log")
        ax.set_xlabel("I = |du/dx| d / sqrt(sigma_xx/rho_p)")
        ax.set_ylabel(lab)
        ax.axvline(min(c.law.I_min for c in pred.cal.values()), color="k", ls=":", lw=0.8)
    axes[0].legend(fontsize=7)
    fig.suptitle("the cell's law (channel variables) and the channel's bins; dotted: the "
                 "lowest steady I the cell reached")
    return save_figure(fig, path)


def _run(df: pl.DataFrame) -> list[str]:
    """The columns that name a channel run in the tables: W, phi_bar, and the seed where
    the dataset has replicas."""
    many = "seed" in df.columns and df["seed"].n_unique() > 1
    return ["W", "phi_bar", *(["seed"] if many else [])]


def _zone_table(z: pl.DataFrame) -> pl.DataFrame:
    wide = z.pivot(on="model", index=[*_run(z), "zone", "n_bins"],
                   values=["u_rel", "log_dudx", "phi"])
    order = {k: i for i, k in enumerate(ZONES)}
    wide = wide.with_columns(pl.col("zone").replace_strict(order).alias("_o")).sort(
        *_run(z), "_o").drop("_o")
    return wide.rename({c: c.replace("_local", " local").replace("_nonlocal", " nonlocal")
                        for c in wide.columns})


def _residual_table(res: pl.DataFrame) -> pl.DataFrame:
    """Per zone: bins, share with I in the calibrated range, mean mu - mu(I) and phi -
    phi(I) (with the SD over bins) for the bins in range."""
    rows = []
    for z in ZONES:
        r = res.filter(pl.col("zone") == z)
        if not r.height:
            continue
        ok = r.filter(pl.col("in_range"))
        row: dict[str, Any] = {"zone": z, "bins": r.height,
                               "in calibrated I range": ok.height}
        for c in ("d_mu", "d_phi"):
            v = ok[c].to_numpy()
            row[f"mean {c}"] = float(np.mean(v)) if v.size else math.nan
            row[f"SD {c}"] = float(np.std(v, ddof=1)) if v.size > 1 else math.nan
        rows.append(row)
    return pl.DataFrame(rows)


def _cases_table(c: pl.DataFrame) -> pl.DataFrame:
    return c.select(
        *_run(c), pl.col("mu_wall").alias("mu wall bin"),
        pl.col("dem_du").alias("u_max-u_slip DEM"), pl.col("local_du").alias("local"),
        pl.col("nonlocal_du").alias("nonlocal"),
        pl.col("dem_plug").alias("plug DEM"), pl.col("local_plug").alias("plug local"),
        pl.col("nonlocal_plug").alias("plug nonlocal"),
        pl.col("dem_delta_095").alias("delta_0.95 DEM"),
        pl.col("local_delta_095").alias("d0.95 local"),
        pl.col("nonlocal_delta_095").alias("d0.95 nonlocal"),
        (pl.col("local_mass") / pl.col("dem_mass")).alias("mass local/DEM"),
        (pl.col("nonlocal_mass") / pl.col("dem_mass")).alias("mass nonlocal/DEM"))


def _misfit_table(c: pl.DataFrame) -> pl.DataFrame:
    return c.select(*_run(c), pl.col("local_u_rel").alias("u misfit local"),
                    pl.col("nonlocal_u_rel").alias("nonlocal, A fitted at W = "
                                                   f"{A_WIDTH:g}"),
                    pl.col("nonlocal_best_u_rel").alias("nonlocal, own best A"),
                    pl.col("A_best").alias("own best A"))


def _boundary_table(b: pl.DataFrame, reference: tuple[float, float, int | None] | None
                    ) -> pl.DataFrame:
    """Per boundary bin: the amplitude fitted on the reference run, the spread of the runs'
    own best amplitudes and the misfits with each and with the reference's held (the other
    runs, the reference's replicas among them)."""
    ref = _is_ref(reference)
    return b.group_by("bin", "x0").agg(
        pl.col("A_ref").first().alias("A (fitted at the reference)"),
        pl.col("A_best").min().alias("own best A: min"),
        pl.col("A_best").max().alias("max"),
        (pl.col("A_best").max() / pl.col("A_best").min()).alias("max/min"),
        pl.col("u_rel_best").max().alias("misfit, own A: worst"),
        pl.col("u_rel_held").filter(~ref).median().alias("misfit, A held: median"),
        pl.col("u_rel_held").filter(~ref).max().alias("worst"),
    ).sort("bin")


def dem_phi_lines(pred: Prediction) -> list[str]:
    """The section on the models with each run's own phi profile (``dem_phi.parquet``): does
    the amplitude transfer once the stress is the DEM's? Empty without that table."""
    d = pred.dem_phi
    if not d.height:
        return []
    bound = pred.boundary.filter(pl.col("bin") == 0)
    spread = {"the model's phi(I)": bound["A_best"], "the DEM's phi": d["A_best"]}
    ref = _is_ref(pred.reference)
    held = {"the model's phi(I)": pred.cases.filter(~ref)["nonlocal_u_rel"],
            "the DEM's phi": d.filter(~ref)["nonlocal_u_rel"]}
    a_ref = float(d["A_ref"][0])
    ratio = {k: float(v.max()) / float(v.min()) for k, v in spread.items()}  # type: ignore[arg-type]
    base = math.log(ratio["the model's phi(I)"])
    narrowing = math.log(ratio["the DEM's phi"]) / base if base > 1e-9 else 1.0
    words = "; ".join(
        f"with {k}: own best A {float(v.min()):.2f}-{float(v.max()):.2f} "  # type: ignore[arg-type]
        f"(x{float(v.max()) / float(v.min()):.2f}), held A's median misfit "  # type: ignore[arg-type]
        f"{float(held[k].median()):.3f}"  # type: ignore[arg-type]
        for k, v in spread.items())
    tab = d.select(*_run(d), pl.col("local_u_rel").alias("u misfit local"),
                   pl.col("nonlocal_u_rel").alias(f"nonlocal, A = {a_ref:.3g} held"),
                   pl.col("nonlocal_best_u_rel").alias("nonlocal, own best A"),
                   pl.col("A_best").alias("own best A"))
    return ["## The models with the DEM's phi", "",
            "Both models with each run's own phi profile in place of the law's phi(I) "
            "(granflow.continuum.given_phi: the stress is the DEM's, only the flow rule is "
            "modelled; boundary data at the wall bin); A fitted so on the reference run "
            f"({a_ref:.3g}) and held, or each run's own:", "",
            md_table(tab), "",
            f"Whole-channel velocity misfits, {words}. If the models' phi ("
            + ", ".join(f"{c.law.phi_0:.3f}" for c in pred.cal.values())
            + " in the plug, where the DEM packs 0.62-0.65) were what made A vary with W and "
            "phi_bar, the DEM's phi would gather the runs' own amplitudes: "
            + ("**it does not** (the spread hardly narrows): the amplitude's trend is the "
               "flow rule's, not the models' packing." if narrowing > GATHERED else
               f"**it narrows their spread** to {narrowing:.2f} of the model's: part of the "
               "amplitude's trend is the models' packing."), ""]


#: the DEM's phi "gathers" the amplitudes where it shrinks log(max A / min A) below this
#: fraction of the model's
GATHERED = 0.75


def _reference(pred: Prediction, cases: list[ChannelCase]) -> ChannelCase | None:
    """The run the amplitude was fitted on (:attr:`Prediction.reference`), where there is
    one."""
    return next((c for c in cases if (c.W, c.phi_bar, c.seed) == pred.reference), None)


def _is_ref(reference: tuple[float, float, int | None] | None) -> pl.Expr:
    """The row of the run the amplitude was fitted on (:attr:`Prediction.reference`; its
    replicas are held runs like any other); none for a given amplitude."""
    if reference is None:
        return pl.lit(False)
    W, phi_bar, seed = reference
    return ((pl.col("W") == W) & (pl.col("phi_bar") == phi_bar)
            & pl.col("seed").eq_missing(pl.lit(seed, dtype=pl.Int64)))


def _per_point(df: pl.DataFrame, col: str, label: str, spec: str,
               by: tuple[str, ...] = ("W", "phi_bar")) -> str:
    """``col`` per point (the columns ``by``) of ``df``'s runs, each as ``label`` filled with
    its value (:func:`span` of its replicas') and where it is ("W = 20, 3 runs" for several
    replicas), in ``df``'s order; "; " between the points where any has replicas."""
    parts, several = [], False
    for key, g in df.group_by(list(by), maintain_order=True):
        where = ", ".join(f"{k} = {x:g}" for k, x in zip(by, key, strict=True))
        several |= g.height > 1
        parts.append(label.format(span_of(g[col], spec),
                                  where + (f", {g.height} runs" if g.height > 1 else "")))
    return ("; " if several else ", ").join(parts)


def findings(pred: Prediction) -> list[str]:
    """Where each model works and where it fails, from the numbers."""
    c = pred.cases
    mu_s = {p: cal.law.mu_s for p, cal in pred.cal.items()}
    ms = min(mu_s.values())
    below = c.filter(pl.col("mu_wall") < ms)
    z = pred.zones
    out = []
    if below.height:
        out.append(
            f"* **The local law cannot make the narrow channels flow.** The stress ratio of the "
            f"wall bin stays below the cell's yield ratio mu_s = {ms:.3f} in "
            + _per_point(below, "mu_wall", "{1} ({0})", ".3f")
            + ": the local model predicts a rigid plug sliding at u_slip (u_max - u_slip = "
            + _per_point(below, "local_du", "{0}", ".3g") + " against the DEM's "
            + _per_point(below, "dem_du", "{0}", ".3g") + ").")
    for model in MODELS:
        zz = z.filter(pl.col("model") == model).group_by("zone").agg(
            pl.col("u_rel").mean(), pl.col("log_dudx").mean(), pl.col("phi").mean())
        d = {r["zone"]: r for r in zz.iter_rows(named=True)}
        out.append(f"* **{model}**, averaged over the runs, per zone: " + "; ".join(
            f"{k}: u {d[k]['u_rel']:.3f}, log10 du/dx {d[k]['log_dudx']:.2f}, phi "
            f"{d[k]['phi']:.3f}" for k in ZONES if k in d) + ".")
    held = c.filter(~_is_ref(pred.reference))
    if held.height:
        a_lo, a_hi = _float(c["A_best"].min()), _float(c["A_best"].max())
        out.append(
            "* **One amplitude, held, predicts the other runs to "
            + span_of(held["nonlocal_u_rel"], ".0%")
            + " of u_max - u_slip** (RMS over the half channel; the local law: "
            + span_of(held["local_u_rel"], ".0%")
            + "): " + _per_point(held, "nonlocal_u_rel", "{} at {}", ".3f")
            + f". But the amplitude does not carry over: each run's own best A lies between "
            f"{a_lo:.2f} and {a_hi:.2f} (against A = {pred.A:.3f} ± {pred.A_se:.3f} from the "
            "calibration's uncertainty), and with it every run is fitted to "
            f"{_float(c['nonlocal_best_u_rel'].max()):.0%} or better. By width, at phi_bar = "
            f"{A_PHI_BAR:g}: " + _per_point(c.filter(pl.col("phi_bar") == A_PHI_BAR),
                                            "A_best", "A = {} ({})", ".2f", ("W",))
            + f"; by phi_bar, at W = {A_WIDTH:g}: "
            + _per_point(c.filter(pl.col("W") == A_WIDTH), "A_best", "A = {} ({})", ".2f",
                         ("phi_bar",))
            + ". Fitted to whole profiles, the cooperativity length the channel needs is "
            "not one material constant with this local law and these boundary data; read "
            "off the bulk alone, the amplitude varies far less (section 'The amplitude "
            "measured in the bulk'): the spread comes from the wall layer.")
    out.append(
        "* **The boundary layer is too wide**: the nonlocal delta_0.95 is "
        + ", ".join(f"{r['nonlocal_delta_095'] - r['dem_delta_095']:+.2f}"
                    for r in c.iter_rows(named=True))
        + " d from the DEM's (same bins, same definition), the plug "
        + ", ".join(f"{r['nonlocal_plug'] - r['dem_plug']:+.1f}" for r in c.iter_rows(named=True))
        + " d (I < " f"{I_PLUG:g}).")
    res = pred.residuals
    loose = res.filter((pl.col("zone") == "loose") & pl.col("in_range"))
    if loose.height:
        out.append(
            f"* **000's loose zone follows the cell's phi(I), not its mu(I).** Its {loose.height} "
            f"bins (all in the calibrated I range) lie {_float(loose['d_phi'].mean()):+.4f} "
            f"(SD {_float(loose['d_phi'].std()):.4f}) from phi(I) but "
            f"{_float(loose['d_mu'].mean()):+.3f} (SD {_float(loose['d_mu'].std()):.3f}) "
            "from mu(I): at the same I the channel shears at a stress ratio ~0.1 lower than "
            "the homogeneous cell, close to or below the cell's yield ratio. The flow there "
            "is fluidised from the wall, as the nonlocal model has it; the packing responds "
            "to the local I alone. Hard-particle local rheology holds for the density, not "
            "for the friction.")
    plug = res.filter(pl.col("zone") == "plug")
    if plug.height:
        out.append(
            "* **Neither model holds the plug's mass**: both take phi(I -> 0) = phi_0 = "
            + ", ".join(f"{cal.law.phi_0:.3f}" for cal in pred.cal.values())
            + " (the cell's critical state at yield) where the DEM's plug bins average "
            f"{_float(plug['phi'].mean()):.3f}; so the models carry "
            + ", ".join(f"{row['nonlocal_mass'] / row['dem_mass']:.3f}"
                        for row in c.iter_rows(named=True))
            + " of the DEM's mass (nonlocal) with the DEM's sigma_xx. A plug compacted above "
            "the critical state (as 000 finds) is outside any phi(I) law.")
    bt = _boundary_table(pred.boundary, pred.reference)
    if bt.height > 1:
        r0, rn = bt.row(0, named=True), bt.row(bt.height - 1, named=True)
        out.append(
            "* **Where the boundary data are taken changes the amplitude and how far it "
            "carries.** A fitted at the reference run is "
            + ", ".join(f"{r['A (fitted at the reference)']:.2f} (x0 = {r['x0']:g} d)"
                        for r in bt.iter_rows(named=True))
            + f"; the runs' own best A spread by a factor {r0['max/min']:.1f} with the wall "
            f"bin's data and {rn['max/min']:.1f} with the data at x0 = {rn['x0']:g} d (table "
            "below). The wall bin is layered (000's wall zone), and its fluidity is not a "
            "continuum boundary condition; past it the amplitude still varies by a factor "
            "~2. (The misfits past bin k leave out the velocity rise before it, so they are "
            "smaller by construction and compare the amplitude's transfer only.)")
    prof = pred.profiles.filter(pl.col("model") == "nonlocal")
    centre = prof.group_by("W", "phi_bar").agg(
        ((pl.col("du_hi") - pl.col("du_lo")).last() / pl.col("du").last()).alias("rel"))
    out.append(
        "* **The calibration is not what limits the prediction**: its band (16-84 % over laws "
        "drawn from the fits' covariance, A held) spans at most "
        f"{_float(centre['rel'].max()):.1%} of the predicted u_max - u_slip, and A refitted "
        f"with drawn laws moves by ± {pred.A_se:.3f}; the misfits above are the models'.")
    if pred.relaxed:
        out.append(f"* {pred.relaxed} of the nonlocal solves (amplitude fits and bands) "
                   "reached a relaxed tolerance of 1e-6 instead of 1e-8 (solve_nonlocal's "
                   "warning): far below the misfits above.")
    return out


def write_report(out: Path, path: Path, plan: Any, channel: str = "docs/data/reproduce_000",
                 n_band: int | None = None, tables: str = "") -> Path:
    """Calibrate from ``out/points.parquet``, predict the runs of ``channel``, write the
    tables (fits, model, cases, compare, model_profiles, residuals, boundary, dem_phi,
    verdict, the amplitude's and the wall layer's) to ``tables`` (default: ``out``, beside the
    points; another directory predicts a second channel dataset from the same calibration
    and leaves ``out`` as it is: the model's amplitude A is fitted on the channel dataset's
    reference run) and the markdown report to ``path`` (figures in
    ``<path stem>_figures/``)."""
    raw = pl.read_parquet(out / "points.parquet")
    cmp_dir = Path(tables) if tables else out
    cmp_dir.mkdir(parents=True, exist_ok=True)
    points = with_defaults(raw, Point)
    rate = points.filter(pl.col("inertial_number") > 0)
    nb = n_band if n_band is not None else (8 if plan.name == "quick" else 24)
    pred = predict(points, channel, n_band=nb)
    fits = fits_table(pred.cal)
    fits.write_parquet(cmp_dir / "fits.parquet")
    pred.constants.save(cmp_dir / "model.parquet")
    pred.cases.write_parquet(cmp_dir / "cases.parquet")
    pred.zones.write_parquet(cmp_dir / "compare.parquet")
    pred.profiles.write_parquet(cmp_dir / "model_profiles.parquet")
    pred.residuals.write_parquet(cmp_dir / "residuals.parquet")
    pred.boundary.write_parquet(cmp_dir / "boundary.parquet")
    pred.dem_phi.write_parquet(cmp_dir / "dem_phi.parquet")
    cases = channel_cases(channel)
    left_out = left_out_runs(channel)  # (named in the report, not only warned)
    verdicts = verdict_table(zone_errors(cases, pred.profiles))
    verdicts.write_parquet(cmp_dir / "verdict.parquet")
    figdir = path.parent / f"{path.stem}_figures"
    rel = path.parent
    figs = [plot_law(pred, figdir / "law.png")]
    phis = sorted(set(pred.cases["phi_bar"].to_list()))
    drawn: set[float] = set()
    for case in cases:
        # one figure per width (its first replica) at the reference phi_bar
        if case.phi_bar == (A_PHI_BAR if A_PHI_BAR in phis else phis[0]) and case.W not in drawn:
            drawn.add(case.W)
            figs.append(plot_width(pred, case.W, case.phi_bar, case.profile,
                                   figdir / f"W{case.W:g}_phi{case.phi_bar:g}.png", case.seed))
    se = (with_defaults(pl.read_parquet(out / "se_vs_time.parquet"), Point)
          if (out / "se_vs_time.parquet").exists() else pl.DataFrame())
    core = float(points.select(core_seconds(points).sum()).item())
    mat = channel_material()
    law = mat.law()
    assert law.kn is not None and law.kt is not None and law.e_n is not None
    mix = dict(zip(mat.sizes.params[0::2], mat.sizes.params[1::2], strict=True))
    dt_frac = mat.dt_rule.value if mat.dt_rule is not None else math.nan
    states = ", ".join(f"{k} {v}" for k, v in sorted(points["state"].value_counts().iter_rows()))
    lo = pred.cal[min(pred.cal)].law
    pooled = pl.concat([c.points for c in pred.cal.values()])
    lines = [
        f"# Predicting the channel from the cell ({plan.name} campaign)", "",
        f"Generated by `python -m granflow.studies.cross_scene --{plan.name} --out {out} "
        f"--report {path} --channel {channel}"
        + (f" --tables {cmp_dir}" if cmp_dir != out else "")
        + "`. The calibration reads back with "
        f"`pl.read_parquet('{out}/points.parquet')` (one row per cell run), the fits with "
        f"`pl.read_parquet('{cmp_dir}/fits.parquet')`, the models' constants (the laws and the "
        "amplitude, to predict any other channel run without refitting) with "
        "`granflow.continuum.constants.ModelConstants.load"
        f"('{cmp_dir}/model.parquet')` and `granflow.continuum.channel_model.predict_channel`; "
        "the comparison is `cases.parquet` (one row "
        "per channel run), `compare.parquet` (misfit per zone), `model_profiles.parquet`, "
        "`residuals.parquet`, `boundary.parquet`, `dem_phi.parquet` and `verdict.parquet` "
        + ("beside them" if cmp_dir == out else f"in `{cmp_dir}`") + ". Channel "
        "data: "
        f"`{channel}/points.parquet` and `profiles.parquet` (the reproduce_000 campaign, kn = "
        "1e5)." + "".join(f" {m}." for m in left_out), "",
        "## Time", "",
        f"* calibration: {points.height} cell runs, {core / 3600:.2f} core-hours in all "
        "(one thread a run; CPU time where recorded, else wall time);",
        f"* fits, continuum solutions, bands and amplitude fits: {pred.seconds:.0f} s.", "",
        "## 1. Calibration in the cell, with the channel's material", "",
        "granflow.scenes.cell.ShearCell (stress-controlled, compacted start)"
        + (f" and, below its arrest, granflow.scenes.RateCell (the rate imposed as I = "
           f"{', '.join(f'{i:g}' for i in sorted(set(rate['inertial_number'].to_list())))}, "
           "sigma_yy held at p_ext, the same compacted start; its stints, floor and budget "
           "are the same strain at every I)" if rate.height else "")
        + " with the channel's "
        f"particles and law, read from the Channel scene's defaults: sizes {mix} "
        f"(number fractions), kt/kn = {law.kt / law.kn:.4f}, e_n = {law.e_n:g}, mu = 0.5, "
        f"tangential damping 1/2 of the normal, dt = {dt_frac:.4f} t_c (the channel's "
        f"dt per contact time), at p d/kn = "
        + ", ".join(f"{p:g}" for p in sorted(pred.cal))
        + " (the channel's sigma_xx d/kn runs from "
        f"{_float(pred.cases['sigma_xx_d_kn'].min()):.2g} to "
        f"{_float(pred.cases['sigma_xx_d_kn'].max()):.2g}; "
        "each channel run takes the calibration nearest its own). Each run goes on until its "
        f"steady part spans a strain of {plan.min_strain:g} and the blocking SEs of mu1, phi "
        f"are within {plan.se_target:.0%} (I: 3x), or arrests, or runs away. States: {states}.",
        "",
        "The cell measures the shear as the channel does (rheology.gradient_frame): mu = "
        "|sigma_xy|/sigma_yy against the normal stress on the shear planes, and I = "
        "|du/dx| d / sqrt(sigma_yy/rho) with the engineering shear rate 2|D| (the cell's own "
        "I and mu1 use |D| and p; sigma_yy/p = "
        f"{_float(pooled['sigma_g_p'].mean()):.3f} here, so the two differ by ~5 % in mu and a "
        "factor ~1.95 in I).", "",
        "The calibration points: per (p_ext, N, tau/p) the mean of its steady replicas "
        "(flowing and converged runs with different seeds; the cell sizes stay apart); its SE "
        "the larger of the within-run SE (the runs' blocking SEs, combined) and the "
        "between-replica SE (their spread over sqrt(replicas), times the Student factor "
        "for few replicas; none for one replica), both shown as (within / between):", "",
        md_table(_points_table(pooled), {"p_ext": ".0e"}), "",
        "Fits, the laws the models use: mu = mu_s + (mu_2 - mu_s)/(1 + I_0/I) + c I (Jop, "
        "Forterre & Pouliquen 2006, with a linear term; row 'mu': c0-c3 = mu_s, mu_2, I_0, "
        "c) and phi = phi_0 - A4 I^a4 - B I^2 (002 (4.7) with a quadratic term; row 'phi': "
        "c0-c3 = phi_0, A4, a4, B); why four constants, below ('Which form fits'). Beside "
        "them for comparison the three-constant forms, Jop's (row 'mu (Jop)'), (4.7) (row "
        "'phi (4.7)') and 002's mu1 = mu1_0 + A1 I^a1 (4.2) (row 'mu (4.2)'), which fits "
        "these points worse and, with a1 < 1, continues to a yield ratio below the ratios at "
        "which the cell arrests. The SE of I is propagated; errors scaled by sqrt(chi2/dof) "
        "where that exceeds 1 (`fits.parquet` keeps the covariance):", "",
        md_table(fits.drop("cov", "equation"), {"p_ext": ".0e"}), "",
        range_sentence(pred.cal) + " " + _near_yield(points, lo), "",
        *continuation_lines(continuation_check(points)),
        *form_lines(form_comparison(points)),
        "## 2. The models (granflow.continuum)", "",
        "Fully developed flow: sigma_xx uniform (the DEM run's mean), d sigma_xy/dx = "
        "-rho_p phi g from the centre (000 B1-B2), phi = phi(I) in both models. Boundary data "
        "from the DEM run at the wall bin's centre: u there (u_slip) and, for the nonlocal "
        "model, the fluidity g = |du/dx|/mu of the wall bin.", "",
        "* local: |sigma_xy| = mu(I) sigma_xx, a plug where mu < mu_s;",
        "* nonlocal (Henann & Kamrin 2013): g = g_loc(mu, sigma_xx) + xi(mu)^2 g'', g_loc = "
        "I_loc(mu) sqrt(sigma_xx/rho_p)/(d mu), xi = A d/sqrt(|mu - mu_s|), g' = 0 at the "
        "centre; one amplitude A, fitted to the velocity profile of the W = "
        f"{A_WIDTH:g}, phi_bar = {A_PHI_BAR:g} run and held for all the others. Its SE is the "
        "spread of A refitted with laws drawn from the calibration's covariance.", "",
        "Bands: the 16-84 % range of each prediction over laws drawn from the fits' "
        f"covariances ({nb} draws per run). Plug: where I < {I_PLUG:g} (DEM and models "
        "alike). Misfits: RMS over the zone's bins of (u - u_DEM)/(u_max - u_slip)_DEM, of "
        "log10 |du/dx| (floored at 1e-6) and of phi; the wall zone leaves out its first bin "
        "(the boundary data).", "",
        "## 3. The channel, predicted", "",
        f"**Nonlocal amplitude: A = {pred.A:.3g} ± {pred.A_se:.2g}** (fitted at W = "
        f"{A_WIDTH:g}, phi_bar = {A_PHI_BAR:g}).", "",
        "Velocity misfit over the whole half channel, the amplitude fitted at one width "
        "against each run's own best amplitude:", "",
        md_table(_misfit_table(pred.cases)), "",
        "Profiles' summary (u in sqrt(g d), widths in d):", "",
        md_table(_cases_table(pred.cases), {"mu wall bin": ".3f"}), "",
        "Misfit per zone (zones as reproduce_000 labels them):", "",
        md_table(_zone_table(pred.zones), {"phi_bar": ".2f"}), "",
        "## What works and what does not", "", *findings(pred), "",
        *verdict_lines(verdicts),
        "## Where the boundary data are taken", "",
        "The nonlocal model with its boundary data (u and the fluidity) from bin k instead of "
        "the wall bin; A refitted on the reference run for each k, the misfits over the bins "
        "past k (so the columns compare the amplitude's transfer, not the models' reach):", "",
        md_table(_boundary_table(pred.boundary, pred.reference), {"x0": ".2f"}), "",
        *dem_phi_lines(pred),
        *bulk_lines(cases, pred.cal, _reference(pred, cases), pred.residuals, cmp_dir,
                    figdir / "bulk_amplitude.png", rel, pred.cases),
        "## 4. The DEM's bins against the cell's law (000's loose-zone claim)", "",
        "Each DEM bin's mu and phi against the cell's law at the bin's own I; in range: the "
        "bins whose I lies in the calibrated range (the others would test an extrapolation):",
        "",
        md_table(_residual_table(pred.residuals)), "",
        "## Figures", "", *[f"![{p.stem}]({p.relative_to(rel)})" for p in figs], ""]
    lines += coverage_lines(raw, out)  # (its command reads the file's own columns)
    if se.height:
        lines += ["## Error against run time (calibration)", "",
                  "Median over the steady calibration runs of the SE over the first quarter "
                  "and half of each run's steady part, relative to the SE over all of it "
                  "(T^-1/2 gives 2 and 1.41):", "",
                  md_table(_se_ratios(se)), ""]
    lines += ["## Not done here", "",
              "* sigma_xx and the slip predicted instead of taken from the DEM (the issue's "
              "stretch): sigma_xx from the mass with a measured plug density, slip from a wall "
              "law measured separately;",
              *(f"* calibration below I = {pred.cal[p].law.I_min:.2g} at p d/kn = {p:g}: the "
                "full plan's rate-controlled points (cross_scene.RATE_I) reach it, not run yet;"
                for p in short_of_channel(pred.cal)),
              *_before_the_rule(raw), ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    return path


def _before_the_rule(raw: pl.DataFrame) -> list[str]:
    """A bullet for the calibration runs written before the present stop rule (those
    :func:`granflow.studies._campaign.engine.is_current` does not count as done)."""
    old = [r for r in raw.iter_rows(named=True) if not is_current(STUDY, r)]
    if not old:
        return []
    return [f"* {len(old)} of the {raw.height} cell runs above predate the stop rule of the "
            "002 campaign (the rules of \"Error bars that hold across replicas\": a "
            "stationarity test, 20 correlation times of the slowest quantity, no SE on fewer "
            "than 10 blocks); their SEs are those of their short runs (the coverage audit "
            "above). `--full` runs them again under the rule, and each new row replaces its "
            "old one;"]


def verdict_lines(table: pl.DataFrame) -> list[str]:
    """The verdict section: per width, model and zone the worst run's
    misfits with their SEs against the targets (granflow.continuum.verdict), and the answer."""
    if not table.height:
        return []
    shown = table.select(
        "W", "model", "zone", "runs",
        pm_column("u_rel", "u_rel_se", "u - u_slip misfit (worst run)", 3), "u",
        pm_column("phi_abs", "phi_abs_se", "phi misfit (worst run)"), "phi")
    return ["## 5. The verdict", "",
            f"The issue's target: one set of constants, fitted once, predicts every wide run "
            f"(W >= {WIDE:g}) within {U_TARGET:.0%} of u_max - u_slip in u - u_slip and "
            f"within {PHI_TARGET:g} in phi outside the plug. Per width, model and zone, the "
            "worst run (largest misfit less 2 SEs): the RMS misfit over the zone's bins with "
            "its SE, propagated from the calibration band (16-84 %, as the SE of the model) "
            "and the DEM bins' SEs (granflow.continuum.verdict); 'within' if misfit + 2 SE "
            "is under the target, 'outside' if misfit - 2 SE is over it, else 'at the "
            "target'. The plug has no phi verdict (the models carry the cell's critical "
            "state there).", "",
            f"**Does a cell calibration predict the channel? {answer(table)}**", "",
            md_table(shown, {"W": "g"}), ""]


def continuation_lines(check: pl.DataFrame) -> list[str]:
    """The rate-controlled points against the stress-controlled law
    (calibration.continuation_check), a table and its verdict in words; none without rate
    points."""
    if check.is_empty():
        return []
    far = check.filter(pl.col("z").abs() > 2.0)
    overlap = check.filter(pl.col("where") == "overlap")
    pooled = ("" if overlap.is_empty() else
              f" In the overlap the two drives agree, |z| <= "
              f"{float(overlap['z'].abs().to_numpy().max()):.1f} over {overlap.height} "
              "comparisons, so their points are pooled into one law; below it the rows test a "
              "stress-only law's extrapolation, which the rate points replace.")
    verdict = ("every one within 2 combined SEs" if far.is_empty() else
               f"{far.height} of {check.height} beyond 2 combined SEs: " + "; ".join(
                   f"{r['quantity']} at I_g = {r['I_g']:.3g}, p d/kn = {r['p_ext']:g} "
                   f"(z {r['z']:+.1f}, {r['where']})" for r in far.iter_rows(named=True)))
    shown = check.select(
        pl.col("p_ext"), pl.col("inertial_number").alias("I (imposed)"), "replicas",
        pl.col("I_g").round_sig_figs(3), "quantity",
        pm_column("measured", "measured_se", "rate-controlled"),
        pm_column("stress_law", "band", "stress-controlled law (band)"),
        pl.col("z").round(2), "where")
    return ["**The rate-controlled points against the stress-controlled law.** Each rate "
            "point's replica mean against the law fitted to the stress-controlled points "
            "alone at its pressure (band: the SD over laws drawn from that fit's "
            "covariance); z over the combined SE. 'overlap': I_g inside the stress points' "
            "range, where the two drives must agree for the points to be pooled into one "
            "law; 'continuation': below it, where the models used the stress law's "
            "continuation before there were rate points "
            f"(`granflow.continuum.calibration.continuation_check`). {verdict}.{pooled}", "",
            md_table(shown, {"p_ext": ".0e", "I (imposed)": ".0e"}), ""]


def form_lines(forms: pl.DataFrame) -> list[str]:
    """Which form fits the calibration over the whole range and over the channel's
    (calibration.form_comparison): a table and its verdict in words."""
    if forms.is_empty():
        return []
    fit = forms.filter(pl.col("red_chi2") <= 2.0)
    models = {q: f[0] for q, f in FORMS.items()}
    three = {q: f[1] for q, f in FORMS.items()}

    def fits(q: str, span: str) -> str:
        ok = fit.filter((pl.col("quantity") == q) & (pl.col("range") == span))
        n_p = forms["p_ext"].n_unique()
        names = [n for n in dict.fromkeys(ok["form"].to_list())
                 if ok.filter(pl.col("form") == n).height == n_p]
        return ", ".join(names) if names else "none of them"

    spans = list(dict.fromkeys(forms["range"].to_list()))
    three_all = forms.filter(pl.col("form").is_in(list(three.values()))
                             & (pl.col("range") == "all"))

    def slowest(q: str) -> float:
        z = three_all.filter(pl.col("quantity") == q)["z_slowest"].abs()
        return float(z.to_numpy().max()) if z.len() else math.nan

    def low(q: str, form: str, span: str) -> str:
        r = forms.filter((pl.col("quantity") == q) & (pl.col("form") == form)
                         & (pl.col("range") == span)).sort("p_ext")
        return ", ".join(pm(v, e, 4) for v, e in zip(r["low_I"], r["low_I_se"], strict=True))

    worst, worst_mu = slowest("phi"), slowest("mu_g")
    words = "; ".join(f"{q} over {s}: {fits(q, s)}" for q in FORMS for s in spans)
    agree = "; ".join(
        f"{name} {low(q, models[q], 'all')} ({models[q]}, all points) against "
        f"{low(q, three[q], spans[-1])} ({three[q]}, {spans[-1]}) and "
        f"{low(q, three[q], 'all')} ({three[q]}, all points)"
        for q, name in (("mu_g", "mu_s"), ("phi", "phi_0")))
    shown = forms.select("p_ext", "quantity", "form", "range", "n", "constants",
                         pl.col("red_chi2").round(2), pl.col("max_abs_z").round(1),
                         pl.col("I_g_slowest").round_sig_figs(2),
                         pl.col("z_slowest").round(1),
                         pm_column("low_I", "low_I_se", "mu_s or phi_0"))
    return ["**Which form fits, and why the models take four constants.** The pooled points "
            f"(both drives) fitted with the models' forms ({models['mu_g']}; "
            f"{models['phi']}) and with the same forms less their fourth constant, over all "
            f"points and over I_g <= {FORM_I_MAX:g} (the channel's dense zone, I_g up to "
            "~0.08, with room); effective variance for the SE of I "
            "(`granflow.continuum.calibration.form_comparison`). Within the SEs (red chi2 "
            f"<= 2 at every pressure): {words}. The three-constant forms over all points "
            f"miss the slowest point by |z| up to {worst:.1f} (phi) and {worst_mu:.1f} "
            "(mu_g): with three constants one curve cannot follow both the low-I dilatancy and "
            "the fast points' curvature (I_g to ~0.8), and the fast points, many and precise, "
            "pull the low-I constants. The fourth constant takes up that curvature, and the "
            "low-I constants then move to those of the three-constant forms fitted over the "
            f"channel's range alone (per pressure, ascending): {agree}. So one mu(I) and one "
            "phi(I) hold over the whole calibrated range with four constants each.", "",
            md_table(shown, {"p_ext": ".0e"}), ""]


#: the slowest and fastest shear in the channel's dense zone (I = 1e-4 to 0.04,
#: docs/cross_scene.md)
CHANNEL_I_MIN, CHANNEL_I_MAX = 1e-4, 0.04


def short_of_channel(cal: Mapping[float, Any]) -> list[float]:
    """The pressures whose calibration stops short of the channel's slowest dense shear
    (its lowest I above 1.5 CHANNEL_I_MIN)."""
    return [p for p, c in sorted(cal.items()) if c.law.I_min > CHANNEL_I_MIN * 1.5]


def range_sentence(cal: Mapping[float, Any]) -> str:
    """The calibrated I range at each pressure against the channel's dense zone, in words."""
    ranges = "; ".join(f"I = {c.law.I_min:.3g} to {c.law.I_max:.3g} at p d/kn = {p:g}"
                       for p, c in sorted(cal.items()))
    short = short_of_channel(cal)
    def below(p: float) -> str:
        frac = math.log(cal[p].law.I_min / CHANNEL_I_MIN) / math.log(CHANNEL_I_MAX
                                                                    / CHANNEL_I_MIN)
        return f"{min(frac, 1.0):.0%} of its decades at p d/kn = {p:g}"

    tail = (" The channel's dense zone shears at I = 1e-4 to 0.04; below the calibrated "
            "range lie " + ", ".join(below(p) for p in short) + ": there both models use "
            "the fitted law's continuation to its yield ratio mu_s, a fit parameter, not a "
            "measurement." if short else
            " That covers the channel's dense zone, I = 1e-4 to 0.04: the models' mu(I) "
            "there is measured, not a continuation.")
    return f"**The calibrated range is {ranges}.**" + tail


def _points_table(pooled: pl.DataFrame) -> pl.DataFrame:
    """The calibration points (calibration.pooled_points): each quantity's mean and its SE
    with the within-run and between-replica SEs beside it; ``drive``: the imposed tau/p or
    (rate-controlled) I."""
    drive = (pl.when(pl.col("inertial_number") > 0)
             .then(pl.format("I = {}", pl.col("inertial_number").round_sig_figs(3)))
             .otherwise(pl.format("tau/p = {}", pl.col("tau_ratio").round(3))))
    cols: list[pl.Expr] = [pl.col("p_ext"), pl.col("N"), drive.alias("drive"),
                           pl.col("replicas")]
    for x in ("I_g", "mu_g", "phi"):  # (one replica has no between SE: '-')
        cols += [pl.col(x).round_sig_figs(4),
                 pl.format("{} ({} / {})", *(sig_text(f"{x}_se{t}")
                                              for t in ("", "_within", "_between")))
                 .alias(f"{x} SE (within / between)")]
    return pooled.sort("p_ext", "N", "I_g").select(*cols, pl.col("sigma_g_p").round_sig_figs(4))


#: the quantities of the calibration's coverage audit (those the fits use)
AUDITED = ("I_g", "mu_g", "phi")


def coverage_lines(points: pl.DataFrame, out: Path) -> list[str]:
    """The coverage audit of the calibration points' replicas (analysis.coverage, over the
    runs that count, calibration.steady_points), in words computed from the data, with the
    command that reads the dataset."""
    steady = steady_points(points)
    by = [c for c in POINT if c in points.columns]  # (a dataset from before rate points)
    reps = steady.group_by(by).len()
    counts = ", ".join(f"{v} with {k} replica{'s' if k > 1 else ''}" for k, v in sorted(
        reps.group_by("len").agg(pl.len().alias("n")).select("len", "n").iter_rows()))
    tab = coverage(steady, by, AUDITED)
    cmd = (f"`python -m granflow.analysis.coverage {out} --by {','.join(by)} "
           f"--observables {','.join(AUDITED)}`")
    extra = steady_rows(points).height - steady.height
    lines = ["## Coverage audit (calibration)", "",
             f"Do the points' SEs hold across seeds? {reps.height} calibration points with "
             f"steady runs: {counts or 'none'}. "]
    if not int(tab["pairs"].max() or 0):  # type: ignore[arg-type]
        lines[-1] += ("No point has two steady replicas, so there is no pair to audit: the "
                      "points' SEs are their runs' own blocking SEs, untested across seeds.")
        return lines + [""]
    inside = [r["observable"] for r in tab.iter_rows(named=True)
              if r["rms_z_lo"] <= 1.0 <= r["rms_z_hi"]]
    above = [r["observable"] for r in tab.iter_rows(named=True) if r["rms_z_lo"] > 1.0]
    below = [r["observable"] for r in tab.iter_rows(named=True) if r["rms_z_hi"] < 1.0]
    lines[-1] += (
        "For every pair of replicas of a point, z = (x_a - x_b)/sqrt(se_a^2 + se_b^2) with the "
        "runs' own SEs; its rms over the pairs is 1 for honest SEs, with the 95 % interval "
        "of the chi-squared distribution on dof = sum over points of (replicas - 1) "
        "(few pairs: wide):")
    show = tab.select("observable", "points", "pairs", "dof", "rms_z",
                      pl.format("{} - {}", pl.col("rms_z_lo").round(2),
                                pl.col("rms_z_hi").round(2)).alias("95 % interval"),
                      "max_abs_z", pl.col("worst").alias("worst pair"))
    verdict = []
    if inside:
        verdict.append(f"1 lies in the interval for {', '.join(inside)}")
    if above:
        verdict.append(f"the run SEs are too small for {', '.join(above)} (the interval "
                       "lies above 1: the replica spread, which the points' SEs include, "
                       "exceeds them)")
    if below:
        verdict.append(f"the run SEs are larger than the spread for {', '.join(below)}")
    said = "; ".join(verdict)
    lines += ["", md_table(show, {"rms_z": ".2f", "max_abs_z": ".1f"}), "",
              said[:1].upper() + said[1:] + ". The same table: " + cmd
              + (f" (it counts every flowing run, converged or not: {extra} more here)"
                 if extra else "") + ".", ""]
    return lines


def _near_yield(points: pl.DataFrame, law: Any) -> str:
    """What the cell did near yield, per cell size, in words, from the runs."""
    d = points.filter((pl.col("tau_ratio") > 0) & (pl.col("tau_ratio") < 0.42))
    steady = (pl.col("state") == "flowing") & pl.col("converged")
    by = d.group_by("N", "tau_ratio").agg(
        pl.len().alias("runs"), (pl.col("state") == "arrested").sum().alias("arrested"),
        steady.sum().alias("steady")).sort("N", "tau_ratio")
    if not by.height:
        return "No ratio below tau/p = 0.42 was run (this plan does not probe yield)."
    slowest = points.filter(steady).group_by("N").agg(pl.col("I_g").min()).sort("N")
    sizes = []
    for n in sorted(set(by["N"].to_list())):
        parts = [f"{r['tau_ratio']:g}: {r['steady']}/{r['runs']} steady, {r['arrested']} "
                 "arrested" for r in by.filter(pl.col("N") == n).iter_rows(named=True)]
        sizes.append(f"N = {n:,}, tau/p = " + "; ".join(parts))
    gap = float(law.mu(1e-3) - law.mu_s)
    return ("Near yield (both pressures): " + ". ".join(sizes) + ". The slowest steady flow: "
            + ", ".join(f"I = {r['I_g']:.3g} at N = {r['N']:,}"
                        for r in slowest.iter_rows(named=True))
            + f": a larger cell holds a steady flow closer to yield. On the fitted law, I = "
            f"1e-3 needs mu within {gap:.4f} of mu_s, below what a stress-controlled cell of "
            "these sizes holds (it arrests first).")


def _float(v: Any) -> float:
    """A polars scalar (min, max, mean, median) as a float."""
    return float(v) if v is not None else math.nan


def _se_ratios(se: pl.DataFrame) -> pl.DataFrame:
    full = se.filter(pl.col("fraction") == 1.0)
    rows = []
    for f in sorted(set(se["fraction"].to_list())):
        if f == 1.0:
            continue
        part = se.filter(pl.col("fraction") == f).join(
            full, on=["mu_s", "tau_ratio", "inertial_number", "seed", "N", "p_ext"],
            suffix="_all")
        row: dict[str, Any] = {"fraction of the steady part": f, "runs": part.height}
        for c in ("I", "phi", "mu1"):
            row[f"SE({c}) / SE_all"] = _float((part[f"{c}_se"] / part[f"{c}_se_all"]).median())
        rows.append(row)
    return pl.DataFrame(rows)

