"""Stress-controlled cell (002) at mu = 0.3, p_ext = 1e-4: a sweep over tau_ext/p_ext, which
runs arrest and which flow, beta and d2/d1 in steady flow, and the measured (I, mu1, phi) beside
the paper's curves for mu = 0.3. Resumable (finished runs are skipped).

    python examples/cell_study.py OUT [--N 2000] [--ratios 0.3 0.4 0.5 0.6 0.7 0.8]
           [--steps 200000] [--workers 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import polars as pl
from granflow.analysis import rheology as rh
from granflow.study import run_grid


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--N", type=int, default=2000)
    ap.add_argument("--ratios", type=float, nargs="+", default=[0.3, 0.4, 0.5, 0.6, 0.7, 0.8])
    ap.add_argument("--p", type=float, default=1e-4)
    ap.add_argument("--mu", type=float, default=0.3)
    ap.add_argument("--steps", type=int, default=200_000)
    ap.add_argument("--workers", type=int, default=1)
    a = ap.parse_args()
    base = {
        "scene": "cell",
        "params": {"N": a.N, "mu": a.mu, "p_ext": a.p, "sample_every": 250},
        "run": {"steps": a.steps, "checkpoint_every": a.steps // 4},
        "output": {},
    }
    t0 = time.perf_counter()
    df = run_grid(base, {"tau_ratio": a.ratios}, a.out, seeds=[1], workers=a.workers)
    cols = ["tau_ratio", "state", "mu1", "mu1_se", "I", "I_se", "phi", "phi_se", "beta",
            "wall_seconds"]
    df = df.select([c for c in cols if c in df.columns]).sort("tau_ratio")
    if "I" in df.columns:
        ref_mu1 = rh.reference_curve("mu1", np.maximum(df["I"].fill_null(0).to_numpy(), 1e-12),
                                     mu_s=a.mu)
        ref_phi = rh.reference_curve("phi", np.maximum(df["I"].fill_null(0).to_numpy(), 1e-12),
                                     mu_s=a.mu)
        df = df.with_columns(pl.Series("paper_mu1(I)", ref_mu1),
                             pl.Series("paper_phi(I)", ref_phi))
    pl.Config.set_tbl_cols(20)
    pl.Config.set_tbl_width_chars(200)
    print(df)
    print(f"total {time.perf_counter() - t0:.0f} s")
    df.write_csv(f"{a.out}/sweep.csv")


if __name__ == "__main__":
    main()
