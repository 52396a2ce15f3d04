"""The 000 report's verdicts on 000's claims: each claim "holds", "does
not hold" or "cannot tell at this scale" against the dataset's points, with the measured
value and the reason (:func:`verdicts`), and the report's section of them."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import polars as pl

from granflow.analysis.channel import L_C_PAPER, fit_phi_ad
from granflow.analysis.compare import AGREE_SIGMA, agrees, interval_z
from granflow.analysis.coverage import steady_rows

from ._campaign import md_table, pm
from .reproduce_000_figures import KINETIC
from .reproduce_000_report_shape import OWN, own_values
from .reproduce_000_report_values import (
    NED,
    PHI_PLUG_PRINTED,
    POINT_BY,
    RATIO_PAPER,
    W_PAPER_MIN,
    W_SCALING_MIN,
    drifting,
    main_depth,
    main_steady,
    pooled,
    steady_points,
    with_state_000,
)

#: 000 §3.2: l_c = 11.5 d (printed: 11.45-11.55)
L_C_PRINTED = (L_C_PAPER - 0.05, L_C_PAPER + 0.05)
#: 000 §3.2: Omega/omega is "close to 1/2" in the dense and loose zones, read off fig. 9a
#: (no digits printed): taken as 1/2 within 10 %. 1/2 exactly is the continuum's value (no
#: microscopic torques); the distance from it is given beside the verdict
OMEGA_RATIO_HALF = 0.5
OMEGA_RATIO_PAPER = (0.45, 0.55)
#: a divergence fit whose chi2 has a p-value below this does not describe its bins
FORM_P = 1e-3
#: u_max/u_slip on its own correlation time (reproduce_000_report_shape)
OWN_RATIO = OWN.format("u_max_over_u_slip")
#: 000 §3.2 (fig. 13): the divergence fits give phi_ad = 0.59 +- 0.002
PHI_AD_PAPER = (0.59, 0.002)


def kinetic_fits(profiles: pl.DataFrame) -> list[tuple[str, dict[str, float]]]:
    """Each kinetic coefficient's label and fit_phi_ad over the loose-zone bins of the
    unbranched points in ``profiles``."""
    loose = profiles.filter(pl.col("zone") == "loose", pl.col("parent") == "")
    return [(name, fit_phi_ad(loose["phi"].to_numpy(), loose[col].to_numpy(),
                              loose[f"{col}_se"].to_numpy())) for col, name in KINETIC]


def judge(value: float, se: float, lo: float, hi: float,
           resolve: tuple[float, float] | None = None) -> tuple[str, str]:
    """(verdict, how far) of a value with its SE against 000's interval [lo, hi].
    ``resolve`` = (the measurement's own SE, 000's quoted +-): an agreement whose own SE
    exceeds 000's precision cannot confirm it ("cannot tell"); a disagreement still counts."""
    z = interval_z(value, se, lo, hi)
    if not math.isfinite(z):
        return "cannot tell at this scale", NED
    interval = f"{lo:g}" + (f"-{hi:g}" if hi != lo else "")
    far = f"inside {interval}" if z == 0 and hi != lo else f"{z:.1f} SEs from {interval}"
    if not agrees(z):
        return "does not hold", far
    if resolve is not None and resolve[0] > resolve[1]:
        return ("cannot tell at this scale",
                far + f", but the fit's own SE {resolve[0]:.4f} exceeds 000's ± {resolve[1]:g}")
    return "holds", far


def combined(verdicts: list[str]) -> str:
    """One verdict of several (a claim judged width by width): "does not hold" where any does
    not, "holds" where all hold, else "cannot tell at this scale"."""
    if any(v == "does not hold" for v in verdicts):
        return "does not hold"
    return "holds" if verdicts and all(v == "holds" for v in verdicts) else \
        "cannot tell at this scale"


def replica_rows(points: pl.DataFrame, rows: pl.DataFrame) -> pl.DataFrame:
    """The steady, unbranched runs of ``points`` that are replicas of the point rows ``rows``
    (empty where ``points`` lacks the point's fields)."""
    need = (*POINT_BY, "parent", "state")
    if not points.height or not all(c in points.columns for c in need):
        return points.clear()
    keys = rows.select(*POINT_BY).unique()
    return steady_rows(points.filter(pl.col("parent") == "")).join(
        keys, on=list(POINT_BY), how="semi")


def value_at(rows: pl.DataFrame, points: pl.DataFrame, col: str,
             factors: Mapping[str, float] | None = None) -> tuple[float, float, str]:
    """``col`` of the point rows ``rows`` (one width, its phi_bar) with its SE (:func:`pooled`)
    and how it was got. A point one of whose replicas gave fewer than MIN_SE_BLOCKS blocks has
    no SE (replica_mean); then the value is pooled over the replicas that have one, said as
    " (k of n runs)", their SE times ``factors[col]`` (:func:`audit_factors`: the shortfall
    of run SEs the coverage audit measures, as point_values applies it to a one-replica
    point), "" otherwise."""
    se = f"{col}_se"
    if rows[se].is_finite().fill_null(False).all():
        return (*pooled(rows, col), "")
    runs = replica_rows(points, rows)
    if col in runs.columns and se in runs.columns:
        ok = runs.filter(pl.col(col).is_finite().fill_null(False)
                         & pl.col(se).is_finite().fill_null(False))
        if ok.height:
            m, e = pooled(ok, col)
            f = (factors or {}).get(col, 1.0)
            return m, e * f, (f" ({ok.height} of {runs.height} runs"
                              + (f", SE × {f:.2f} by the audit)" if f != 1.0 else ")"))
    return (*pooled(rows, col), "")


def no_plug_reasons(wide: pl.DataFrame, profiles: pl.DataFrame | None) -> dict[float, str]:
    """Per W of ``wide`` whose runs found no plug (xi_plug at the centre: from the centre
    out every bin shears beyond 2 SEs, granflow.analysis.channel.zones), what the central
    half of the half profile shows: the median |du/dx| and its median z, and whether of one
    sign. 000's plug is where the shear rate is zero within its error (§3.2)."""
    need = ("W", "xi", "gamma_dot", "gamma_dot_se", "parent")
    if profiles is None or not profiles.height or not all(c in profiles.columns for c in need):
        return {}
    out = {}
    for r in wide.filter(pl.col("xi_plug") >= pl.col("W") / 2 - 0.5).iter_rows(named=True):
        w = r["W"]
        c = profiles.filter(pl.col("W") == w, pl.col("parent") == "", pl.col("xi") >= w / 4)
        g, e = c["gamma_dot"].to_numpy(), c["gamma_dot_se"].to_numpy()
        ok = np.isfinite(g) & np.isfinite(e) & (e > 0)
        if not ok.any():
            continue
        g, e = g[ok], e[ok]
        sign = "of either sign" if (g > 0).any() and (g < 0).any() else "of one sign"
        out[w] = (f"no plug: the central {w / 4:g} d shear at |du/dx| ~ "
                  f"{float(np.median(np.abs(g))):.1e} ({float(np.median(np.abs(g) / e)):.0f} "
                  f"SEs, median), {sign}")
    return out


def widest_steady(values: pl.DataFrame) -> float:
    """The widest W of the points the verdicts judge (:func:`main_steady`); NaN for none."""
    st = main_steady(values)
    return float(st["W"].max()) if st.height else math.nan  # type: ignore[arg-type]


def wider_drifts(points: pl.DataFrame, values: pl.DataFrame) -> pl.DataFrame:
    """The runs wider than the widest steady point (every run without one) that ran but
    whose mean drifts, by W: the verdicts name them as a reason (:func:`drift_reasons`)."""
    if not points.height or "drift_z" not in points.columns:
        return points.clear()
    widest = widest_steady(values)
    return drifting(points).filter(pl.col("W") > (widest if math.isfinite(widest) else 0.0)) \
        .sort("W", "phi_bar", "seed")


def drift_reasons(points: pl.DataFrame, values: pl.DataFrame) -> list[str]:
    """A line per run of :func:`wider_drifts`, with its measure: the thirds test's |z| and
    its slowest correlation time against the time it averaged."""
    return [f"- W = {r['W']:g} (φ̄ = {r['phi_bar']:g}) ran to t = {r['t_end']:.0f} but drifts "
            f"({r['drift_quantity']}: |z| = {r['drift_z']:.1f} by the thirds test; its "
            f"slowest correlation time {r['tau_max']:.0f} against {r['T_avg']:.0f} averaged)."
            for r in wider_drifts(points, values).iter_rows(named=True)]


def main_own(own: pl.DataFrame) -> pl.DataFrame:
    """The points of ``own`` (reproduce_000_report_shape.own_values) at k_n = 1e5 and the
    main depth, less the stiffness branches: as :func:`main_steady` takes them."""
    if not own.height:
        return pl.DataFrame(schema={"W": pl.Float64, OWN_RATIO: pl.Float64,
                                    f"{OWN_RATIO}_se": pl.Float64, "replicas": pl.Int64})
    return main_depth(steady_points(own).filter(~pl.col("branch")))


def with_own_ratio(steady: pl.DataFrame, points: pl.DataFrame) -> pl.DataFrame:
    """``steady`` (:func:`main_steady`'s points) with a point's u_max/u_slip and its SE
    taken on the ratio's own correlation time (:func:`main_own`) where the level's blocks
    gave it no SE (a slow mode: too few blocks) and its runs carry one; ``ratio_how`` says
    so (" (own τ, N runs)"), "" where the point keeps its own."""
    d = steady.with_columns(pl.lit("").alias("ratio_how"))
    own = main_own(own_values(points, POINT_BY)) if d.height else pl.DataFrame()
    if not own.height:
        return d
    d = d.join(own.select(*POINT_BY, pl.col(OWN_RATIO).alias("_r"),
                          pl.col(f"{OWN_RATIO}_se").alias("_r_se"),
                          pl.col("replicas").alias("_n")), on=list(POINT_BY), how="left")
    use = (~pl.col("u_max_over_u_slip_se").is_finite().fill_null(False)
           & pl.col("_r_se").is_finite().fill_null(False))
    return d.with_columns(
        pl.when(use).then(pl.col("_r")).otherwise(pl.col("u_max_over_u_slip"))
        .alias("u_max_over_u_slip"),
        pl.when(use).then(pl.col("_r_se")).otherwise(pl.col("u_max_over_u_slip_se"))
        .alias("u_max_over_u_slip_se"),
        pl.when(use).then(pl.format(" (own τ, {} runs)", pl.col("_n")))
        .otherwise(pl.col("ratio_how")).alias("ratio_how")).drop("_r", "_r_se", "_n")


def ratio_how(points: pl.DataFrame) -> str:
    """How a group of :func:`with_own_ratio`'s points got u_max/u_slip ("" or
    " (own τ, N runs)"), once per kind."""
    return "".join(sorted(set(points["ratio_how"])))


def verdicts(points: pl.DataFrame, values: pl.DataFrame,
             profiles: pl.DataFrame | None = None,
             factors: Mapping[str, float] | None = None) -> pl.DataFrame:
    """000's claims, each "holds", "does not hold" (the measured value more
    than AGREE_SIGMA SEs outside 000's interval) or "cannot tell at this scale" (no point at
    000's widths, or no SE), with the measured value and the reason. At 000's widths only:
    W >= W_SCALING_MIN for the scaling claims (the two widest steady widths there), W >=
    W_PAPER_MIN for the others; k_n = 1e5 points (000: 1e6; fig. 10 finds phi and u the same).
    With ``profiles`` (the steady k_n = 1e5 points' half profiles) also phi_ad from the
    divergence of the kinetic coefficients in the loose zone (:func:`phi_ad_fits`) at W >=
    W_PAPER_MIN; it holds only where the fit resolves 000's +- 0.002."""
    st = main_steady(values)
    rows: list[dict[str, Any]] = []

    def add(claim: str, paper: str, measured: str, verdict: str, why: str) -> None:
        rows.append({"claim (000)": claim, "000": paper, "measured here": measured,
                     "verdict": verdict, "why": why})

    widest = widest_steady(values)
    scale_why = (f"the widest steady channel here is W = {widest:g}" if st.height
                 else "no steady point")
    # a wider run that ran but whose mean drifts is named (its measure: wider_drifts)
    drifts = wider_drifts(points, values)
    if drifts.height:
        scale_why += "; " + ", ".join(
            f"W = {w:g} (φ̄ = {p:g}) drifts" for w, p in drifts.select("W", "phi_bar")
            .iter_rows()) + " (below the table)"
    # the scaling exponents between the two widest widths >= 100, per phi_bar, pooled
    for raw, name, n0 in (("u_slip", "u_slip ∝ √W", 0.5), ("u_max", "u_max ∝ √W", 0.5),
                          ("delta_095", "δ0.95 ∝ W", 1.0)):
        ns, es = [], []
        for (_,), g in st.filter(pl.col("W") >= W_SCALING_MIN).group_by(["phi_bar"]):
            g = g.sort("W")
            if g.height < 2:
                continue
            a, b = g.row(-2, named=True), g.row(-1, named=True)
            span = math.log(b["W"] / a["W"])
            ns.append(math.log(b[raw] / a[raw]) / span)
            es.append(math.hypot(a[f"{raw}_se"] / a[raw], b[f"{raw}_se"] / b[raw]) / span)
        if not ns:
            add(name + " (W ≥ 100)", f"exponent {n0:g}", "-", "cannot tell at this scale",
                scale_why + " (two steady widths >= 100 needed)")
            continue
        n, e = pooled(pl.DataFrame({"n": ns, "n_se": es}), "n")
        verdict, far = judge(n, e, n0, n0)
        add(name + " (W ≥ 100)", f"exponent {n0:g}", f"exponent {pm(n, e, 2)}", verdict,
            far + f" ({len(ns)} φ̄)")
    wide = st.filter(pl.col("W") >= W_PAPER_MIN)
    # u_max/u_slip in 1.37-1.40 at every W and phi_bar: the worst width; a point without an
    # SE (the level's slow mode: too few blocks) on the ratio's own correlation time where
    # its runs carry it (with_own_ratio); a width with neither: "cannot tell" there
    per = [(w, *pooled(g, "u_max_over_u_slip"), ratio_how(g))
           for (w,), g in with_own_ratio(wide, points).group_by(["W"], maintain_order=True)]
    if per:
        per.sort(key=lambda p: p[0])
        judged = [(w, m, e, *judge(m, e, *RATIO_PAPER), how) for w, m, e, how in per]
        bad = [j for j in judged if j[3] == "does not hold"]
        unknown = [j for j in judged if j[3] != "holds" and j[3] != "does not hold"]
        show = bad or unknown or judged
        add("u_max/u_slip = 1.37-1.40 for every W, φ̄", "1.37-1.40",
            "; ".join(f"W = {w:g}: {pm(m, e, 4)}{how}" for w, m, e, _, _, how in judged),
            combined([j[3] for j in judged]),
            "; ".join(f"W = {w:g}: {far}" for w, _, _, _, far, _ in show))
    else:
        add("u_max/u_slip = 1.37-1.40 for every W, φ̄", "1.37-1.40", "-",
            "cannot tell at this scale", scale_why + " (000: W = 60-150)")
    # the plug's phi, l_c, Omega/omega: width by width at 000's widths (they change with W)
    no_plug = no_plug_reasons(wide, profiles)
    for col, claim, paper, (lo, hi), digits in (
            ("phi_plug", "plug φ ≈ 0.63", "0.63", PHI_PLUG_PRINTED, 4),
            ("l_c", "conduction length l_c = 11.5 d", "11.5", L_C_PRINTED, 2),
            ("omega_ratio_shearing", "Ω/ω → 1/2 in the shear zones", "1/2 (taken as ± 10 %)",
             OMEGA_RATIO_PAPER, 4)):
        if not wide.height:
            add(claim, paper, "-", "cannot tell at this scale", scale_why)
            continue
        rows_ = []
        for (w,), g in wide.sort("W").group_by(["W"], maintain_order=True):
            m, e, how = value_at(g, points, col, factors)
            verdict, far = judge(m, e, lo, hi)
            if far == NED and col != "omega_ratio_shearing" and w in no_plug:
                far = no_plug[w]
            elif col == "omega_ratio_shearing" and math.isfinite(e) and e > 0:
                far += f"; {abs(m - OMEGA_RATIO_HALF) / e:.0f} SEs from 1/2 exactly"
            rows_.append((w, m, e, how, verdict, far))
        add(claim, paper, "; ".join(f"W = {w:g}: {pm(m, e, digits)}{how}"
                                    for w, m, e, how, _, _ in rows_),
            combined([r[4] for r in rows_]),
            "; ".join(f"W = {w:g}: {far}" for w, _, _, _, _, far in rows_))
    # mu_wall: independent of W (the narrowest and widest of 000's widths at each phi_bar)
    mw = []
    for (phi,), g in wide.sort("W").group_by(["phi_bar"], maintain_order=True):
        if g.height >= 2:
            (v0, e0, h0), (v1, e1, h1) = (value_at(g.filter(pl.col("W") == g["W"][i]),
                                                   points, "wall_friction", factors)
                                          for i in (0, -1))
            mw.append((phi, g["W"][0], g["W"][-1], v1 - v0, math.hypot(e0, e1), h0 + h1))
    if mw:
        zs = [dv / e for *_, dv, e, _ in mw]
        ok = all(math.isfinite(z) for z in zs)
        verdict = ("cannot tell at this scale" if not ok else
                   "holds" if all(agrees(z) for z in zs) else "does not hold")
        add("μ_wall independent of W", "independent of W (fig. 7b)",
            "; ".join(f"φ̄ = {p:g}, W {a:g} → {b:g}: {pm(dv, e, 4, signed=True)}{how}"
                      for p, a, b, dv, e, how in mw), verdict,
            "; ".join(f"φ̄ = {p:g}: " + (f"{dv / e:+.1f} SEs" if math.isfinite(dv / e) else NED)
                      for p, _, _, dv, e, _ in mw)
            + " (the change from the narrowest to the widest of 000's widths)")
    else:
        add("μ_wall independent of W", "independent of W (fig. 7b)", "-",
            "cannot tell at this scale", scale_why + " (two steady widths >= 60 needed)")
    # phi_ad at 000's widths, as its other claims (its fig. 13 is from those channels); a fit
    # whose own SE exceeds 000's +- 0.002 agrees with anything near 0.59 and so cannot
    # confirm it: "holds" needs that resolution (a fit that far off still does not hold)
    at_paper = (profiles.filter(pl.col("W") >= W_PAPER_MIN) if profiles is not None
                and profiles.height else pl.DataFrame())
    if at_paper.height:
        fits = []
        for name, f in kinetic_fits(at_paper):
            v, e = f["phi_ad"], math.hypot(f["phi_ad_se"], PHI_AD_PAPER[1])
            verdict, far = judge(v, e, PHI_AD_PAPER[0], PHI_AD_PAPER[0],
                                 resolve=(f["phi_ad_se"], PHI_AD_PAPER[1]))
            # (a form that misfits its bins locates no divergence, whatever its phi_ad: the
            # SE above is widened by sqrt(chi2/dof) and the location is given, not judged)
            if f["chi2_p"] < FORM_P:
                verdict = "does not hold"
                far = (f"A/(φ_ad - φ) misfits its {f['n']} bins, χ²/dof = "
                       f"{f['chi2_per_dof']:.3g} (φ_ad {far})")
            fits.append((name.split(" ")[0], v, e, verdict, far))
        verdict = combined([j[3] for j in fits])
        add("φ_ad: the kinetic coefficients diverge at 0.59 ± 0.002 (fig. 13)",
            "0.59 ± 0.002", "; ".join(f"{n}: {pm(v, e, 4)}" for n, v, e, *_ in fits),
            verdict, "; ".join(f"{n}: {far}" for n, _, _, _, far in fits)
            + " (the SE with 000's ± 0.002; bins of the loose zone at W >= "
            f"{W_PAPER_MIN:g} pooled)")
    elif profiles is not None:
        add("φ_ad: the kinetic coefficients diverge at 0.59 ± 0.002 (fig. 13)",
            "0.59 ± 0.002", "-", "cannot tell at this scale", scale_why
            + " (a loose zone at W >= 60 needed)")
    # the states: steady at 0.59-0.61, fluctuating at 0.62, jammed above (W >= 60)
    flow = points.filter((pl.col("parent") == "") & (pl.col("W") >= W_PAPER_MIN)) \
        if points.height else points
    if flow.height:
        want = {0.59: "steady", 0.60: "steady", 0.61: "steady", 0.62: "fluctuating"}
        seen = [(r["W"], r["phi_bar"], r["state_000"])
                for r in with_state_000(flow).iter_rows(named=True)
                if round(r["phi_bar"], 2) in want and r["state_000"] is not None]
        miss = [(w, p, st_) for w, p, st_ in seen if st_ != want[round(p, 2)]]
        add("states: steady at φ̄ 0.59-0.61, fluctuating at 0.62, jammed above",
            "steady / fluctuating / jammed", f"{len(seen) - len(miss)} of {len(seen)} runs "
            "as 000", "cannot tell at this scale" if not seen else
            "holds" if not miss else "does not hold",
            "; ".join(f"W = {w:g}, φ̄ = {p:g}: {st_}" for w, p, st_ in miss)
            or ("no run's v_cm state recorded" if not seen else "φ̄ tested: " + ", ".join(
                f"{p:g}" for p in sorted({p for _, p, _ in seen}))))
    else:
        add("states: steady at φ̄ 0.59-0.61, fluctuating at 0.62, jammed above",
            "steady / fluctuating / jammed", "-", "cannot tell at this scale",
            "no run at W >= 60")
    return pl.DataFrame(rows)


def verdict_lines(points: pl.DataFrame, values: pl.DataFrame, profiles: pl.DataFrame,
                  factors: Mapping[str, float] | None = None) -> list[str]:
    """000's claims, one line each (:func:`verdicts`; ``factors``: the coverage audit's,
    :func:`audit_factors`)."""
    if not points.height:
        return []
    tab = verdicts(points, values, profiles if profiles.height else None, factors)
    drifts = drift_reasons(points, values)
    count = {v: int((tab["verdict"] == v).sum())
             for v in ("holds", "does not hold", "cannot tell at this scale")}
    return ["## 000's claims: verdicts", "",
            f"Each claim against this dataset: 'holds' within {AGREE_SIGMA:g} SEs of 000's "
            "value (its printed digits' interval), 'does not hold' beyond, 'cannot tell at "
            f"this scale' without a point at 000's widths (W >= {W_PAPER_MIN:g}; the scaling "
            f"claims two steady widths >= {W_SCALING_MIN:g}) or without an SE. "
            + ", ".join(f"{k}: {n}" for k, n in count.items()) + ".", "", md_table(tab), "",
            *([*drifts, ""] if drifts else [])]
