"""The report of the 002 campaign (:mod:`granflow.studies.reproduce_002`): Table 1 rows beside
the paper's, the offsets from 002's laws and what they come from, figures 3-8, the size
effect, the ratios without a steady state, error against run time, wall time per piece and
the paper-scale recipe with its core-hours."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl

from granflow.analysis import rheology as rh
from granflow.analysis.compare import AGREE_SIGMA, agrees, interval_z
from granflow.analysis.coverage import coverage, steady_rows
from granflow.analysis.replicas import DISAGREE_P, replica_mean
from granflow.analysis.stats import weighted_mean

from ._campaign import (
    ERROR_STATES,
    cost,
    dask_recipe,
    keys_done,
    md_table,
    paper_scale_estimate,
    plot_campaign_se,
    pm,
    pm_column,
)
from ._campaign.cell import STUDY, Point
from .reproduce_002_figures import plot_figures
from .reproduce_002_report_offsets import decided_lines

#: the laws' parameters, in the order of the report's table
PARAMS = (("A1", "mu1"), ("A2", "mu2"), ("A3", "mu3"), ("A4", "phi"), ("mu1_0", "mu1"),
          ("a1", "mu1"), ("mu2_0", "mu2"), ("a2", "mu2"), ("mu3_0", "mu3"), ("a3", "mu3"),
          ("phi_0", "phi"), ("a4", "phi"))


def _offset_phrase(off: pl.DataFrame, mu: float, col: str, p: float) -> str:
    """``+0.0221 +- 0.0008 (27 SE)`` for one offset of :func:`offsets`, or "(no data)"."""
    r = off.filter((pl.col("mu_s") == mu) & ((pl.col("p_ext") / p - 1).abs() < 1e-9))
    if not r.height or f"{col} - paper" not in r.columns:
        return "(no data)"
    v, e = float(r[f"{col} - paper"][0]), float(r[f"{col} - paper SE"][0])
    z = abs(v) / e if e > 0 else math.inf
    return f"{v:+.4f} +- {e:.4f} ({'within 2 SE' if agrees(z) else f'{z:.0f} SE'})"


def discussion(off: pl.DataFrame, curves: pl.DataFrame, rows: pl.DataFrame,
               checked: bool = False) -> str:
    """What the comparison shows, every number computed from the dataset: the offsets of
    ``off`` (:func:`offsets`), the curve verdicts of ``curves`` (:func:`curve_comparison`),
    the per-constant verdicts of ``rows`` (:func:`table_rows`); ``checked``: whether the
    LAMMPS and protocol checks (:func:`protocol_checks`) are in the report."""
    lines = ["What the differences are, as measured here:", ""]
    for mu in sorted(set(off["mu_s"].to_list())) if off.height else []:
        ps = sorted(set(off.filter(pl.col("mu_s") == mu)["p_ext"].to_list()), reverse=True)
        for p in ps:
            lines.append(
                f"* mu_s = {mu:g}, p_ext = {p:.0e}: at our own I, mu1 lies "
                f"{_offset_phrase(off, mu, 'mu1', p)} from 002's (4.2), mu2 "
                f"{_offset_phrase(off, mu, 'mu2', p)} from (4.4) and phi "
                f"{_offset_phrase(off, mu, 'phi', p)} from (4.7) (the fitted points, "
                f"I <= {FIT_I_MAX:g}).")
    for mu in sorted(set(off["mu_s"].to_list())) if off.height else []:
        g = off.filter(pl.col("mu_s") == mu).sort("p_ext", descending=True)
        if g.height < 2:
            continue
        v, e = g["mu1 - paper"].to_numpy(), g["mu1 - paper SE"].to_numpy()
        lines.append(
            f"* **Pressure.** At mu_s = {mu:g} the mu1 offset is "
            + ", ".join(f"{a:+.4f} at {q:.0e}" for a, q in zip(v, g["p_ext"], strict=True))
            + f": it moves by at most {np.ptp(v):.4f} (SE {float(np.sqrt(2) * e.max()):.4f}) "
            f"with the pressure, {np.ptp(v) / np.abs(v).mean():.0%} of its size: where the "
            "offset is larger than that, it is not a pressure effect, and fitting over "
            "002's three pressures does not remove it (the pressures' own differences: "
            "'Pressure collapse' above" + ("; whether LAMMPS shifts alike at the same I: "
                                          "'This code, or the protocol?' below)."
                                          if checked else ")."))
    bad = curves.filter(pl.col("verdict") != "agrees") if curves.height else curves
    if curves.height:
        lines.append(
            f"* Of the {curves.height} curves 002 gives in full, {curves.height - bad.height} "
            "agree with ours within the errors over our fitted I range"
            + (": " + ", ".join(f"mu_s = {r['mu_s']:g} {r['law']} differs by up to "
                                f"{r['largest |ours - paper|']:.3f} (at I = {r['at I']:.2g})"
                                for r in bad.iter_rows(named=True)) if bad.height else "")
            + ".")
    phi_rows = rows.filter(pl.col("parameter").is_in(["phi_0", "A4"])
                           & pl.col("verdict").str.starts_with("differs"))
    if phi_rows.height and off.height and "phi - paper" in off.columns:
        lines.append(
            "* Where the phi curve is shifted, its constants phi_0 and A4 take up the shift and "
            f"'differ' one by one ({phi_rows.height} such comparisons in the table): compare "
            "the curves first.")
    lines += [
        "* **Correlated constants.** A three-constant power law over 1-1.5 decades of I leaves "
        "(c0, A, alpha) strongly correlated: a constant that 'differs' alone does not make a "
        "curve differ; the headline comparison above is of the curves, with the fits' "
        "covariance.",
        ("* **This code, the protocol.** LAMMPS on one protocol from the same states, and the "
         "rate-controlled cell against this stress-controlled one at the same I: the section "
         "'This code, or the protocol?' below; the "
         if checked else
         "* **Not compared here.** Whether LAMMPS gives the same offsets on one protocol is "
         "not measured with this dataset (benchmarks/lammps_rate_cell.py); the ")
        + "reading of t_c (collision against printed) moves I by -1.9 % +- 1.6 % and mu1, phi "
        "not at all within their errors at "
        "mu_s = 0.3, tau/p = 0.45, N = 500 (`python benchmarks/tc_reading.py --N 500 --steps "
        "300000 --seeds 1 2 3 4`, docs/cell.md). 002 reports tau/p up to 1.2; from the "
        "compacted start no steady state exists above the runaway ratios listed below, so "
        f"the fits cover I <= {FIT_I_MAX:g} and the paper's constants at high I are not tested."]
    return "\n".join(lines)


#: the comparisons beside a committed dataset (docs/data/<name>), if there: granflow against
#: LAMMPS on the rate-controlled protocol (benchmarks/lammps_rate_cell.py) and the stress- against
#: the rate-controlled cell at matched I (benchmarks/rate_cell.py equivalence)
LAMMPS_TABLE = ("lammps_rate_cell", "table.parquet")
EQUIVALENCE_TABLE = ("rate_cell", "equivalence.parquet")
#: the same comparison at 002's lower pressures, and each code's change from p_ext = 1e-4 to
#: them (``--p-ext P --reference``): whether the campaign's pressure dependence at the same
#: stress ratio is the particles' stiffness (both codes shift) or this code (granflow alone)
LAMMPS_LOW_P = (("lammps_rate_cell_p1e-5", 1e-5), ("lammps_rate_cell_p1e-6", 1e-6))


def _listed(col: pl.Series) -> str:
    """The distinct values of ``col``, space-separated as on a command line."""
    return " ".join(f"{v:g}" for v in sorted(set(col.to_list())))


def _agreement(intro: str, table: pl.DataFrame, shown: pl.DataFrame,
               fmt: Mapping[str, str]) -> list[str]:
    """A comparison's report lines: ``intro``, how many rows of ``table`` agree (within 2
    combined SEs), and ``shown`` as a markdown table."""
    ok = int((table["verdict"] == "agrees").sum())
    return [f"{intro} {ok} of {table.height} within 2 combined SEs:", "",
            md_table(shown, fmt), ""]


def _seeds(table: pl.DataFrame) -> str:
    """The seeds a LAMMPS table was built from, as on the command line (1 to the most
    replicas of a point; a seed a point lacks is skipped there)."""
    most = int(table["replicas_granflow"].max())  # type: ignore[arg-type]
    return " ".join(str(k) for k in range(1, most + 1))


def _lammps_lines(t: pl.DataFrame, where: Path, p_ext: float) -> list[str]:
    """The granflow-against-LAMMPS table at ``p_ext`` (benchmarks/lammps_rate_cell.py's
    table.parquet in ``where``) as report lines."""
    p_arg = "" if p_ext == P_MAIN else f" --p-ext {p_ext:g}"
    return _agreement(
        f"**granflow against LAMMPS at p_ext = {p_ext:.0e}** on one protocol, from the same "
        "states: the rate-controlled cell (granflow.scenes.RateCell, sigma_yy held at p_ext, x "
        "and z fixed; N = 2000) handed at the switch to LAMMPS's `fix deform/pressure` with "
        "`gran/hooke/history` (benchmarks/lammps_rate_cell.py; each I's run length in "
        f"benchmarks/NOTES.md; `python benchmarks/lammps_rate_cell.py{p_arg} --mu "
        f"{_listed(t['mu_s'])} --I {_listed(t['I'])} --seeds {_seeds(t)} --only-table --out "
        f"{where.as_posix()}` rebuilds the table from the committed series); mu = "
        "|sigma_xy|/sigma_yy, N1, N2 over p (LAMMPS's sigma_xx without the kinetic term of "
        "its dilating box sliding past the material, measured in benchmarks/NOTES.md: up to "
        "+0.02 in N1/p at I = 0.15); replica means of the seeds, z = difference over the "
        "combined SE.", t,
        t.select("mu_s", "I", "quantity", pl.col("replicas_granflow").alias("seeds"),
                 pm_column("granflow", "granflow_se", "granflow"),
                 pm_column("lammps", "lammps_se", "LAMMPS"), "z", "verdict"),
        {"mu_s": "g", "I": "g", "z": "+.2f"})


def _shift_lines(shift: pl.DataFrame, where: Path, p_ext: float, reference: Path,
                 seeds: str) -> list[str]:
    """Each code's change from p_ext = 1e-4 to ``p_ext`` at the same I (shift.parquet in
    ``where``) as report lines: the stiffness check of the pressure collapse."""
    real = shift.filter(pl.col("quantity") != "syy_pext")
    both = real.filter((pl.col("z_granflow").abs() > 2) & (pl.col("z_lammps").abs() > 2))
    alike = int((real["codes"] == "shift alike").sum())
    moved = ", ".join(f"{r['quantity']} at mu_s = {r['mu_s']:g}, I = {r['I']:g} "
                      f"({r['shift_granflow']:+.4f} and {r['shift_lammps']:+.4f})"
                      for r in both.iter_rows(named=True)) or "none"
    return [f"**The pressure dependence, in both codes.** Each code's change from p_ext = "
            f"{P_MAIN:.0e} to {p_ext:.0e} at the same imposed I, replica means of each "
            "pressure's seeds, each run from its own compacted state (`python "
            f"benchmarks/lammps_rate_cell.py --p-ext {p_ext:g} --mu {_listed(shift['mu_s'])} "
            f"--I {_listed(shift['I'])} "
            f"--seeds {seeds} --only-table --out {where.as_posix()} --reference "
            f"{reference.as_posix()}`). Moved beyond 2 SEs in both codes (granflow, LAMMPS): "
            f"{moved}. The two codes' shifts agree within 2 combined SEs in {alike} of "
            f"{real.height} (codes z = granflow's shift less LAMMPS's over their combined "
            "SE): a shift both codes make comes from the particles' stiffness p d/kn, not "
            "from this code.", "",
            md_table(real.select(
                "mu_s", "I", "quantity",
                pm_column("shift_granflow", "shift_granflow_se", "granflow shift"),
                pm_column("shift_lammps", "shift_lammps_se", "LAMMPS shift"),
                "codes_z", "codes"), {"mu_s": "g", "I": "g", "codes_z": "+.2f"}), ""]


def _check_paths(out: Path) -> tuple[Path, list[tuple[Path, float]], Path]:
    """Where the checks beside the dataset ``out`` live: LAMMPS_TABLE's file, LAMMPS_LOW_P's
    folders with their pressures, EQUIVALENCE_TABLE's file."""
    return (out.parent.joinpath(*LAMMPS_TABLE),
            [(out.parent / name, p) for name, p in LAMMPS_LOW_P],
            out.parent.joinpath(*EQUIVALENCE_TABLE))


def protocol_checks(out: Path) -> list[str]:
    """The section on whether the offsets are this code's or the protocol's, from the tables
    beside the dataset ``out`` (LAMMPS_TABLE, EQUIVALENCE_TABLE, and LAMMPS_LOW_P's tables and
    shifts where present); empty when neither of the first two is there."""
    lmp, lows, eq = _check_paths(out)
    if not (lmp.exists() or eq.exists()):
        return []
    lines = ["## This code, or the protocol?", ""]
    if lmp.exists():
        lines += _lammps_lines(pl.read_parquet(lmp), lmp.parent, P_MAIN)
    for low, p in lows:
        t = (pl.read_parquet(low / "table.parquet") if (low / "table.parquet").exists()
             else None)
        if t is not None:
            lines += _lammps_lines(t, low, p)
        if (low / "shift.parquet").exists():
            lines += _shift_lines(pl.read_parquet(low / "shift.parquet"), low, p, lmp.parent,
                                  _seeds(t) if t is not None else "1 2 3")
    if eq.exists():
        e = pl.read_parquet(eq)
        lines += _agreement(
            "**Stress against rate control** in granflow: this campaign's points against the "
            "rate-controlled cell with the pressure held, at each point's replica-mean I, the "
            "same seeds, 12,000 t_c each (`python benchmarks/rate_cell.py equivalence`); the SE "
            "of a difference carries the stress point's SE of I through the local slope.", e,
            e.select("mu_s", "tau_ratio", pl.col("I_stress").alias("I"), "quantity",
                     pm_column("stress", "stress_se", "stress-controlled"),
                     pm_column("rate", "rate_se", "rate-controlled"), "z", "verdict"),
            {"mu_s": "g", "tau_ratio": "g", "I": ".3f", "z": "+.2f"})
    where = ("p_ext = 1e-4; the stress/rate check was run there only"
             if any(low.exists() for low, _ in lows)
             else "p_ext = 1e-4; the checks were run there only")
    lines += ["Where both agree, the offsets from 002's laws found above are neither this "
              f"code's nor the protocol's at those points ({where}); what remains is 002's "
              "set-up. How much room the checks' errors leave, offset by offset: 'The offsets, "
              "decided' below.", ""]
    return lines


def check_tables(out: Path) -> tuple[list[pl.DataFrame], pl.DataFrame | None]:
    """The granflow-against-LAMMPS tables at every pressure and the stress/rate equivalence
    table beside the dataset ``out``, those that exist (the data of :func:`protocol_checks`)."""
    lmp, lows, eq = _check_paths(out)
    paths = [lmp] + [low / "table.parquet" for low, _ in lows]
    return ([pl.read_parquet(p) for p in paths if p.exists()],
            pl.read_parquet(eq) if eq.exists() else None)


KEYS = ("mu_s", "N", "p_ext", "tau_ratio")


#: the reported quantities: the coverage audit's, and those whose SEs a point must have
REPORTED = ("I", "phi", "mu1", "mu2")


def pooled(points: pl.DataFrame) -> pl.DataFrame:
    """One row per point: the replica mean of its steady (flowing, stationary) seeds
    (:func:`granflow.analysis.replicas.replica_mean`: ``X``, ``X_se`` the larger of the within
    and between SEs, both kept, and ``replicas``)."""
    flow = steady_rows(points)
    obs = [c for c in flow.columns if f"{c}_se" in flow.columns and c not in KEYS]
    return replica_mean(flow, list(KEYS), obs)


def has_errors(pool: pl.DataFrame) -> pl.Expr:
    """The points whose reported quantities all have an SE (none from too little data)."""
    tests = [pl.col(f"{c}_se").is_finite() for c in REPORTED if f"{c}_se" in pool.columns]
    return pl.all_horizontal(tests) if tests else pl.lit(True)


def agreeing(pool: pl.DataFrame) -> pl.Expr:
    """The points whose replicas agree in every reported quantity (the chi-squared test of
    :func:`granflow.analysis.replicas.replica_mean`; one replica: nothing to test)."""
    tests = [~(pl.col(f"{c}_agree_p") < DISAGREE_P) for c in REPORTED
             if f"{c}_agree_p" in pool.columns]
    return pl.all_horizontal(tests) if tests else pl.lit(True)


def usable(pool: pl.DataFrame) -> pl.Expr:
    """The points that are fitted: :func:`has_errors` and :func:`agreeing`."""
    return has_errors(pool) & agreeing(pool)


#: the campaign's first pressure (the cost of the paper's points is scaled from it where a
#: pressure has no measured points)
P_MAIN = 1e-4


#: the laws are fitted to dense flow: I <= FIT_I_MAX (above, at the edge of runaway dilation,
#: mu1 falls below any power law: mu_s = 0.3, tau/p = 0.65 flows at I = 0.68, phi = 0.38, with
#: mu1 = 0.65 where (4.2) fitted below gives 0.7)
FIT_I_MAX = 0.5


def main_set(pool: pl.DataFrame, n: int) -> pl.DataFrame:
    """The points the laws are fitted to: ``N = n``, every pressure (002 fits each mu_s over
    its three pressures: "all the curves at various pressures collapse onto a master curve",
    §4.1), I <= FIT_I_MAX, every reported quantity with an SE (:func:`usable`)."""
    return pool.filter((pl.col("N") == n) & (pl.col("I") <= FIT_I_MAX) & usable(pool))


def fits_by_mu(pool: pl.DataFrame, n: int = 2000) -> dict[float, dict[str, rh.FitResult]]:
    """The four laws fitted per mu_s at ``N = n`` over every pressure (:func:`main_set`; SEs
    of I propagated)."""
    out = {}
    for (mu,), g in main_set(pool, n).group_by(["mu_s"], maintain_order=True):
        out[float(mu)] = rh.fit_all(g, include_x_errors=True, states=None)
    return dict(sorted(out.items()))


def table_rows(fits: Mapping[float, Mapping[str, rh.FitResult]]) -> pl.DataFrame:
    """One row per (mu_s, parameter): ours with its error (scaled by sqrt(chi2/dof) where that
    exceeds 1), the paper's (Table 1, or §4's text; interpolated between Table 1 rows where
    flagged), the difference in errors and the verdict."""
    rows: list[dict[str, Any]] = []
    for mu, f in fits.items():
        ref = rh.reference_parameters(mu)
        for name, law in PARAMS:
            fr = f.get(law)
            v = fr.params.get(name, math.nan) if fr is not None else math.nan
            e = fr.errors_scaled.get(name, math.nan) if fr is not None else math.nan
            pv = float(ref.get(name, math.nan))
            # (the paper's value is known to half a unit of its last printed digit: the
            # distance is to that interval)
            half = 0.5 * rh.printed_unit(name)
            z = interval_z(v, e, pv - half, pv + half)
            verdict = ("-" if not math.isfinite(z)
                       else "not determined" if rh.undetermined(v, e, pv)
                       else "agrees" if agrees(z) else f"differs ({z:.1f} sigma)")
            rows.append({"mu_s": mu, "parameter": name, "fit": v, "fit_err": e,
                         "red_chi2": fr.red_chi2 if fr is not None else math.nan,
                         "n_points": fr.n if fr is not None else 0,
                         "paper": pv, "paper_unit": 2 * half,
                         "paper_interpolated": bool(ref["interpolated"]),
                         "z": z, "verdict": verdict})
    return pl.DataFrame(rows)


def _verdicts(rows: pl.DataFrame) -> str:
    """One line per parameter family: how many of the mu_s agree, differ, are undetermined."""
    out = []
    for fam, names in (("Table 1's A1-A4", ("A1", "A2", "A3", "A4")),
                       ("the text's mu1_0, a1, mu2_0, a2, a3, phi_0, a4",
                        ("mu1_0", "a1", "mu2_0", "a2", "a3", "phi_0", "a4"))):
        r = rows.filter(pl.col("parameter").is_in(list(names)) & (pl.col("verdict") != "-"))
        v = r["verdict"].to_list()
        agree = sum(x == "agrees" for x in v)
        und = sum(x == "not determined" for x in v)
        out.append(f"* {fam}: {agree} of {len(v)} comparisons agree, {len(v) - agree - und} "
                   f"differ, {und} not determined.")
    return "\n".join(out)


def table1_markdown(rows: pl.DataFrame) -> str:
    """Table 1 (A1..A4) and the text's constants as markdown, ours ± error beside the paper's."""
    out = ["| mu_s | parameter | granflow | paper (as printed) | distance / error | verdict |",
           "|---|---|---|---|---|---|"]
    for r in rows.iter_rows(named=True):
        digits = max(0, round(-math.log10(r["paper_unit"])))
        paper = "-" if not math.isfinite(r["paper"]) else (
            f"{r['paper']:.{digits}f}" + (" (interp.)" if r["paper_interpolated"]
                                          and r["parameter"].startswith("A") else ""))
        z = "-" if not math.isfinite(r["z"]) else f"{r['z']:.1f}"
        out.append(f"| {r['mu_s']:g} | {r['parameter']} | {pm(r['fit'], r['fit_err'])} | "
                   f"{paper} | {z} | {r['verdict']} |")
    return "\n".join(out)


#: the laws with a complete parameter set in 002 (mu3_0 is not given)
CURVE_LAWS = ("mu1", "mu2", "phi")
#: points on the I grid of a curve comparison
CURVE_GRID = 60


def _curve_sd(law: str, grid: np.ndarray, params: Sequence[float],
              cov: np.ndarray) -> np.ndarray:
    """The SD of a law's curve on ``grid`` from its parameters' covariance (the Jacobian by
    central differences)."""
    p = np.asarray(params, dtype=np.float64)
    jac = np.empty((grid.size, p.size))
    for k in range(p.size):
        h = 1e-6 * max(abs(p[k]), 1e-3)
        up, dn = p.copy(), p.copy()
        up[k] += h
        dn[k] -= h
        jac[:, k] = (rh.law_value(law, grid, *up) - rh.law_value(law, grid, *dn)) / (2 * h)
    return np.sqrt(np.maximum(np.einsum("ik,kl,il->i", jac, cov, jac), 0.0))


def curve_comparison(pool: pl.DataFrame, fits: Mapping[float, Mapping[str, rh.FitResult]],
                     n: int = 2000) -> pl.DataFrame:
    """The headline comparison: per mu_s where 002 gives a law's constants and per law, our
    fitted curve against the paper's over the I range of our fitted points (ours is not
    extrapolated), on a log grid: the largest |ours - paper| over its error (our fit's
    covariance, scaled as the table's errors, and the paper's constants' printed precision,
    a uniform half unit each, propagated through the curves), where it is, and the verdict."""
    rows = []
    for mu, f in fits.items():
        g = main_set(pool, n).filter(pl.col("mu_s") == mu)
        ref = rh.reference_parameters(mu)
        for law in CURVE_LAWS:
            fr = f.get(law)
            names = rh.LAWS[law].params
            paper = [float(ref[k]) for k in names]
            if fr is None or not fr.success or not all(map(math.isfinite, paper)) or g.height < 2:
                continue
            lo, hi = float(g["I"].min()), float(g["I"].max())  # type: ignore[arg-type]
            grid = np.geomspace(lo, hi, CURVE_GRID)
            ours = fr(grid)
            theirs = rh.law_value(law, grid, *paper)
            unit = np.diag([rh.printed_unit(k) ** 2 / 12.0 for k in names])
            sd = np.hypot(_curve_sd(law, grid, list(fr.params.values()), fr.cov_scaled),
                          _curve_sd(law, grid, paper, unit))
            z = (ours - theirs) / sd
            j = int(np.argmax(np.abs(z)))
            rows.append({"mu_s": mu, "law": rh.LAWS[law].equation.split()[0] + " " + law,
                         "I from": lo, "I to": hi, "points": g.height,
                         "largest |ours - paper|": float(np.max(np.abs(ours - theirs))),
                         "at I": float(grid[int(np.argmax(np.abs(ours - theirs)))]),
                         "largest |z|": float(abs(z[j])), "at I (z)": float(grid[j]),
                         "verdict": "agrees" if agrees(z[j])
                         else f"differs ({abs(z[j]):.1f} sigma)"})
    return pl.DataFrame(rows)


def offsets(pool: pl.DataFrame, n: int = 2000) -> pl.DataFrame:
    """Per mu_s with the paper's complete laws (0 and 0.3) and pressure: how far our points
    lie from the paper's curves at our own I, for mu1 (4.2), mu2 (4.4) and phi (4.7): the
    inverse-variance mean of (ours - paper(I)) with its SE, and the number of points; the
    points the laws are fitted to (I <= FIT_I_MAX, :func:`usable`)."""
    rows = []
    fitted = pool.filter((pl.col("N") == n) & (pl.col("I") <= FIT_I_MAX) & usable(pool))
    for (mu, p), g in fitted.group_by(["mu_s", "p_ext"], maintain_order=True):
        row: dict[str, Any] = {"mu_s": float(mu), "p_ext": float(p), "points": g.height}
        for col in ("mu1", "mu2", "phi"):
            try:
                mean, err = _mean_residual(
                    g, col, partial(rh.reference_curve, col, mu_s=float(mu)))
            except ValueError:
                row = {}
                break
            row[f"{col} - paper"], row[f"{col} - paper SE"] = mean, err
        if row:
            rows.append(row)
    return pl.DataFrame(rows).sort(["mu_s", "p_ext"]) if rows else pl.DataFrame()


def _mean_residual(g: pl.DataFrame, col: str,
                   curve: Callable[[np.ndarray], Any]) -> tuple[float, float]:
    """The inverse-variance mean of ``col`` - ``curve(I)`` over the points of ``g`` and its SE:
    each point's SE of ``col`` and its SE of I through the curve's slope (central to the
    comparison of points with a law)."""
    ii = g["I"].to_numpy()
    eps = 1e-6 * ii
    y = np.asarray(curve(ii))
    slope = (np.asarray(curve(ii + eps)) - y) / eps
    se = np.sqrt(g[f"{col}_se"].to_numpy() ** 2 + (slope * g["I_se"].to_numpy()) ** 2)
    return weighted_mean(g[col].to_numpy() - y, se)


#: the laws whose pressure collapse is tested (002 draws panels (b) of figs. 3, 4, 6)
COLLAPSE_LAWS = ("mu1", "mu2", "phi")


def collapse(pool: pl.DataFrame, n: int = 2000) -> pl.DataFrame:
    """Does each mu_s collapse over pressure? Per mu_s and law (:data:`COLLAPSE_LAWS`) with
    fitted points (:func:`main_set`) at two or more pressures of at least 4 points each: the
    nested-model F test of one law for those pressures against one law per pressure,
    F = ((chi2_joint - chi2_apart) / (3 (k - 1))) / (chi2_apart / (n - 3 k)), its p value, and
    per pressure the mean residual of its points from the joint law
    (:func:`_mean_residual`) with its z. 'collapses': p >= COLLAPSE_P; a mean residual alone
    can cancel where the pressures cover different ranges of I, the F test cannot."""
    from scipy.stats import f as f_dist

    rows = []
    for (mu,), g in main_set(pool, n).group_by(["mu_s"], maintain_order=True):
        parts = {p: h for (p,), h in g.group_by(["p_ext"]) if h.height >= 4}
        if len(parts) < 2:
            continue
        ps = sorted(parts, reverse=True)
        joint = rh.fit_all(pl.concat([parts[p] for p in ps]), include_x_errors=True,
                           states=None)
        alone = {p: rh.fit_all(parts[p], include_x_errors=True, states=None) for p in ps}
        k, npts = len(ps), sum(parts[p].height for p in ps)
        extra, dof_apart = 3 * (k - 1), npts - 3 * k
        for law in COLLAPSE_LAWS:
            one = joint.get(law)
            sep = [alone[p].get(law) for p in ps]
            if one is None or not one.success or any(a is None or not a.success for a in sep):
                continue
            chi_apart = sum(a.chi2 for a in sep if a is not None)
            f_val = (((one.chi2 - chi_apart) / extra) / (chi_apart / dof_apart)
                     if dof_apart > 0 and chi_apart > 0 else math.nan)
            p_val = float(f_dist.sf(f_val, extra, dof_apart)) if math.isfinite(f_val) else math.nan
            verdict = ("-" if not math.isfinite(p_val) else "collapses" if p_val >= COLLAPSE_P
                       else f"apart (p = {p_val:.1g})")
            for p in ps:
                h = parts[p]
                mean, err = _mean_residual(h, law, one)
                rows.append({"mu_s": float(mu), "law": law, "p_ext": float(p),
                             "points": h.height, "I from": float(h["I"].min()),  # type: ignore[arg-type]
                             "I to": float(h["I"].max()),  # type: ignore[arg-type]
                             "ours - joint": mean, "SE": err, "z": mean / err,
                             "chi2/dof joint": one.red_chi2,
                             "chi2/dof apart": chi_apart / dof_apart if dof_apart > 0
                             else math.nan, "F": f_val, "p": p_val, "verdict": verdict})
    return pl.DataFrame(rows)


#: the F test's p value below which the pressures do not collapse onto one law
COLLAPSE_P = 0.01


def matched_stress(pool: pl.DataFrame, n: int = 2000) -> tuple[pl.DataFrame, pl.DataFrame]:
    """The collapse without a law: at the same mu_s and imposed tau/p, a point at another
    pressure against the one at :data:`P_MAIN` (usable points, N = ``n``, any I). In a
    stress-controlled cell mu1 is imposed (mu1 ~ tau/p), so a collapse of mu1(I), mu2(I),
    phi(I) onto one curve needs equal I, phi, mu2 at equal tau/p. Returns the pairs (values,
    I's relative difference, z of each of :data:`REPORTED` from the combined SE) and per mu_s,
    pressure and quantity the chi-squared test of the pairs' z (sum z^2 over ``pairs``
    degrees of freedom; 'collapses': p >= COLLAPSE_P). Unlike the F test of :func:`collapse`
    it does not weaken where a law fits the points poorly."""
    from scipy.stats import chi2 as chi2_dist

    fit = pool.filter((pl.col("N") == n) & usable(pool))
    ref = fit.filter(pl.col("p_ext") == P_MAIN)
    other = fit.filter(pl.col("p_ext") != P_MAIN)
    if not ref.height or not other.height:
        return pl.DataFrame(), pl.DataFrame()
    j = other.join(ref, on=["mu_s", "tau_ratio"], suffix="_ref").sort(
        ["mu_s", "p_ext", "tau_ratio"], descending=[False, True, False])
    if not j.height:
        return pl.DataFrame(), pl.DataFrame()
    z = {q: (pl.col(q) - pl.col(f"{q}_ref"))
         / (pl.col(f"{q}_se") ** 2 + pl.col(f"{q}_se_ref") ** 2).sqrt() for q in REPORTED}
    pairs = j.select("mu_s", "p_ext", "tau_ratio", "I", pl.col("I_ref").alias(f"I at {P_MAIN:.0e}"),
                     (pl.col("I") / pl.col("I_ref") - 1.0).alias("dI/I"),
                     *(e.alias(f"z {q}") for q, e in z.items()),
                     (pl.col("phi") - pl.col("phi_ref")).alias("d phi"))
    rows = []
    for (mu, p), g in pairs.group_by(["mu_s", "p_ext"], maintain_order=True):
        for q in REPORTED:
            zz = g[f"z {q}"].to_numpy()
            chi = float(np.sum(zz**2))
            pv = float(chi2_dist.sf(chi, zz.size))
            rows.append({"mu_s": float(mu), "p_ext": float(p), "quantity": q,
                         "pairs": int(zz.size), "mean z": float(np.mean(zz)),
                         "chi2/pairs": chi / zz.size, "p": pv,
                         "verdict": "collapses" if pv >= COLLAPSE_P
                         else f"apart (p = {pv:.1g})"})
    return pairs, pl.DataFrame(rows)


def collapse_section(pool: pl.DataFrame, n: int) -> list[str]:
    """The pressure collapse as report lines: the matched-stress test
    (:func:`matched_stress`, the verdict) and the laws' F test (:func:`collapse`); none with
    one pressure."""
    pairs, tests = matched_stress(pool, n)
    tab = collapse(pool, n)
    if not pairs.height and not tab.height:
        return []
    lines = ["## Pressure collapse", "",
             "002: \"all the curves at various pressures collapse onto a master curve for each "
             "mu_s\" (§4.1-4.4), with phi \"moderately\" lower at lower pressure (§4.4)."]
    if pairs.height:
        apart = tests.filter(pl.col("verdict") != "collapses")
        lines += ["", f"**At the same imposed stress** (the verdict): a point at another "
                  f"pressure against the one at p_ext = {P_MAIN:.0e} with the same mu_s and "
                  "tau/p, each quantity's z from the combined SE. mu1 is imposed (mu1 ~ "
                  "tau/p), so the curves mu1(I), mu2(I), phi(I) collapse only if I, mu2 and "
                  "phi are equal at equal tau/p; per mu_s and pressure, the chi-squared test "
                  "of the pairs' z "
                  f"('collapses': p >= {COLLAPSE_P:g}). {tests.height - apart.height} of "
                  f"{tests.height} tests collapse"
                  + (": apart are " + "; ".join(
                      f"{r['quantity']} at mu_s = {r['mu_s']:g}, p_ext = {r['p_ext']:.0e} "
                      f"(mean z {r['mean z']:+.1f})" for r in apart.iter_rows(named=True))
                     if apart.height else "") + ".", "",
                  md_table(pairs, {"p_ext": ".0e", "I": ".4g", f"I at {P_MAIN:.0e}": ".4g",
                                   "dI/I": "+.3f", "z I": "+.1f", "z phi": "+.1f",
                                   "z mu1": "+.1f", "z mu2": "+.1f", "d phi": "+.4f"}), "",
                  md_table(tests, {"p_ext": ".0e", "mean z": "+.1f", "chi2/pairs": ".1f",
                                   "p": ".2g"}), ""]
    if tab.height:
        laws = tab.unique(["mu_s", "law"], maintain_order=True)
        ok = laws.filter(pl.col("verdict") == "collapses").height
        lines += ["**Through the fitted laws**: per mu_s and law, the F test of one law "
                  "for all pressures against one law per pressure (chi2 of both, from the "
                  "points' SEs with the SE of I through the law's slope; 'collapses': p >= "
                  f"{COLLAPSE_P:g}); per pressure, the mean residual of its fitted points from "
                  "the joint law with its z. Weaker than the test above where a law misfits "
                  "the points of one pressure already (chi2/dof apart >> 1: the F test "
                  "compares the pressures' difference with that misfit) and where the "
                  "pressures cover different ranges of I (the joint law bends to both). "
                  f"{ok} of {laws.height} laws pass it.", "",
                  md_table(tab, {"p_ext": ".0e", "I from": ".3g", "I to": ".3g",
                                 "ours - joint": "+.4f", "SE": ".4f", "z": "+.1f",
                                 "chi2/dof joint": ".2f", "chi2/dof apart": ".2f", "F": ".1f",
                                 "p": ".2g"}), ""]
    return lines + ["Figures 3(b), 4(b) and 6(b) below draw it.", ""]


def se_shrink(se: pl.DataFrame) -> pl.DataFrame:
    """Per observable: median over points of SE(fraction)/SE(all) against sqrt(1/fraction),
    over the points with both SEs (a fraction with too little data has none)."""
    rows = []
    full = se.filter(pl.col("fraction") == 1.0)
    key = [c for c in ("mu_s", "N", "p_ext", "tau_ratio", "seed") if c in se.columns]
    for f in sorted(set(se["fraction"].to_list())):
        part = se.filter(pl.col("fraction") == f).join(full, on=key, suffix="_all")
        row: dict[str, Any] = {"fraction of the run": f, "expected (T^-1/2)": 1 / math.sqrt(f)}
        for col in ("I", "phi", "mu1"):
            r = (part[f"{col}_se"] / part[f"{col}_se_all"]).to_numpy()
            r = r[np.isfinite(r)]  # (too little data for an SE: none)
            row[f"SE({col}) / SE(all)"] = float(np.median(r)) if r.size else math.nan
            row[f"points ({col})"] = int(r.size)
        rows.append(row)
    return pl.DataFrame(rows)


#: a pressure's own median steps stand for its paper-scale points once it has this many
#: flowing N = 2000 points; below, P_MAIN's median scaled by sqrt(P_MAIN / p)
MEDIAN_POINTS = 12


def median_steps(points: pl.DataFrame, p_ext: float = P_MAIN) -> tuple[float, bool]:
    """The median steps of shear of the flowing N = 2000 points at ``p_ext``, and whether
    it is measured there (at least MEDIAN_POINTS points); else P_MAIN's median times
    sqrt(P_MAIN / p_ext), the strain rate's inertial scaling."""
    def at(p: float) -> pl.DataFrame:
        return points.filter((pl.col("state") == "flowing") & (pl.col("N") == 2000)
                             & ((pl.col("p_ext") / p - 1).abs() < 1e-9))

    own = at(p_ext)
    if own.height >= MEDIAN_POINTS:
        return float(own["shear_steps"].median()), True  # type: ignore[arg-type]
    main = at(P_MAIN)
    if not main.height:
        return math.nan, False
    return float(main["shear_steps"].median()) * math.sqrt(P_MAIN / p_ext), False  # type: ignore[arg-type]


#: the band of the coverage audit's rms z that counts as honest SEs
COVERAGE_BAND = (0.7, 1.4)


def _scaled(plan: Any) -> str:
    """How a plan's times depend on the pressure, as a parenthesis (or nothing)."""
    if getattr(plan, "p_ref", None) is None:
        return ""
    return (f" (the stint, the minimum length and the cap below are those at p_ext = "
            f"{plan.p_ref:.0e}; at a lower p_ext they are sqrt({plan.p_ref:.0e}/p_ext) times "
            "longer, the inertial time's scaling: the same strain and correlation times)")


def what_was_run(points: pl.DataFrame, pool: pl.DataFrame, plan: Any, n: int) -> list[str]:
    """The runs, the stop rule, the states, and the runs that do not count (drifting, too
    little data, stopped at the cap)."""
    reps = points.group_by(list(KEYS)).len()["len"].to_numpy()
    most = int(reps.max()) if reps.size else 0
    lines = [
        f"{points.height} cell runs (granflow.scenes.cell.ShearCell, defaults but for the point: "
        "collision reading of t_c, e_n = exp(-1/4), kt = kn, gamma_t = gamma_n/2, diameters "
        "uniform in [0.9, 1.1], dt = 0.02 t_c, compacted start), p_ext = "
        + ", ".join(f"{p:.0e}" for p in sorted(set(points["p_ext"].to_list()), reverse=True))
        + f" kn/a; {most} independent seeds per point ({int((reps < most).sum())} points with "
        "fewer: the runaway probes, one each). States: " + ", ".join(f"{k} {v}" for k, v in sorted(
            points["state"].value_counts().iter_rows())) + ".", "",
        "**The stop rule** (`granflow.studies._campaign.cell.converged`), in stints of "
        f"{plan.stint:g} t_c{_scaled(plan)}: a run counts only once it is flowing and "
        "stationary (the means of the first and last thirds of its steady part within 3 SEs "
        "for each of I, phi, mu1, mu2: `granflow.analysis.stats.stationarity`); it may stop "
        f"only once its steady part spans {plan.min_length:,.0f} t_c, {plan.min_taus:g} "
        "integrated correlation times of the slowest of I, phi, mu1, mu2 and a shear strain of "
        f"{plan.min_strain:g}; only then are the SE targets consulted ("
        + ", ".join(f"{k} within {t:.0%}" for k, t in plan.targets().items())
        + f" of its mean); at most {plan.max_steps(n, P_MAIN):,} steps of shear"
        + (f" at p_ext = {P_MAIN:.0e}" if plan.p_ref is not None else "")
        + ". No SE rests on fewer than 10 blocks of 2 tau: a quantity with less data has "
        "none, and its point is not fitted.", "",
        "**mu1 and mu2** project the deviatoric stress on D and on (2.4)'s D^2 tensor built "
        "from D's deviatoric part, where 002 prints (4.1) and (4.3) with D for an isochoric "
        "flow: the barostat's breathing (tr D = d ln phi/dt, zero only in the mean) otherwise "
        "adds terms of zero mean to every sample that inflate the SEs (docs/cell.md; "
        "`python benchmarks/cell_breathing.py OUT` compares both forms on a campaign's "
        "series)."]
    drift = points.filter(pl.col("state") == "drifting")
    if drift.height:
        lines += ["", f"{drift.height} runs still drifted at the end of their budget; they are "
                  "not averaged and not fitted (their points keep their other seeds):", "",
                  md_table(drift.select("mu_s", "tau_ratio", "seed", "shear_steps",
                                        "drift_quantity", "drift_z", "I", "phi"),
                           {"drift_z": ".1f", "I": ".4f", "phi": ".4f"})]
    short = points.filter((pl.col("state") == "flowing")
                          & ~pl.col("converged").cast(pl.Boolean).fill_null(False))
    if short.height:
        tc = ([(pl.col("T_avg_tc")).alias("T (t_c)"),
               (pl.col("tau_max") * pl.col("T_avg_tc") / pl.col("T_avg")).alias("tau_max (t_c)")]
              if "T_avg_tc" in short.columns else [pl.col("T_avg")])
        tab = short.select(
            "mu_s", "tau_ratio", "seed", "shear_steps", *tc,
            (pl.col("I_se") / pl.col("I")).alias("SE(I)/I"),
            (pl.col("phi_se") / pl.col("phi")).alias("SE(phi)/phi"),
            (pl.col("mu1_se") / pl.col("mu1")).alias("SE(mu1)/mu1"))
        lines += ["", f"{short.height} flowing runs stopped at the step cap before the stop "
                  "rule was met (they count with their SEs; '-': too little data for one):",
                  "", md_table(tab, {"SE(I)/I": ".3f", "SE(phi)/phi": ".4f",
                                     "SE(mu1)/mu1": ".4f", "T_avg": ".0f", "T (t_c)": ".0f",
                                     "tau_max (t_c)": ".0f"})]
    lacking = pool.filter(~has_errors(pool))
    if lacking.height:
        lines += ["", f"{lacking.height} points lack an SE of a reported quantity (too little "
                  "data) and are not fitted: " + ", ".join(
                      f"mu_s = {r['mu_s']:g}, tau/p = {r['tau_ratio']:g}"
                      for r in lacking.iter_rows(named=True)) + "."]
    apart = pool.filter(has_errors(pool) & ~agreeing(pool))
    if apart.height:
        def worst(r: Mapping[str, Any]) -> str:
            c = min(REPORTED, key=lambda c: r.get(f"{c}_agree_p", 1.0))
            return f"{c}: p = {r[f'{c}_agree_p']:.1e}"

        lines += ["", f"{apart.height} points have replicas that disagree beyond their SEs (the "
                  f"chi-squared test of their agreement, p < {DISAGREE_P:g}, "
                  "`granflow.analysis.replicas`): no reproducible steady state at this run "
                  "length; listed, not fitted: " + "; ".join(
                      f"mu_s = {r['mu_s']:g}, tau/p = {r['tau_ratio']:g} ({worst(r)})"
                      for r in apart.iter_rows(named=True)) + "."]
    return lines


def coverage_section(points: pl.DataFrame, dataset: str) -> list[str]:
    """The coverage audit (:mod:`granflow.analysis.coverage`) of the steady replicas: a table
    with each quantity's rms z, its 95 % interval and worst pair, and the verdict."""
    tab = coverage(steady_rows(points), list(KEYS), REPORTED)
    lo, hi = COVERAGE_BAND
    inside = [r["observable"] for r in tab.iter_rows(named=True)
              if lo <= r["rms_z"] <= hi]
    return [
        "For every pair of seeds of a point (both steady) and each reported quantity, z = "
        "(x_a - x_b) / sqrt(SE_a^2 + SE_b^2) is standard normal for honest SEs: the root mean "
        "square of z over the pairs is 1, within the interval its degrees of freedom allow "
        "(the sum over points of seeds - 1). Made by "
        f"`python -m granflow.analysis.coverage {dataset}`:", "",
        md_table(tab.rename({"rms_z_lo": "95 % from", "rms_z_hi": "95 % to"}),
                 {"rms_z": ".2f", "95 % from": ".2f", "95 % to": ".2f", "max_abs_z": ".1f"}),
        "", f"rms z within {lo:g}-{hi:g}: {', '.join(inside) or 'none'}"
        + (f"; outside: {', '.join(o for o in tab['observable'] if o not in inside)}"
           if len(inside) < tab.height else "") + "."]


def curves_section(pool: pl.DataFrame, fits: Mapping[float, Mapping[str, rh.FitResult]],
                   n: int) -> list[str]:
    """The headline verdict: our curves against 002's (:func:`curve_comparison`)."""
    cmp = curve_comparison(pool, fits, n)
    if not cmp.height:
        return ["No law that 002 gives in full (mu_s = 0 and 0.3) could be fitted here (a "
                "fit needs at least four usable points of one mu_s)."]
    agree = cmp.filter(pl.col("verdict") == "agrees").height
    return [f"**{agree} of {cmp.height} curves agree** with 002's. Where 002 gives all of a "
            "law's constants (mu_s = 0 and 0.3, §4), our fitted curve against the paper's over "
            "the I range of our fitted points: the largest difference, and the largest "
            "difference over its error (our fit's covariance, scaled by sqrt(chi2/dof) where "
            "that exceeds 1, with the paper's constants known to half a unit of their printed "
            f"digits); 'agrees': within {AGREE_SIGMA:g} errors over the whole range.", "",
            md_table(cmp, {"I from": ".3g", "I to": ".3g", "largest |ours - paper|": ".4f",
                           "at I": ".3g", "largest |z|": ".1f", "at I (z)": ".3g"})]


def points_markdown(pool: pl.DataFrame) -> str:
    """The points' replica means with their SEs (within / between) as markdown."""
    cols = [c for c in REPORTED if c in pool.columns]

    def cell(r: Mapping[str, Any], c: str) -> str:
        v, e = r[c], r[f"{c}_se"]
        w, b = r[f"{c}_se_within"], r[f"{c}_se_between"]
        dig = 5 if abs(v) < 0.01 else 4
        # (one replica has no between-replica SE: '-', not 'nan')
        bs = f"{b:.{dig}f}" if math.isfinite(b) else "-"
        return (f"{v:.{dig}f} ± {e:.{dig}f} ({w:.{dig}f} / {bs})" if math.isfinite(e)
                else f"{v:.{dig}f} (not enough data)")

    def agree(r: Mapping[str, Any]) -> str:
        ps = [r[f"{c}_agree_p"] for c in cols if math.isfinite(r.get(f"{c}_agree_p", math.nan))]
        return f"{min(ps):.2g}" if ps else "-"

    out = ["| mu_s | N | p_ext | tau/p | seeds | " + " | ".join(cols)
           + " | replicas agree (smallest p) |", "|" + "---|" * (6 + len(cols))]
    for r in pool.sort(list(KEYS)).iter_rows(named=True):
        out.append(f"| {r['mu_s']:g} | {r['N']} | {r['p_ext']:.0e} | {r['tau_ratio']:g} | "
                   f"{r['replicas']} | " + " | ".join(cell(r, c) for c in cols)
                   + f" | {agree(r)} |")
    return "\n".join(out)


def _remaining(points: pl.DataFrame, plan: Any, rate: float) -> list[str]:
    """The plan's points not done in ``points`` (absent, or with a row from before the stop
    rule: the campaign runs them again, :meth:`CellStudy.current`) and their estimated
    core-hours (the median steps of their pressure, :func:`median_steps`, at the measured
    ``rate``), as report lines; none when the plan is done."""
    done = keys_done(points, Point, STUDY)
    left = [q for q in plan.points if q.key not in done]
    if not left:
        return []
    med = {p: median_steps(points, p) for p in {q.p_ext for q in left}}
    by_p: dict[float, tuple[int, float]] = {}
    for q in left:
        n, h = by_p.get(q.p_ext, (0, 0.0))
        by_p[q.p_ext] = (n + 1, h + q.N * med[q.p_ext][0] / rate / 3600)
    parts = ", ".join(f"{n} at p = {p:.0e} (~{h:.1f} core-hours, median steps "
                      f"{'measured' if med[p][1] else 'scaled'})"
                      for p, (n, h) in sorted(by_p.items(), reverse=True))
    total = sum(h for _, h in by_p.values())
    return [f"Not yet run: {len(left)} points of the {plan.name} plan: {parts}; about "
            f"{total:.0f} core-hours in all (`python -m granflow.studies.reproduce_002 "
            f"--{plan.name} --out DATASET --workers 2 --threads 1` goes on with them, two "
            "points at a time, one core each; committed in pieces).", ""]


def _pressures(pool: pl.DataFrame, n: int) -> str:
    """The pressures of the ``N = n`` points, highest first, as text."""
    ps = sorted(set(pool.filter(pl.col("N") == n)["p_ext"].to_list()), reverse=True)
    return ", ".join(f"{p:.0e}" for p in ps)


def size_effect_lines(pool: pl.DataFrame, n_main: int) -> list[str]:
    """The N = 10,000 points beside the same states at ``n_main`` (markdown; none without
    them): each quantity ± its SE and the difference in combined SEs (``-`` where an SE is
    missing, never NaN)."""
    big = pool.filter(pl.col("N") == 10_000)
    if not big.height:
        return []
    both = big.join(pool.filter(pl.col("N") == n_main), on=["mu_s", "p_ext", "tau_ratio"],
                    suffix="_small")

    def z(col: str) -> pl.Expr:
        return ((pl.col(col) - pl.col(f"{col}_small"))
                / (pl.col(f"{col}_se") ** 2 + pl.col(f"{col}_se_small") ** 2).sqrt())

    size = both.select(
        "mu_s", "tau_ratio",
        pm_column("I_small", "I_se_small", f"I (N={n_main})"),
        pm_column("I", "I_se", "I (N=10000)"),
        pm_column("phi_small", "phi_se_small", f"phi (N={n_main})"),
        pm_column("phi", "phi_se", "phi (N=10000)"),
        z("I").fill_null(float("nan")).alias("dI / error"),
        z("phi").fill_null(float("nan")).alias("dphi / error"))
    return [f"## Size effect (N = 10,000 against N = {n_main})", "",
            md_table(size, {"dI / error": ".1f", "dphi / error": ".1f"}), ""]


def write_report(out: Path, path: Path, plan: Any, paper: Sequence[Any]) -> Path:
    """Write the markdown report for the dataset in ``out`` (campaign ``plan``) to ``path``
    (figures beside it, in ``<path stem>_figures/``), with the cost of the ``paper`` points."""
    points = pl.read_parquet(out / "points.parquet")
    se = (pl.read_parquet(out / "se_vs_time.parquet")
          if (out / "se_vs_time.parquet").exists() else pl.DataFrame())
    pool = pooled(points)
    n_main = 2000 if 2000 in set(points["N"].to_list()) else int(points["N"].min())  # type: ignore[arg-type]
    fits = fits_by_mu(pool, n_main)
    rows = table_rows(fits)
    figdir = path.parent / f"{path.stem}_figures"
    figs = plot_figures(pool, fits, figdir, n_main)
    if se.height:
        figs.append(plot_campaign_se(se, figdir / "se_vs_time.png", ("I", "phi", "mu1"),
                                     [c for c in KEYS if c in se.columns] + ["seed"],
                                     xlabel="steady averaging time T (t_c)"))
    # (wall time and core-hours per piece: pressure, mu_s and N)
    per, rate = cost(points, ["p_ext", "N", "mu_s"], "N", "shear_steps",
                     columns=[pl.col("shear_steps").sum().alias("steps of shear")],
                     sort=["p_ext", "N", "mu_s"])
    per = per.sort("p_ext", "N", "mu_s", descending=[True, False, False])
    rel = path.parent
    dataset = out.as_posix()
    lines = [f"# Reproducing 002: Table 1 and figures 3-8 ({plan.name} campaign)", "",
             "Generated by `python -m granflow.studies.reproduce_002 "
             f"--{plan.name} --out {dataset} --report {path.as_posix()}`; the dataset reads back "
             f"with `pl.read_parquet('{dataset}/points.parquet')` (one row per run) and "
             f"`se_vs_time.parquet` (SE against averaging time).", "",
             "## What was run", "",
             *what_was_run(points, pool, plan, n_main), "",
             "## Coverage: do the runs' SEs hold across seeds?", "",
             *coverage_section(points, dataset), "",
             "## Against 002: the curves", "",
             *curves_section(pool, fits, n_main), "",
             "## Table 1, constant by constant", "",
             "Fits of (4.2), (4.4), (4.6), (4.7) to the replica means of every usable point at "
             f"N = {n_main}, p_ext = {_pressures(pool, n_main)} (all pressures together, as "
             f"002) and I <= {FIT_I_MAX:g} ("
             + (", ".join(f"mu_s = {r['mu_s']:g}, tau/p = {r['tau_ratio']:g} at I = {r['I']:.2f}"
                          for r in pool.filter((pl.col("N") == n_main)
                                               & (pl.col("I") > FIT_I_MAX)).iter_rows(named=True))
                or "none") + " left out: dense flow only; "
             f"errors from the fit's covariance, scaled by sqrt(chi2/dof) where "
             f"that exceeds 1; the SE of I propagated). 'agrees': within {AGREE_SIGMA:g} "
             "errors of the interval the paper's value stands for (its printed digits: 0.63 is "
             "0.625-0.635); 'not determined': the error exceeds "
             f"{rh.UNDETERMINED:.0%} of the value; the paper's A's are Table 1 (interpolated "
             "between its rows where marked), the other constants are given in §4 for mu_s = 0 and "
             "0.3 only. Constants are correlated within a law: read the curves above first.",
             "", _verdicts(rows), "", table1_markdown(rows), ""]
    lines += collapse_section(pool, n_main)
    off = offsets(pool, n_main)
    checks = protocol_checks(out)
    if off.height:
        lines += ["## Against the paper's curves at our I", "",
                  "Where 002 gives all of a law's constants (mu_s = 0 and 0.3, §4), the mean "
                  "distance of our fitted points (I <= "
                  f"{FIT_I_MAX:g}) from its curve at our own I (inverse-variance weighted, the "
                  "SE of I propagated through the curve's slope):", "",
                  md_table(off, {**{c: ".4f" for c in off.columns if c != "mu_s"},
                                  "p_ext": ".0e"}), "",
                  discussion(off, curve_comparison(pool, fits, n_main), rows,
                             checked=bool(checks)), ""]
    lines += checks
    lines += decided_lines(off, *check_tables(out))
    lines += ["## Points", "",
              "Every point's replica mean; ± the point's SE, the larger of the within-run SE "
              "(from the runs' own blocking SEs) and the between-replica SE (from their spread, "
              "with the Student small-sample factor), both given as (within / between); "
              "`granflow.analysis.replicas`.", "", points_markdown(pool), ""]
    lines += ["## Figures", "",
              "Figs. 3-6 as 002 draws them: (a) the quantity against I, our fit (solid) and "
              "002's curve (dashed, where §4 gives all its constants); (b) the pressure "
              "collapse at mu_s = 0 and 0.3; (c) and (d) our fitted quasi-static value and "
              "exponent against mu_s (all pressures, errors scaled by sqrt(chi2/dof) where that "
              "exceeds 1; open: not determined) with 002's (§4) as squares.", ""]
    lines += [f"![{p.stem}]({p.relative_to(rel)})" for p in figs] + [""]
    lines += size_effect_lines(pool, n_main)
    gone = points.filter(pl.col("state").is_in(ERROR_STATES))
    if gone.height:
        lines += ["## Ratios without a steady state", "",
                  "Above these ratios the cell dilates until the kernel's guard (20-fold "
                  "dilation from its densest state) stops it: phi when tau_ext was switched on "
                  "and at the last sample before the stop, after T_end contact times of shear.",
                  "", md_table(gone.select("mu_s", "N", "tau_ratio", "seed", "phi_start",
                                            "phi_end", "t_end", "state"),
                                {"phi_start": ".3f", "phi_end": ".3f", "t_end": ".0f"}), ""]
    if se.height:
        lines += ["## Error against run time", "",
                  "SE over the first quarter, half and all of each point's steady part, as a "
                  "ratio to the SE over all of it (median over points); blocking SEs of a "
                  "steady run shrink as T^-1/2. Where they shrink more slowly, the shorter "
                  "stretch's SE is too small: it sees only the correlations shorter than "
                  "itself (the slow volume mode needs a stretch of many of its correlation "
                  "times). That is why a run may stop only after the stop rule's minimum "
                  "length; shorter stretches are for this table only.", "",
                  md_table(se_shrink(se), {}), ""]
    # the paper points' steps: the median of our flowing N = 2000 points at the point's
    # pressure where measured, else at P_MAIN times sqrt(P_MAIN/p) (a strain rate
    # I sqrt(p/rho)/a takes that much longer per strain); the same count at N = 1e4 (its
    # smaller fluctuations would need fewer: an upper estimate)
    medians = {p: median_steps(points, p) for p in sorted({q.p_ext for q in paper}, reverse=True)}
    est = paper_scale_estimate(paper, lambda q: q.N * medians[q.p_ext][0], rate)
    steps_text = "; ".join(f"{v:,.0f} at p = {p:.0e} ({'measured' if m else 'scaled'})"
                           for p, (v, m) in medians.items())
    lines += ["## Cost", "",
              f"Measured throughput {rate:.3g} particle-steps per core-second (one thread a "
              "point, two points at a time on this 2-core machine; compaction not counted), "
              "from each point's CPU time where recorded, else its wall time (an upper bound "
              "where a point shared its core); longest point: wall time.",
              "", md_table(per, {"core-hours": ".3f", "longest point (s)": ".0f",
                                 "p_ext": ".0e"}), "",
              f"Total: {per['core-hours'].sum():.2f} core-hours.", "",
              *_remaining(points, plan, rate),
              "## The paper-scale campaign (recipe)", "",
              "002 runs N = 1e4, p_ext in {1e-4, 1e-5, 1e-6}, 14 mu_s, tau/p 0-1.2 and 3 "
              "realisations. `--paper` (reproduce_002.paper_plan) is that campaign over the "
              "ratios with steady flow here (8 per mu_s, interpolated between the measured "
              f"ends): {est['runs']:.0f} runs. From the median steps of our "
              f"flowing N = 2000 points ({steps_text}: a pressure with fewer than "
              f"{MEDIAN_POINTS} flowing points takes p = {P_MAIN:.0e}'s median times "
              f"sqrt({P_MAIN:.0e}/p), the slower strain rate) at the measured "
              f"throughput it needs about {est['core-hours']:,.0f} core-hours: "
              f"{est['core-hours'] / 64:,.0f} hours on 64 cores.", "",
              *dask_recipe("granflow.studies.reproduce_002", "results/paper_scale", "12:00:00")]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    return path
