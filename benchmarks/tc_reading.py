"""What the contact-time reading changes (issue 21): the stress-controlled cell at one imposed
tau/p, run with 002's printed t_c and with the force law's collision time (granflow.scenes.cell
.contact_time), several seeds each; prints the steady means of I, phi and mu1 with their
standard errors, the restitution each reading implies, and the paper's mu1(I), phi(I).

    python benchmarks/tc_reading.py [--N 500] [--tau 0.45] [--steps 100000] [--seeds 1 2]
           [--workers 2] [--out benchmarks/out/tc_reading.parquet]
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import polars as pl
from granflow.analysis import rheology as rh
from granflow.scenes.cell import ShearCell


def one(args: tuple[str, int, int, float, int]) -> dict[str, object]:
    reading, seed, n, tau, steps = args
    t0 = time.perf_counter()
    c = ShearCell(N=n, mu=0.3, p_ext=1e-4, tau_ratio=tau, sample_every=250, seed=seed,
                  tc_reading=reading, threads=1)
    c.run(steps)
    s = c.summary()
    m_e = float(np.mean(np.pi * c._d**3 / 6)) / 2
    # the binary collision time of the law as run, and its restitution exp(-gamma_n t_coll/2)
    gamma = 0.5 / c.t_c
    t_coll = np.pi / np.sqrt(c.kn / m_e - gamma**2 / 4)
    out = {"reading": reading, "seed": seed, "N": n, "tau_ratio": tau, "steps": steps,
           "t_c": c.t_c, "e_n": float(np.exp(-gamma * t_coll / 2)),
           "wall_seconds": time.perf_counter() - t0}
    for k in ("state", "I", "I_se", "phi", "phi_se", "mu1", "mu1_se"):
        out[k] = s.get(k)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, default=500)
    ap.add_argument("--tau", type=float, default=0.45)
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    jobs = [(r, s, a.N, a.tau, a.steps) for r in ("printed", "collision") for s in a.seeds]
    with ProcessPoolExecutor(a.workers) as ex:
        rows = list(ex.map(one, jobs))
    df = pl.DataFrame(rows)
    inertial = np.maximum(df["I"].fill_null(0).to_numpy(), 1e-12)
    df = df.with_columns(
        pl.Series("paper_mu1(I)", rh.reference_curve("mu1", inertial, mu_s=0.3)),
        pl.Series("paper_phi(I)", rh.reference_curve("phi", inertial, mu_s=0.3)))
    pl.Config.set_tbl_cols(30)
    pl.Config.set_tbl_width_chars(250)
    print(df)
    # per reading: the mean over seeds and its seed-to-seed standard error
    agg = [pl.col("t_c").mean(), pl.col("e_n").first(), pl.len().alias("seeds")]
    for k in ("I", "phi", "mu1"):
        agg += [pl.col(k).mean(), (pl.col(k).std() / pl.len().sqrt()).alias(k + "_sem")]
    print(df.group_by("reading").agg(agg).sort("reading"))
    if a.out:
        df.write_parquet(a.out)


if __name__ == "__main__":
    main()
