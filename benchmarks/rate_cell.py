"""The rate-controlled cell (granflow.scenes.RateCell): how long its slow flows take to become
stationary, and whether it gives the stress-controlled cell's rheology at the same I.

    python benchmarks/rate_cell.py settling [--I 1e-2 1e-3 1e-4] [--strain 10 5 2] [--N 500]
    python benchmarks/rate_cell.py equivalence [--seeds 1 2 3] [--length 10000]
    ... [--out benchmarks/out/rate_cell] [--only-table]

settling: one run per I (mu_s = 0.3, p_ext = 1e-4 kn/a, normal "yy", seed 1) for the given
shear strain after the switch; per run the cell's steady start (MSER,
``rheology.cell_steady_start``) in strain and t_c, the thirds test over what follows
(``analysis.stats.stationarity``), and the steady means with their SEs.

equivalence: the 002 campaign's stress-controlled points (docs/data/reproduce_002) at mu_s = 0
(tau/p = 0.25, 0.35) and 0.3 (0.4, 0.5), against the rate-controlled cell (normal "pressure",
the stress cell's mean pressure held; N = 2000) at each point's replica-mean I, same seeds, a
steady part of ``--length`` t_c. Replica means (``analysis.replicas.replica_mean``) of mu1,
phi, mu2; the difference's SE combines both SEs and the stress point's SE of I carried through
the local slope d(X)/dI of the stress points (finite difference of the neighbours).

Every run's series is kept in OUT (resumable: a series present is not run again).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import polars as pl

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "rate_cell"
P_EXT = 1e-4
#: the stress-controlled points matched: (mu_s, tau/p)
EQUIV_POINTS = ((0.0, 0.25), (0.0, 0.35), (0.3, 0.4), (0.3, 0.5))
COMPARED = ("mu1", "phi", "mu2")
SHOWN = {"settling": ("I_set", "state", "strain_total", "start_strain", "start_tc", "steady_tc",
                      "drift_z", "I", "I_se", "phi", "phi_se", "phi_tau_tc", "mu1", "mu1_se",
                      "mu2", "mu2_se", "wall_s"),
         "equivalence": ("mu_s", "tau_ratio", "I_stress", "I_rate", "quantity", "stress",
                         "stress_se", "rate", "rate_se", "runs", "diff", "se", "z", "verdict")}


@dataclass(frozen=True)
class CellRun:
    """One rate-cell run of this benchmark (the engine's point; ``key``: its series file's
    stem, the name of its work directory)."""

    stem: str
    N: int
    mu: float
    I: float  # noqa: E741
    normal: str
    seed: int
    strain: float | None
    length_tc: float | None
    sample_every: int
    stint: int

    @property
    def key(self) -> str:
        return self.stem


def _sheared_steps(c: Any, run: CellRun) -> tuple[int, int]:
    """(steps of the whole sheared part, steps done): ``strain`` after the switch, or
    ``length_tc`` t_c plus a fifth for the transient, in whole sampling intervals."""
    dt = c.timestep
    span = (run.strain / c.shear_rate if run.strain is not None
            else 1.2 * float(run.length_tc) * c.t_c)
    steps = int(math.ceil(span / dt / run.sample_every)) * run.sample_every
    return steps, round((c.core.time - c.shear_start_time) / dt)


def _study() -> Any:
    """The engine's study of one rate-cell run (granflow.studies._campaign.engine): it runs
    the sheared part in stints, each ending with a checkpoint and the series so far, and
    stops when the budget of :func:`_sheared_steps` is spent."""
    from granflow.scenes import RateCell
    from granflow.studies._campaign.engine import Study

    class RateCellRuns(Study):
        def scene(self, point: CellRun, plan: Any, threads: int) -> Any:
            return RateCell(N=point.N, mu=point.mu, p_ext=P_EXT, inertial_number=point.I,
                            normal=point.normal, seed=point.seed,
                            sample_every=point.sample_every, threads=threads)

        def next_steps(self, scene: Any, point: CellRun, plan: Any) -> int:
            steps, done = _sheared_steps(scene, point)
            return min(point.stint, max(steps - done, 0))

        def context(self, scene: Any) -> dict[str, Any]:
            return {"t_c": scene.t_c, "shear_start": scene.shear_start_time,
                    "shear_rate_set": scene.shear_rate}

        def progress(self, scene: Any, prep_seconds: float) -> dict[str, Any]:
            return {"strain": (scene.core.time - scene.shear_start_time) * scene.shear_rate}

        def row(self, point: CellRun, plan: Any, tables: Mapping[str, Any],
                context: Mapping[str, Any]) -> dict[str, Any]:
            return {"state": "running", **context}

        def stop(self, row: Mapping[str, Any], point: CellRun, plan: Any,
                 history: Sequence[str]) -> str | None:
            print(f"  {point.stem}: strain {row['strain']:.3f}", flush=True)
            return None  # (to the end of the budget: next_steps gives 0)

    return RateCellRuns()


def run_cell(path: Path, *, N: int, mu: float, I: float, normal: str, seed: int,  # noqa: E741
             strain: float | None = None, length_tc: float | None = None,
             sample_every: int = 200, stint: int = 2_000_000) -> pl.DataFrame:
    """Run (or read) one rate cell: ``strain`` after the switch, or ``length_tc`` t_c plus
    a fifth for the transient; the sheared part of its series (with t_c in the metadata).
    Runs in stints of ``stint`` steps (the campaign engine's
    :func:`~granflow.studies._campaign.engine.run_point`), each ending with a checkpoint and
    the series so far in ``<path's folder>/work/<path's stem>/``: a stopped run goes on from
    there (the slow flows take hours)."""
    if path.exists():
        return pl.read_parquet(path)
    from granflow.studies._campaign.engine import run_point

    run = CellRun(path.stem, N, mu, I, normal, seed, strain, length_tc, sample_every, stint)
    row = run_point(_study(), run, None, str(path.parent / "work"), threads=1)
    if "error" in row:
        raise RuntimeError(f"{path.stem}: {row['error']}")
    s = pl.read_parquet(path.parent / "work" / path.stem / "series.parquet")
    s = s.filter(pl.col("t") > row["shear_start"]).with_columns(
        t_c=pl.lit(row["t_c"]), shear_start=pl.lit(row["shear_start"]),
        wall_s=pl.lit(row["wall_seconds"]), shear_rate_set=pl.lit(row["shear_rate_set"]))
    path.parent.mkdir(parents=True, exist_ok=True)
    s.write_parquet(path)
    print(f"  {path.name}: strain {row['strain']:.3f}, {row['wall_seconds']:.0f} s", flush=True)
    return s


def analyse(s: pl.DataFrame) -> dict[str, Any]:
    """Steady start, stationarity and steady means / SEs of one run's sheared series."""
    from granflow.analysis import rheology as rh

    res = rh.analyse_run(s, columns=["I", "phi", "mu1", "mu2", "p", "sigma_yy"])
    st = res.state
    t = s["t"].to_numpy()
    t0, tc, rate = float(s["shear_start"][0]), float(s["t_c"][0]), float(s["shear_rate_set"][0])
    out: dict[str, Any] = {"state": st.state.value, "strain_total": (t[-1] - t0) * rate,
                           "start_strain": (st.t_start - t0) * rate,
                           "start_tc": (st.t_start - t0) / tc,
                           "steady_tc": (t[-1] - st.t_start) / tc,
                           "drift_z": getattr(st, "drift_z", math.nan),
                           "wall_s": float(s["wall_s"][0])}
    for r in res.stats.iter_rows(named=True):
        out[r["observable"]] = r["mean"]
        out[f"{r['observable']}_se"] = r["se"]
        out[f"{r['observable']}_tau_tc"] = r["tau"] / tc
    return out


def settling(a: argparse.Namespace) -> pl.DataFrame:
    rows = []
    for i, strain in zip(a.I, a.strain, strict=True):
        p = a.out / f"settling_N{a.N}_mu0.3_I{i:g}_strain{strain:g}.parquet"
        if not (p.exists() or not a.only_table):
            continue
        s = run_cell(p, N=a.N, mu=0.3, I=i, normal="yy", seed=1, strain=strain,
                     sample_every=a.every)
        rows.append({"I_set": i, **analyse(s)})
    return pl.DataFrame(rows)


def _stress_points() -> pl.DataFrame:
    from granflow.analysis.replicas import replica_mean

    d = pl.read_parquet(ROOT / "docs" / "data" / "reproduce_002" / "points.parquet")
    d = d.filter(pl.col("state") == "flowing")
    return replica_mean(d, ["mu_s", "tau_ratio"], ["I", *COMPARED]).sort(["mu_s", "tau_ratio"])


def equivalence(a: argparse.Namespace) -> pl.DataFrame:
    from granflow.analysis.compare import agrees
    from granflow.analysis.replicas import replica_mean

    stress = _stress_points()
    rows = []
    for mu, tau in EQUIV_POINTS:
        pt = stress.filter((pl.col("mu_s") == mu) & (pl.col("tau_ratio") == tau)).row(
            0, named=True)
        runs = []
        for seed in a.seeds:
            p = a.out / f"equiv_N2000_mu{mu:g}_tau{tau:g}_s{seed}.parquet"
            if a.only_table and not p.exists():
                continue
            s = run_cell(p, N=2000, mu=mu, I=float(pt["I"]), normal="pressure", seed=seed,
                         length_tc=a.length, sample_every=a.every)
            runs.append({"seed": seed, **analyse(s)})
        if not runs:
            continue
        rr = pl.DataFrame(runs).filter(pl.col("state") == "flowing")
        if rr.height == 0:
            continue
        rate = replica_mean(rr.with_columns(pl.lit(0).alias("k")), ["k"], ["I", *COMPARED])
        rate_row = rate.row(0, named=True)
        same_mu = stress.filter(pl.col("mu_s") == mu)
        for x in COMPARED:
            slope = _slope(same_mu, tau, x)
            se = math.sqrt(pt[f"{x}_se"] ** 2 + rate_row[f"{x}_se"] ** 2
                           + (slope * pt["I_se"]) ** 2)
            diff = rate_row[x] - pt[x]
            rows.append({"mu_s": mu, "tau_ratio": tau, "I_stress": pt["I"],
                         "I_rate": rate_row["I"], "quantity": x, "stress": pt[x],
                         "stress_se": pt[f"{x}_se"], "rate": rate_row[x],
                         "rate_se": rate_row[f"{x}_se"], "runs": rr.height,
                         "slope_dI": slope, "diff": diff, "se": se, "z": diff / se,
                         "verdict": "agrees" if agrees(diff / se) else "differs"})
    return pl.DataFrame(rows)


def _slope(points: pl.DataFrame, tau: float, x: str) -> float:
    """d(x)/dI at the point ``tau`` from its neighbours in tau (one-sided at the ends)."""
    taus = points["tau_ratio"].to_list()
    k = taus.index(tau)
    lo, hi = max(k - 1, 0), min(k + 1, len(taus) - 1)
    i, y = points["I"].to_numpy(), points[x].to_numpy()
    return float((y[hi] - y[lo]) / (i[hi] - i[lo]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part", choices=("settling", "equivalence"))
    ap.add_argument("--I", type=float, nargs="+", default=[1e-2, 1e-3, 1e-4])
    ap.add_argument("--strain", type=float, nargs="+", default=[10.0, 5.0, 2.0])
    ap.add_argument("--N", type=int, default=500)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--length", type=float, default=10_000.0, help="steady part, t_c")
    ap.add_argument("--every", type=int, default=200)
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--only-table", action="store_true")
    a = ap.parse_args(argv)
    table = settling(a) if a.part == "settling" else equivalence(a)
    shown = [c for c in SHOWN[a.part] if c in table.columns]
    with pl.Config(tbl_cols=-1, tbl_width_chars=250, tbl_rows=50, float_precision=5):
        print(table.select(shown) if table.height else table)
    if table.height:
        table.write_parquet(a.out / f"{a.part}.parquet")
    return 0


if __name__ == "__main__":
    sys.exit(main())
