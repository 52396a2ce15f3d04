"""The 000 report's section on creep: does a run's flow still speed up (or slow down)
through the steady part the stop rule accepted? The straight-line trend of |v_cm| of each
steady run (reproduce_000.creep_row: ``creep``, ``creep_se``, ``creep_z`` of its row), pooled
over a point's replicas."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import polars as pl

from granflow.analysis.coverage import steady_rows
from granflow.analysis.stats import weighted_mean

from ._campaign import md_table

#: a point's pooled creep beyond this many SEs counts as creeping
CREEP_Z = 3.0
#: replicas whose ends differ by more than this (time units: a few windows) stopped apart
STOP_APART = 10.0


def creep_table(points: pl.DataFrame, by: Sequence[str]) -> pl.DataFrame:
    """Per point (its fields ``by``, the seed aside) with steady replicas that carry it
    (reproduce_000.creep_row): the creep of |v_cm| through the steady parts, relative per
    1000 time units, pooled over the replicas (inverse-variance mean and SE), its z, each
    replica's z, the steady parts' span, and whether the replicas stopped apart (their ends
    more than STOP_APART apart: a creep then spreads them by where each stopped)."""
    st = steady_rows(points) if points.height else points
    if not st.height or "creep" not in st.columns:
        return pl.DataFrame()
    st = st.filter(pl.col("creep").is_finite() & pl.col("creep_se").is_finite()
                   & (pl.col("creep_se") > 0))
    rows = []
    for key, g in st.sort("seed").group_by(list(by), maintain_order=True):
        c, se = weighted_mean(g["creep"].to_numpy(), g["creep_se"].to_numpy())
        rows.append({**dict(zip(by, key, strict=True)), "replicas": g.height,
                     "creep per 1000 t": c, "SE": se, "z": c / se,
                     "replicas' z": ", ".join(f"{z:+.1f}" for z in g["creep_z"].to_list()),
                     "steady parts": f"t = {g['t_start'].to_numpy().min():.0f}-"
                                     f"{g['t_end'].to_numpy().max():.0f}",
                     "stopped apart": bool(np.ptp(g["t_end"].to_numpy()) > STOP_APART)})
    return pl.DataFrame(rows).sort(list(by)) if rows else pl.DataFrame()


def creep_lines(points: pl.DataFrame, by: Sequence[str]) -> list[str]:
    """The creep table (:func:`creep_table`) and what it says; none without the fields."""
    tab = creep_table(points, by)
    if not tab.height:
        return []
    creeping = tab.filter(pl.col("z").abs() > CREEP_Z)
    lines = ["### Creep within the steady parts", "",
             "The straight-line trend of |v_cm| through each steady part (its SE corrected for "
             "serial correlation, granflow.analysis.stats.steady.trend), relative per 1000 "
             "time units, pooled over a point's replicas (inverse-variance). It is not part of "
             "the stop rule: the thirds test judges each run alone, and a creep within its "
             "errors still moves a run's means: alike for replicas that average over the "
             "same span (a bias), by where each stopped for replicas that stop apart (a "
             "spread).", "",
             md_table(tab.drop(*(c for c in ("kn", "B", "H", "stopped apart")
                                 if c in tab.columns)),
                      {"creep per 1000 t": "+.4f", "SE": ".4f", "z": "+.1f"}), ""]
    if creeping.height:
        apart = ", ".join(f"W = {r['W']:g}, φ̄ = {r['phi_bar']:g}"
                          for r in creeping.iter_rows(named=True) if r["stopped apart"])
        lines += [f"**{creeping.height} of {tab.height} points creep** (pooled |z| > "
                  f"{CREEP_Z:g}): "
                  + "; ".join(f"W = {r['W']:g}, φ̄ = {r['phi_bar']:g}: "
                              f"{r['creep per 1000 t']:+.1%} per 1000 time units (z "
                              f"{r['z']:+.1f})" for r in creeping.iter_rows(named=True))
                  + ". These flows were still changing through their averaged spans (+: "
                  "speeding up): they had not finished developing when the average began"
                  + (f"; the replicas of {apart} stopped apart, so their spread in the audit "
                     "above is in part where each one stopped" if apart else "")
                  + ".", ""]
    return lines
