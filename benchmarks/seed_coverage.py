"""Are the cell's standard errors honest? The same point run with many seeds: the spread of the
seeds' steady means against the SE each run reports (issue 21, item 7).

    python benchmarks/seed_coverage.py [--seeds 32] [--N 500] [--tau 0.45] [--steps 300000]
           [--workers 2] [--reanalyse]

Each seed is a ShearCell (compacted start, defaults otherwise) run ``--steps`` steps after the
compaction; its series is kept in benchmarks/out/seed_coverage/ (``--reanalyse`` only
re-reads them). Per observable (I, phi, mu2, mu1): ratio = standard deviation of the seeds'
means / root mean square of their reported SEs; with honest SEs it is 1 within the sampling
error of a standard deviation from K seeds (~1/sqrt(2(K-1)): 0.18 for 16, 0.13 for 32; 32 is
the default since 16 seeds' noise spans the band's margin). PASS when it is within 0.7-1.4 for
I, phi and mu2. Runs that are not steady (the drift test) are left out, as a campaign does.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import polars as pl

OUT = Path(__file__).resolve().parent / "out" / "seed_coverage"
CHECKED = ("I", "phi", "mu2")
SHOWN = CHECKED + ("mu1",)
BAND = (0.7, 1.4)


def run_seed(seed: int, n: int, tau: float, steps: int, path: str, threads: int = 1) -> str:
    from granflow.scenes.cell import ShearCell

    c = ShearCell(N=n, mu=0.3, p_ext=1e-4, tau_ratio=tau, seed=seed, sample_every=200,
                  threads=threads)
    c.prepare(progress=False)
    c.run(steps, progress=False)
    s = pl.from_arrow(c.tables()["series"])
    assert isinstance(s, pl.DataFrame)
    s.filter(pl.col("t") > c.shear_start_time).write_parquet(path)
    return path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=32)
    ap.add_argument("--N", type=int, default=500)
    ap.add_argument("--tau", type=float, default=0.45)
    ap.add_argument("--steps", type=int, default=300_000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--reanalyse", action="store_true")
    a = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    paths = [OUT / f"N{a.N}_tau{a.tau:g}_steps{a.steps}_seed{s}.parquet"
             for s in range(1, a.seeds + 1)]
    t0 = time.perf_counter()
    if not a.reanalyse:
        from granflow.study import map_tasks

        todo = [(s, a.N, a.tau, a.steps, str(p))
                for s, p in zip(range(1, a.seeds + 1), paths, strict=True) if not p.exists()]
        for _ in map_tasks(run_seed, todo, workers=a.workers):
            pass
    from granflow.analysis.coverage import seed_spread, steady_rows
    from granflow.analysis.rheology import collect_runs

    runs = collect_runs([({}, pl.read_parquet(p)) for p in paths if p.exists()],
                        columns=list(SHOWN))
    d = seed_spread(steady_rows(runs), SHOWN)
    pl.Config.set_tbl_cols(10)
    print(f"N = {a.N}, mu = 0.3, tau/p = {a.tau}, {a.steps} steps after the compaction, "
          f"{time.perf_counter() - t0:.0f} s")
    print(d)
    ok = True
    for r in d.iter_rows(named=True):
        if r["observable"] in CHECKED:
            good = BAND[0] <= r["ratio"] <= BAND[1]
            ok &= good
            print(f"{'PASS' if good else 'FAIL'}: {r['observable']} spread/SE = "
                  f"{r['ratio']:.2f} (band {BAND[0]}-{BAND[1]})")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
