"""The 000 report's reading of its dataset: the rules applied to a run's row (the 10-block
rule, the drifting runs, 000's state of a run) and a point's value from its replicas, with
000's numbers the tables and the claims compare against (:mod:`.reproduce_000_report`, the
report; :mod:`.reproduce_000_report_claims`, the verdicts)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import polars as pl

from granflow.analysis.coverage import steady_rows
from granflow.analysis.replicas import replica_mean
from granflow.analysis.rheology import pool_realizations
from granflow.analysis.stats import MIN_SE_BLOCKS
from granflow.states import FlowState

#: 000 §3.1: u_max/u_slip "varying by about 2 % in a very small range 1.37-1.40"
RATIO_PAPER = (1.37, 1.40)
#: 000 §3.2: phi in the plug "~0.63", printed with two decimals: 0.625-0.635
PHI_PLUG_PAPER = 0.63
PHI_PLUG_PRINTED = (0.625, 0.635)
#: what the report writes where a quantity has no SE: its steady part gave fewer than
#: MIN_SE_BLOCKS jackknife blocks
NED = "not enough data"
#: the quantities whose SE rests on where the plug ends (the plug edge needs the SE of du/dx:
#: without it the analysis leaves the plug undetermined, granflow.analysis.channel.zones)
PLUG_QUANTITIES = ("xi_plug", "phi_plug", "l_c")
#: the reported quantities (columns of points.parquet, each with its ``_se``): the value of a
#: point over its replicas and the coverage audit
REPORTED = ("u_slip", "u_max", "u_max_over_u_slip", "delta_095", "mean_velocity_ratio",
            "wall_friction", "sigma_xx_mean")
#: audited across replicas beside REPORTED (the plug's packing, set by each run's preparation)
AUDITED = ("phi_plug",)
#: a point's fields less the seed (and the parent key, which names its parent's seed): the
#: replicas of a point share them
POINT_BY = ("W", "phi_bar", "kn", "B", "H")
#: 000's scale: its claims are made for W = 60-150 (the scaling claims for W >= 100)
W_PAPER_MIN, W_SCALING_MIN = 60.0, 100.0


def refuse_few_blocks(points: pl.DataFrame, table: pl.DataFrame | None = None) -> pl.DataFrame:
    """``table`` (default ``points``) with every ``*_se`` of a run whose steady part gave fewer
    than MIN_SE_BLOCKS jackknife blocks set to NaN, and (points) its plug quantities too:
    the rule the analysis now applies (granflow.analysis.stats.jackknife_se), applied to a
    dataset written before it. The runs' block counts are the ``n_blocks`` column of
    points.parquet (the blocks behind every SE of the run: its profiles, zone means and
    section 3 numbers come from the one jackknife); ``table``'s rows are matched to their run
    by the point's fields. The shape quantities on their own correlation times keep their
    SEs (their own blocks: reproduce_000_report_shape)."""
    key = [*POINT_BY, "seed"]
    few = points.filter(pl.col("n_blocks").fill_null(0) < MIN_SE_BLOCKS).select(key)
    d = points if table is None else table
    if not d.height or not few.height:
        return d
    d = d.join(few.with_columns(pl.lit(True).alias("_few")), on=key, how="left")
    bad = pl.col("_few").fill_null(False)
    # (a shape quantity on its own correlation time has blocks of its own, X_own_blocks)
    cols = [c for c in d.columns if c.endswith("_se") and not c.endswith("_own_se")]
    if table is None:
        cols += [c for c in PLUG_QUANTITIES if c in d.columns]
    return d.with_columns(*(pl.when(bad).then(float("nan")).otherwise(pl.col(c).cast(
        pl.Float64)).alias(c) for c in cols)).drop("_few")


def drifting(points: pl.DataFrame) -> pl.DataFrame:
    """The runs whose steady part drifts (state "drifting"): left out of every table and fit."""
    return points.filter(pl.col("state") == FlowState.DRIFTING.value)


def with_state_000(points: pl.DataFrame) -> pl.DataFrame:
    """``points`` with ``state_000``: a run's state as 000 classifies it, from v_cm's
    fluctuations. A drifting mean overrides ``state``, so a drifting run's v_cm state is in
    ``vcm_state``; a drifting row from before that column has none (null: not judged)."""
    own = (pl.when(pl.col("state") != FlowState.DRIFTING.value).then(pl.col("state"))
           .otherwise(None))
    vcm = pl.col("vcm_state") if "vcm_state" in points.columns else pl.lit(None, pl.String)
    return points.with_columns(state_000=pl.coalesce(vcm, own))


def audit_factors(tab: pl.DataFrame) -> dict[str, float]:
    """Per audited quantity whose run SEs the coverage audit ``tab`` (:func:`coverage_table`)
    finds too small (the 95 % interval of rms z above 1), that rms z: the factor by which a
    run's SE falls short of the spread between its replicas."""
    return {r["observable"]: float(r["rms_z"]) for r in tab.iter_rows(named=True)
            if r["pairs"] > 0 and r["rms_z_lo"] > 1}


def point_values(points: pl.DataFrame,
                 factors: Mapping[str, float] | None = None) -> pl.DataFrame:
    """One row per point (POINT_BY; ``branch``: a stiffness branch) from its steady replicas:
    every ``X`` with ``X_se`` as their mean with ``X_se``, ``X_se_within`` and
    ``X_se_between`` (:func:`granflow.analysis.replicas.replica_mean`; NaN where a replica has
    no SE), ``replicas``, ``n_blocks`` the fewest blocks of a replica, and the zone boundaries
    without an SE (xi_plug, xi_wall) as the replicas' mean.

    ``factors`` (:func:`audit_factors`): a point with one replica has no between-replica SE
    to fall back on, so its ``X_se`` is its run SE times ``factors[X]`` (``audit_scaled``:
    True); ``X_se_within`` stays the run's own. That carries the audit of the points with
    replicas over to it: an assumption (a run's SE falling short by the same factor at
    another width), stated where the report uses it."""
    d = steady_rows(points)
    if not d.height:
        return pl.DataFrame()
    obs = [c for c in d.columns if f"{c}_se" in d.columns and c not in POINT_BY]
    rm = replica_mean(d.with_columns(*(pl.col(c).cast(pl.Float64) for c in
                                       (*obs, *(f"{o}_se" for o in obs)))), POINT_BY, obs)
    scale = {o: f for o, f in (factors or {}).items() if o in obs}
    one = pl.col("replicas") == 1
    rm = rm.with_columns(*(pl.when(one).then(pl.col(f"{o}_se") * f).otherwise(
        pl.col(f"{o}_se")).alias(f"{o}_se") for o, f in scale.items()),
        # flagged only where a scaled SE exists (a run too short for blocks has none to scale)
        (one & pl.any_horizontal(pl.lit(False), *(pl.col(f"{o}_se").is_finite().fill_null(False)
                                                  for o in scale))).alias("audit_scaled"))
    extra = d.group_by(list(POINT_BY)).agg(
        pl.col("n_blocks").min(), pl.col("xi_plug").mean(), pl.col("xi_wall").mean(),
        pl.col("l_c_at_bound").any(), (pl.col("parent").str.len_chars() > 0).any().alias(
            "branch"))
    return rm.join(extra, on=list(POINT_BY), how="left").sort(["W", "phi_bar", "kn"])


def main_depth(values: pl.DataFrame) -> pl.DataFrame:
    """The points at the campaign's main depth (the most common B): the depth check's other
    depths (:func:`depth_table`) stay out of the width tables, fits and verdicts."""
    if not values.height:
        return values
    b = values["B"].mode().sort()[0]
    return values.filter(pl.col("B") == b)


def steady_points(values: pl.DataFrame, kn: float | None = 1e5) -> pl.DataFrame:
    """The points of :func:`point_values` at ``kn`` (None: every k_n)."""
    d = values
    if kn is not None and d.height:
        d = d.filter((pl.col("kn") / kn - 1).abs() < 1e-9)
    return d.sort(["W", "phi_bar"]) if d.height else d


def main_steady(values: pl.DataFrame) -> pl.DataFrame:
    """The k_n = 1e5 points of ``values`` (:func:`steady_points`) less the stiffness
    branches: what the fig. 5 tables, the verdicts and the findings are made of."""
    return steady_points(values).filter(~pl.col("branch")) if values.height else values


def pooled(g: pl.DataFrame, col: str) -> tuple[float, float]:
    """The inverse-variance mean of ``col`` over the rows of ``g`` that have an SE, and its SE
    (:func:`granflow.analysis.rheology.pool_realizations`); the plain mean and NaN where no
    row has one."""
    se = f"{col}_se"
    ok = g.select(col, se).filter(pl.col(col).is_finite() & pl.col(se).is_finite()
                                  & (pl.col(se) > 0))
    if not ok.height:
        v = g[col].to_numpy()
        return (float(np.nanmean(v)) if np.isfinite(v).any() else math.nan), math.nan
    r = pool_realizations(ok.with_columns(_all=pl.lit(0)), ["_all"]).row(0, named=True)
    return float(r[col]), float(r[se])
