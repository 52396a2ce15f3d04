"""The 000 report's section on the velocity profile's shape on its own correlation time.

The flow's level (u_max, the mean velocity, the plug) has a slow mode at W >= 60 (hundreds of
time units: the plug's speed relaxing against the shear zones' drag), which sets every run's
jackknife blocks; a run capped at 000's 2000 + 600 and a little more then holds too few of them
for any SE. The shape of the profile (u_max/u_slip, delta_095) moves with the level far
less: each run's row carries it on blocks of its own correlation time, with its own thirds
test (reproduce_000.point_row: ``X_own``, ``X_own_se``, ``X_own_tau``, ``X_own_blocks``,
``X_own_z``; granflow.analysis.channel.own_blocked). A run whose level drifts still counts
here where its shape passes its own test; its v_cm state must be a flowing one."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import polars as pl

from granflow.analysis.channel import SHAPE_QUANTITIES
from granflow.analysis.coverage import pair_z
from granflow.analysis.replicas import replica_mean
from granflow.states import FlowState

from ._campaign import md_table, pm, sig

#: the row columns of a shape quantity ``X`` on its own correlation time
OWN = "{}_own"


def _flowing(points: pl.DataFrame) -> pl.DataFrame:
    """The rows whose v_cm state (``vcm_state``, else ``state``) is a steady one: the flow
    itself is steady or fluctuating, whatever the thirds test says of its level."""
    vcm = pl.col("vcm_state") if "vcm_state" in points.columns else pl.col("state")
    ok = [s.value for s in FlowState if s.is_steady]
    return points.filter(pl.coalesce(vcm, pl.col("state")).is_in(ok))


def own_rows(points: pl.DataFrame) -> pl.DataFrame:
    """The flowing runs (:func:`_flowing`) that carry a shape quantity with an SE on its own
    correlation time (rows from before the columns have none)."""
    cols = [OWN.format(k) for k in SHAPE_QUANTITIES]
    if not points.height or any(f"{c}_se" not in points.columns for c in cols):
        return points.clear()
    d = _flowing(points)
    return d.filter(pl.any_horizontal(*(pl.col(f"{c}_se").is_finite().fill_null(False)
                                        for c in cols)))


def own_values(points: pl.DataFrame, by: Sequence[str]) -> pl.DataFrame:
    """Per point (``by``) with runs of :func:`own_rows`: each shape quantity ``X_own`` as its
    replicas' mean with ``X_own_se`` the larger of the within-run and between-replica SEs
    (granflow.analysis.replicas.replica_mean), the longest correlation time and the fewest
    blocks of its replicas, and ``branch`` (a stiffness branch). A replica without the SE of
    one quantity leaves that quantity's SE NaN (its other quantities count)."""
    d = own_rows(points)
    if not d.height:
        return pl.DataFrame()
    cols = [OWN.format(k) for k in SHAPE_QUANTITIES]
    d = d.with_columns(*(pl.col(c, f"{c}_se").cast(pl.Float64) for c in cols))
    rm = replica_mean(d, by, cols)
    extra = d.group_by(list(by)).agg(
        *(pl.col(f"{c}_tau").max() for c in cols),
        *(pl.col(f"{c}_blocks").min() for c in cols),
        (pl.col("parent").fill_null("").str.len_chars() > 0).any().alias("branch"),
        pl.col("state").str.join(", ").alias("states"))
    return rm.join(extra, on=list(by), how="left").sort(list(by))


def _kn(row: Mapping[str, Any]) -> dict[str, str]:
    """The k_n cell of a point's row where the point has one (the stiffness branches share
    W and phi_bar with their parents)."""
    return {"k_n": f"{row['kn']:.0e}"} if row.get("kn") is not None else {}


def shape_lines(points: pl.DataFrame, by: Sequence[str]) -> list[str]:
    """The section: per point, the shape quantities on their own correlation times beside
    the level's (``tau_max``), and the replicas' agreement; none without such runs."""
    vals = own_values(points, by)
    if not vals.height:
        return []
    r, dl = OWN.format("u_max_over_u_slip"), OWN.format("delta_095")
    lvl = (own_rows(points).group_by(list(by)).agg(pl.col("tau_max").max().alias("level τ"))
           if "tau_max" in points.columns else None)
    if lvl is not None:
        vals = vals.join(lvl, on=list(by), how="left")
    rows = []
    for v in vals.iter_rows(named=True):
        rows.append({"W": v["W"], "φ̄": v["phi_bar"], **_kn(v), "runs": v["replicas"],
                     "states": v["states"],
                     "u_max/u_slip": pm(v[r], v[f"{r}_se"], 4),
                     "within / between": " / ".join(
                         sig(v[f"{r}_se_{k}"]) for k in ("within", "between")),
                     "τ": f"{v[f'{r}_tau']:.1f}", "blocks": v[f"{r}_blocks"],
                     "δ0.95": pm(v[dl], v[f"{dl}_se"], 3),
                     "τ δ0.95": f"{v[f'{dl}_tau']:.1f}",
                     "level τ": (f"{v['level τ']:.0f}" if v.get("level τ") is not None
                                 and math.isfinite(v["level τ"]) else "-")})
    lines = ["## The profile's shape on its own correlation time", "",
             "Where a run's level (u_max, the mean velocity, the plug's φ) has a slow mode, "
             "its jackknife blocks are as long as that mode's correlation time, and a run "
             "stopped at the cap can hold too few for any SE (the tables above then print "
             "none). The profile's shape, u_max/u_slip and δ0.95, moves with the level far "
             "less: each run carries it on blocks of its own correlation time (τ; at least 10 "
             "blocks, the blocking at its plateau) and its own thirds test "
             "(granflow.analysis.channel.own_blocked), so a run whose level drifts still "
             "counts here where its shape is stationary (its v_cm state must be flowing). "
             "Runs: mean over the point's runs; SE the larger of within-run and between-run "
             "(both shown); 'level τ' the slowest correlation time of the stop rule's "
             "quantities (tau_max).", "",
             md_table(pl.DataFrame(rows)), ""]
    cols = [OWN.format(k) for k in SHAPE_QUANTITIES]
    pz = pair_z(own_rows(points), by, cols)
    if pz.height:
        lines += ["Pairs of runs of a point, their difference over its combined SE (1 for "
                  "honest SEs): " + "; ".join(
                      f"W = {p['W']:g}, φ̄ = {p['phi_bar']:g}"
                      + "".join(f", k_n = {k}" for k in _kn(p).values())
                      + f" (seeds {p['seed_a']}, "
                      f"{p['seed_b']}): u_max/u_slip z = {p[f'z_{r}']:+.1f}, δ0.95 z = "
                      f"{p[f'z_{dl}']:+.1f}" for p in pz.iter_rows(named=True)) + ".", ""]
    return lines
