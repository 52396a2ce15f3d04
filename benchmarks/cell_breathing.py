"""mu1 and mu2 as 002 (4.1), (4.3) print them, sigma:D / (2|D|p) and 1.5 sigma:D2 / (|D|^2 p),
D2 = D^2 - tr(D^2)/3 I, against the deviatoric forms the kernel now samples, (sigma - pI):D and
D2 from D's deviatoric part (src/sampling/cell_obs.rs says why): their means and the coverage
audit of each over a cell campaign's replicas.

    python benchmarks/cell_breathing.py OUT [--rewrite]

OUT is a cell campaign's output (``points.parquet`` and its ``work/``, e.g. the 002 re-run).
Both forms come from the same series: the printed mu1 adds tr D / (2|D|) to every sample
(the barostat's breathing, tr D = d ln phi/dt), and the printed D2 carries 2 tr(D)/3 D_dev.
Each run's steady part and SEs are the campaign's own (``_campaign.cell.point_row``).

``--rewrite`` puts the deviatoric mu1, mu2, N0_tau and N1_tau (which share the projections) into the
work directories' series written by a kernel before the change (rescaled by the ratio of the
two projections, to round-off of the kernel's own values); a series already in the deviatoric
form is left alone. Then ``--reanalyse`` the campaign to refresh its tables.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
AX = "xyz"
#: the form a series' mu1 is in is read from how close it is to each (relative)
SAME = 1e-9


def projections(series: pa.Table) -> dict[str, np.ndarray]:
    """Per sample, the stress projections of mu1 and mu2, as printed and in the deviatoric
    form (sigma symmetrised, as the kernel): ``sd`` / ``sd_dev``, sigma:D and (sigma - pI):D;
    ``sd2`` / ``sd2_dev``, sigma:(D^2 - tr(D^2)/3 I) from D and from D's deviatoric part."""
    s = pl.from_arrow(series)
    n = s.height
    sig = np.stack([[s[f"sigma_{a}{b}"].to_numpy() for b in AX] for a in AX]).transpose(2, 0, 1)
    sp = 0.5 * (sig + sig.transpose(0, 2, 1))
    d = np.stack([[s[f"D_{min(a, b)}{max(a, b)}"].to_numpy() for b in AX]
                  for a in AX]).transpose(2, 0, 1)
    p = s["p"].to_numpy()
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))

    def second(m: np.ndarray) -> np.ndarray:
        mm = m @ m
        return mm - np.trace(mm, axis1=1, axis2=2)[:, None, None] / 3 * eye

    dev = d - np.trace(d, axis1=1, axis2=2)[:, None, None] / 3 * eye
    return {"sd": (sp * d).sum(axis=(1, 2)),
            "sd_dev": ((sp - p[:, None, None] * eye) * d).sum(axis=(1, 2)),
            "sd2": (sp * second(d)).sum(axis=(1, 2)),
            "sd2_dev": (sp * second(dev)).sum(axis=(1, 2))}


def form(series: pa.Table) -> str:
    """"printed" or "deviatoric": which projection the series' mu1 was sampled with."""
    s = pl.from_arrow(series)
    pr = projections(series)
    gd, p, mu1 = s["shear_rate"].to_numpy(), s["p"].to_numpy(), s["mu1"].to_numpy()
    ok = mu1 != 0.0
    scale = np.abs(mu1[ok]).max() if ok.any() else 1.0
    for name, key in (("deviatoric", "sd_dev"), ("printed", "sd")):
        if np.allclose(mu1[ok], pr[key][ok] / (2 * gd[ok] * p[ok]), rtol=0, atol=SAME * scale):
            return name
    raise ValueError("mu1 matches neither projection")


def with_form(series: pa.Table, target: str) -> pa.Table:
    """``series`` with mu1, mu2, N0_tau and N1_tau in the ``target`` projection (each the
    kernel's value rescaled by the ratio of the two projections)."""
    if form(series) == target:
        return series
    pr = projections(series)
    new, old = ("_dev", "") if target == "deviatoric" else ("", "_dev")
    r1 = pr["sd" + new] / pr["sd" + old]
    r2 = pr["sd2" + new] / pr["sd2" + old]
    out = series
    for c, f in (("mu1", r1), ("mu2", r2), ("N0_tau", r2 / r1), ("N1_tau", 1 / r1)):
        x = series.column(c).to_numpy()
        y = np.where(x != 0.0, x * f, 0.0)
        out = out.set_column(out.schema.get_field_index(c), c, pa.array(y))
    return out.replace_schema_metadata(series.schema.metadata)


def rows(out: Path, target: str) -> pl.DataFrame:
    """The campaign's rows recomputed with mu1 in the ``target`` projection."""
    from granflow.studies._campaign.cell import Point, point_row
    from granflow.studies.reproduce_002 import full_plan

    plan = full_plan()
    got = []
    for r in pl.read_parquet(out / "points.parquet").iter_rows(named=True):
        d = out / "work" / Point(r["mu_s"], r["tau_ratio"], r["seed"], r["N"], r["p_ext"]).key
        if r["state"] in ("runaway", "failed") or not (d / "meta.json").exists():
            continue
        shear0 = json.loads((d / "meta.json").read_text())["context"]["shear_start_time"]
        series = with_form(pq.read_table(d / "series.parquet"), target)
        row = point_row(Point(r["mu_s"], r["tau_ratio"], r["seed"], r["N"], r["p_ext"]),
                        plan, series, shear0)
        row.pop("se_rows")
        got.append(row)
    return pl.from_dicts(got, infer_schema_length=None)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--rewrite", action="store_true",
                    help="put the deviatoric form into the work directories' series")
    a = ap.parse_args(argv)
    from granflow.analysis.coverage import coverage, steady_rows

    if a.rewrite:
        n = 0
        for f in sorted((a.out / "work").glob("*/series.parquet")):
            tab = pq.read_table(f)
            if form(tab) == "printed":
                pq.write_table(with_form(tab, "deviatoric"), f)
                n += 1
        print(f"rewrote {n} series")
        return
    by = ["mu_s", "tau_ratio", "N", "p_ext"]
    table = []
    for target in ("printed", "deviatoric"):
        x = steady_rows(rows(a.out, target))
        for cov in coverage(x, by, ["mu1", "mu2"]).iter_rows(named=True):
            o = cov["observable"]
            table.append({"form": target, "runs": x.height, **cov,
                          "median SE": float(x[f"{o}_se"].median())})
        if target == "printed":
            base = x.select([*by, "seed", "mu1", "mu2"])
        else:
            diff = x.join(base, on=[*by, "seed"], suffix="_printed")
            for o in ("mu1", "mu2"):
                d = (diff[f"{o}_printed"] - diff[o]).to_numpy()
                print(f"{o}: printed - deviatoric over {d.size} runs: mean {d.mean():.2e}, "
                      f"SE {d.std(ddof=1) / np.sqrt(d.size):.1e}")
    with pl.Config(tbl_cols=-1, tbl_width_chars=200):
        print(pl.DataFrame(table))


if __name__ == "__main__":
    sys.exit(main())
