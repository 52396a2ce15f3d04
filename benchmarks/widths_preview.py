"""A running widths point, previewed: how its flow and its plug still change, and the row it
would get if its development time were ``--t-dev`` (a forecast of the stop rule, not a result).

    python benchmarks/widths_preview.py W100_phi0.6_kn100000_B10_H20_rain_s1 --t-dev 1000

Reads the point's tables from docs/data/reproduce_000_widths/work/<key> (this machine's run;
``--dir`` for another, e.g. the committed copy under progress/, whose bins start at its
development time). Prints, per ``--every`` time units from ``--from``: the means of the stop
rule's window quantities (granflow.analysis.channel.STEADY_QUANTITIES) and of phi in the
plug (xi >= ``--plug``), the shear zones (3 <= xi < 12) and the wall layer (xi < 3); their
correlation times from ``--from`` on; then the point's row with t_dev = ``--t-dev``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from granflow.analysis import channel as ach
from granflow.analysis.channel_profiles import profiles
from granflow.studies import reproduce_000 as r

WORK = Path(__file__).resolve().parent.parent / "docs/data/reproduce_000_widths/work"
ROW_KEYS = ("state", "converged", "t_start", "T_avg", "n_blocks", "u_slip", "u_max",
            "u_max_over_u_slip", "delta_095", "phi_plug", "drift_z", "drift_quantity",
            "tau_max", "creep")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("key")
    ap.add_argument("--t-dev", type=float, default=1000.0)
    ap.add_argument("--from", dest="t_from", type=float, default=100.0)
    ap.add_argument("--every", type=float, default=100.0)
    ap.add_argument("--plug", type=float, default=20.0, help="xi where the plug starts")
    ap.add_argument("--dir", type=Path, default=None)
    a = ap.parse_args()
    d = a.dir or WORK / a.key
    bins, series = pq.read_table(d / "bins.parquet"), pq.read_table(d / "series.parquet")
    prof = profiles(bins, start_time=a.t_from)
    xi = prof.xi

    def phis(m: dict[str, np.ndarray]) -> np.ndarray:
        phi = np.asarray(prof.derived(m)["phi"])
        return np.array([phi[xi >= a.plug].mean(), phi[(xi >= 3) & (xi < 12)].mean(),
                         phi[xi < 3].mean()])

    q = ach.window_quantities(prof)
    ph = prof.window_series(phis)
    step = max(1, round(a.every / prof.window_dt))
    for i in range(0, len(ph), step):
        cells = "  ".join(f"{k} {np.mean(v[i:i + step]):.3f}" for k, v in q.items())
        p = ph[i:i + step].mean(axis=0)
        print(f"t ~ {a.t_from + i * prof.window_dt:6.0f}  {cells}  phi plug {p[0]:.4f} "
              f"shear {p[1]:.4f} wall {p[2]:.4f}")
    tau = ach.steady_check(prof).tau
    print(f"correlation times from t = {a.t_from:g}:",
          ", ".join(f"{k} {v:.1f}" for k, v in tau.items()))
    plan = dataclasses.replace(r.widths_plan(), t_dev=a.t_dev)
    point = next(p for p in plan.points if p.key == a.key)
    n = json.loads((d / "meta.json").read_text())["context"]["n"]
    row = r.point_row(point, plan, bins, series, n=n)
    print(f"row as if t_dev = {a.t_dev:g}:")
    for k in ROW_KEYS:  # (a run that is not steady gets its state alone)
        v, se = row.get(k), row.get(f"{k}_se")
        if v is None:
            continue
        print(f"  {k} = {v:.5g}" if isinstance(v, float) else f"  {k} = {v}",
              f"± {se:.2g}" if isinstance(se, float) else "")


if __name__ == "__main__":
    main()
