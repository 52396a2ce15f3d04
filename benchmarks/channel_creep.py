"""Does a finished widths-campaign point keep creeping? Continue it from its checkpoint to the
plan's cap with no stop before it, then print |v_cm| and the phi profile per window of time.

    python benchmarks/channel_creep.py W20_phi0.6_kn100000_B10_H20_rain_s1
           [--data docs/data/reproduce_000_widths] [--work /tmp/creep] [--window 300]

The point's work directory (its checkpoint, git-ignored: on the machine that ran it) is copied
to ``--work`` first, so the campaign's own checkpoint and rows are left as they are. The
continuation runs the widths plan's stints with the SE target set to 0 (never met), so it
stops only at the plan's cap (t_max). Printed: per ``--window`` time units, the mean
|v_cm|, phi per bin from the wall to the centre (folded) and the mean sigma_xx; then the
row's creep over its
steady part (reproduce_000.creep_row). The flow-development question of the widths report's
creep section ("Creep within the steady parts").
"""

from __future__ import annotations

import argparse
import shutil
from dataclasses import replace
from pathlib import Path

import polars as pl
from granflow.studies import reproduce_000 as rp
from granflow.studies._campaign import run_point


def windows(work: Path, key: str, W: float, width: float) -> pl.DataFrame:
    """|v_cm| and the folded phi profile per ``width`` time units of the run in ``work``."""
    d = work / key
    s = pl.read_parquet(d / "series.parquet", columns=["t", "vcm_y"]).with_columns(
        (pl.col("t") // width * width).alias("from"))
    v = s.group_by("from").agg(pl.col("vcm_y").abs().mean().alias("|v_cm|"))
    b = pl.read_parquet(d / "bins.parquet", columns=["t0", "x", "phi", "sigma_xx"]).with_columns(
        (pl.col("t0") // width * width).alias("from"),
        pl.min_horizontal(pl.col("x"), W - pl.col("x")).alias("xi"))
    prof = b.group_by("from", "xi").agg(pl.col("phi").mean()).sort("from", "xi").group_by(
        "from", maintain_order=True).agg(
        pl.col("phi").round(4).cast(pl.String).str.join(" ").alias("phi (wall -> centre)"))
    sxx = b.group_by("from").agg(pl.col("sigma_xx").mean().alias("sigma_xx"))
    return v.join(prof, on="from").join(sxx, on="from").sort("from")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("key", help="a finished point's key, e.g. W20_phi0.6_kn100000_B10_H20_rain_s1")
    ap.add_argument("--data", type=Path, default=Path("docs/data/reproduce_000_widths"))
    ap.add_argument("--work", type=Path, default=Path("/tmp/granflow_creep"))
    ap.add_argument("--window", type=float, default=300.0)
    a = ap.parse_args()
    plan = replace(rp.widths_plan(), se_target=0.0)
    point = next((p for p in plan.points if p.key == a.key), None)
    if point is None:
        raise SystemExit(f"invalid key {a.key!r}: not a point of the widths plan")
    src = a.data / "work" / a.key
    if not (src / "checkpoint.gfck").exists():
        raise SystemExit(f"no checkpoint in {src}: the point ran on another machine")
    if not (a.work / a.key).exists():
        shutil.copytree(src, a.work / a.key)
    row = run_point(rp.STUDY, point, plan, str(a.work))
    with pl.Config(tbl_rows=-1, fmt_str_lengths=200, tbl_width_chars=200):
        print(windows(a.work, a.key, point.W, a.window))
    print({k: row.get(k) for k in ("state", "t_start", "t_end", "creep", "creep_se", "creep_z",
                                   "drift_z", "u_slip", "u_slip_se", "phi_plug", "cpu_seconds")})


if __name__ == "__main__":
    main()
