"""002's cell mass read literally: does the rheology move?

    python benchmarks/omega_g_reading.py [--mu 0.3] [--tau 0.45] [--seeds 1 2 3] [--only-table]

002 prints omega_g = 2.2 sqrt(m/kn), a time; granflow reads it as the frequency 2.2 sqrt(kn/m)
(``ShearCell.omega_g_factor = 2.2``). Taken literally, the number 2.2 sqrt(m/kn) in 002's units
(kn = a = rho = 1, m the mean particle's mass) is the frequency, i.e. omega_g_factor =
2.2 m/kn (~1.16: a cell mass 3.6x the default's). This runs the 002 campaign's point (N = 2000,
p_ext = 1e-4; docs/data/reproduce_002) with the literal reading, each seed for the shear steps
its committed run took, analyses it with the campaign's own row (``_campaign.cell.point_row``)
and compares the replica means of I, phi, mu1, mu2 with the committed ones (difference over
the combined SE). Series are kept in benchmarks/out/omega_g_reading/ (resumable).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import polars as pl

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "out" / "omega_g_reading"
COMPARED = ("I", "phi", "mu1", "mu2")


def literal_factor(cell: object) -> float:
    """omega_g_factor for omega_g = 2.2 sqrt(m/kn) read as a frequency: 2.2 m/kn (m: the size
    distribution's mean mass)."""
    mat = cell.mat  # type: ignore[attr-defined]
    return 2.2 * float(mat.mean_mass()) / float(mat.kn_value)


def run(path: Path, mu: float, tau: float, seed: int,
        shear_steps: int) -> tuple[pl.DataFrame, float]:
    """The literal-reading run of one seed (or its kept series) and its shear start."""
    if path.exists():
        s = pl.read_parquet(path)
        return s, float(s["shear_start"][0])
    from granflow.scenes import ShearCell

    probe = ShearCell(N=2000, mu=mu, p_ext=1e-4, tau_ratio=tau, seed=seed)
    c = ShearCell(N=2000, mu=mu, p_ext=1e-4, tau_ratio=tau, seed=seed,
                  omega_g_factor=literal_factor(probe), threads=1)
    t0 = time.perf_counter()
    c.prepare(progress=False)
    c.run(shear_steps, progress=False)
    s = pl.from_arrow(c.tables()["series"])
    assert isinstance(s, pl.DataFrame)
    s = s.with_columns(shear_start=pl.lit(c.shear_start_time),
                       omega_g_factor=pl.lit(c.omega_g_factor))
    path.parent.mkdir(parents=True, exist_ok=True)
    s.write_parquet(path)
    print(f"  seed {seed}: omega_g_factor {c.omega_g_factor:.3f}, {shear_steps:,} steps, "
          f"{time.perf_counter() - t0:.0f} s", flush=True)
    return s, float(c.shear_start_time or 0.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mu", type=float, default=0.3)
    ap.add_argument("--tau", type=float, default=0.45)
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--only-table", action="store_true")
    a = ap.parse_args(argv)
    from granflow.analysis.compare import difference_z
    from granflow.analysis.replicas import replica_mean
    from granflow.studies._campaign.cell import Point, point_row
    from granflow.studies.reproduce_002 import full_plan

    plan = full_plan()
    committed = pl.read_parquet(ROOT / "docs" / "data" / "reproduce_002" / "points.parquet")
    base = committed.filter((pl.col("mu_s") == a.mu) & (pl.col("tau_ratio") == a.tau)
                            & (pl.col("N") == 2000) & pl.col("seed").is_in(a.seeds))
    rows = []
    for r in base.iter_rows(named=True):
        p = a.out / f"mu{a.mu:g}_tau{a.tau:g}_s{r['seed']}.parquet"
        if a.only_table and not p.exists():
            continue
        s, shear0 = run(p, a.mu, a.tau, r["seed"], int(r["shear_steps"]))
        row = point_row(Point(a.mu, a.tau, r["seed"]), plan,
                        s.drop(["shear_start", "omega_g_factor"]).to_arrow(), shear0)
        row.pop("se_rows")
        rows.append(row)
    if not rows:
        return 0
    lit = pl.from_dicts(rows, infer_schema_length=None)
    steady = ("flowing",)
    lit_m = replica_mean(lit.filter(pl.col("state").is_in(steady)), ["mu_s"], COMPARED)
    base_m = replica_mean(base.filter(pl.col("state").is_in(steady)), ["mu_s"], COMPARED)
    out = []
    for x in COMPARED:
        lv, bv = lit_m.row(0, named=True), base_m.row(0, named=True)
        diff, _, z = difference_z(lv[x], lv[f"{x}_se"], bv[x], bv[f"{x}_se"])
        out.append({"quantity": x, "printed_literal": lv[x], "literal_se": lv[f"{x}_se"],
                    "project_reading": bv[x], "reading_se": bv[f"{x}_se"],
                    "diff": diff, "z": z,
                    "replicas": f"{lit_m['replicas'][0]} / {base_m['replicas'][0]}"})
    print(f"mu_s = {a.mu:g}, tau/p = {a.tau:g}, N = 2000, p_ext = 1e-4; states (literal): "
          + ", ".join(lit["state"].to_list()))
    with pl.Config(tbl_cols=-1, tbl_width_chars=200, float_precision=5):
        print(pl.DataFrame(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
