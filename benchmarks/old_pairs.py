"""The 002 campaign's worst pairs of seeds before issue 34, under its rules: each run again to
its old length (the same seed and steps: the same series), then classified and judged by the
cell campaign's row and stop rule of today.

    python benchmarks/old_pairs.py [--rev 5045371] [--workers 2]

The old rows come from docs/data/reproduce_002/points.parquet at git revision ``--rev`` (the
dataset before the re-run). Per run: I then and now (equal: the same run), the state now (a
drift across the steady part makes it "drifting"), the thirds test's largest |z|, the steady
part's length against the minimum the stop rule asks for (both in t_c), and whether the rule
lets it stop.
"""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
from pathlib import Path

import polars as pl

ROOT = Path(__file__).resolve().parents[1]
#: the issue's worst pairs: (mu_s, tau/p), seeds 1 and 2, N = 2000, p = 1e-4
PAIRS = ((0.0, 0.4), (0.2, 0.6), (0.01, 0.4))


def old_points(rev: str) -> pl.DataFrame:
    """The 002 dataset's points at git revision ``rev``."""
    raw = subprocess.run(["git", "show", f"{rev}:docs/data/reproduce_002/points.parquet"],
                         cwd=ROOT, check=True, capture_output=True).stdout
    return pl.read_parquet(io.BytesIO(raw))


def judge(mu_s: float, tau: float, seed: int, steps: int, threads: int = 1
          ) -> dict[str, object]:
    """Run the point ``steps`` steps of shear and return today's row and verdict."""
    from granflow.studies._campaign.cell import STUDY, Point, long_enough, point_row
    from granflow.studies.reproduce_002 import full_plan

    plan = full_plan()
    p = Point(mu_s, tau, seed)
    cell = STUDY.scene(p, plan, threads)
    cell.prepare(progress=False)
    cell.run(steps, progress=False)
    row = point_row(p, plan, cell.tables()["series"], float(cell.shear_start_time))
    return {"mu_s": mu_s, "tau_ratio": tau, "seed": seed, "shear_steps": steps,
            "I now": row.get("I"), "state now": str(row["state"]),
            "drift |z|": row.get("drift_z"), "drift in": row.get("drift_quantity"),
            "T (t_c)": row.get("T_avg_tc"),
            # (tau_max in kernel time, as T_avg: over T_avg / T_avg_tc in t_c)
            "minimum (t_c)": max(plan.min_length, plan.min_taus * row.get("tau_max", 0.0)
                                 * row.get("T_avg_tc", 0.0) / row.get("T_avg", 1.0)),
            "may stop": bool(long_enough(row, plan))}


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--rev", default="5045371")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    from granflow.study import map_tasks

    old = old_points(a.rev).filter((pl.col("N") == 2000) & (pl.col("p_ext") == 1e-4))
    args, then = [], {}
    for mu, tau in PAIRS:
        for seed in (1, 2):
            r = old.filter((pl.col("mu_s") == mu) & (pl.col("tau_ratio") == tau)
                           & (pl.col("seed") == seed)).row(0, named=True)
            args.append((mu, tau, seed, int(r["shear_steps"])))
            then[(mu, tau, seed)] = (r["I"], r["I_se"], r["state"])
    rows = []
    for _, row in map_tasks(judge, args, workers=a.workers):
        i, se, st = then[(row["mu_s"], row["tau_ratio"], row["seed"])]
        rows.append({**row, "I then": i, "SE then": se, "state then": st})
    d = pl.DataFrame(rows).sort("mu_s", "tau_ratio", "seed").select(
        "mu_s", "tau_ratio", "seed", "shear_steps", "state then", "I then", "SE then", "I now",
        "state now", "drift |z|", "drift in", "T (t_c)", "minimum (t_c)", "may stop")
    with pl.Config(tbl_rows=-1, tbl_cols=-1, tbl_width_chars=220):
        print(d)
    counted = d.filter(pl.col("state now") == "flowing").filter(pl.col("may stop"))
    print(f"{counted.height} of {d.height} old runs would count under today's rules")
    return 0 if counted.height == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
