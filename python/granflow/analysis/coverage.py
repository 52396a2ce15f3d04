"""The coverage audit of a campaign: do its runs' SEs hold across seeds?

For every pair of replicas (runs of one point with different seeds, both in a steady state)
and every reported quantity, z = (x_a - x_b) / sqrt(se_a^2 + se_b^2) is standard normal when
the SEs are honest; the audit is the root mean square of z over the pairs, 1 for honest SEs,
with its 95 % interval from the chi-squared distribution with nu = sum over points of
(replicas - 1) degrees of freedom (the independent contrasts: 3 replicas give 3 pairs but 2
degrees of freedom). Few pairs make it wide.

    python -m granflow.analysis.coverage docs/data/reproduce_002 [--by mu_s,N,p_ext,tau_ratio]
           [--observables I,phi,mu1,mu2]

reads ``points.parquet`` of a campaign dataset (the point's fields from its metadata, written
by the campaign engine, or ``--by``) and prints the table. With many seeds of one point
(benchmarks/seed_coverage.py, granflow.studies.seed_coverage) the same question is
:func:`seed_spread`: the seeds' spread over their root-mean-square SE.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import polars as pl
from scipy import stats

from granflow.states import FlowState

from .tables import TableLike, to_polars

__all__ = ["POINT_FIELDS_KEY", "coverage", "main", "pair_z", "point_fields", "seed_spread",
           "steady_rows"]

#: the Parquet metadata key under which the campaign engine lists a point's fields
POINT_FIELDS_KEY = b"granflow.point"
#: the quantities audited by default (those the 002 campaign reports)
DEFAULT_OBSERVABLES = ("I", "phi", "mu1", "mu2")


def steady_rows(points: TableLike, state: str = "state") -> pl.DataFrame:
    """The rows whose ``state`` is a steady one (:attr:`FlowState.is_steady`): the replicas
    that count."""
    d = to_polars(points)
    ok = [s for s in d[state].unique().to_list()
          if s in FlowState._value2member_map_ and FlowState(s).is_steady]
    return d.filter(pl.col(state).is_in(ok))


def pair_z(points: TableLike, by: Sequence[str], observables: Sequence[str],
           seed: str = "seed") -> pl.DataFrame:
    """One row per pair of replicas of a point (groups of ``by``): the point, ``seed_a``,
    ``seed_b`` and ``z_X`` for each observable ``X`` (NaN where an SE is missing)."""
    d = to_polars(points)
    rows = []
    for key, g in d.sort(seed).group_by(list(by), maintain_order=True):
        recs = list(g.iter_rows(named=True))
        for a, b in itertools.combinations(recs, 2):
            row: dict[str, object] = dict(zip(by, key, strict=True))
            row["seed_a"], row["seed_b"] = a[seed], b[seed]
            for o in observables:
                va, vb = a.get(o), b.get(o)
                sa, sb = a.get(f"{o}_se"), b.get(f"{o}_se")
                ok = all(v is not None and math.isfinite(v) for v in (va, vb, sa, sb))
                den = math.sqrt(sa**2 + sb**2) if ok else math.nan  # type: ignore[operator]
                row[f"z_{o}"] = (va - vb) / den if ok and den > 0 else math.nan  # type: ignore[operator]
            rows.append(row)
    return pl.from_dicts(rows, infer_schema_length=None) if rows else pl.DataFrame()


def coverage(points: TableLike, by: Sequence[str],
             observables: Sequence[str] = DEFAULT_OBSERVABLES, seed: str = "seed",
             level: float = 0.95) -> pl.DataFrame:
    """The audit (module docstring) over the replicas of ``points`` that count (pass only
    those: :func:`steady_rows`). One row per observable: ``points`` (with at least two
    replicas), ``pairs``, ``dof``, ``rms_z``, its ``level`` interval ``rms_z_lo`` /
    ``rms_z_hi``, and the worst pair (``max_abs_z`` and its point, ``worst``, named by the
    fields of ``by`` that differ between points)."""
    pz = pair_z(points, by, observables, seed)
    # the worst pair is named by the fields that tell points apart (a field every point shares,
    # such as a stress campaign's inertial_number 0, says nothing)
    named = [k for k in by if pz.height and pz[k].n_unique() > 1] or list(by)
    rows = []
    for o in observables:
        z = pz[f"z_{o}"].to_numpy() if pz.height else np.zeros(0)
        ok = np.isfinite(z)
        used = pz.filter(pl.Series(ok)) if pz.height else pz
        # the degrees of freedom: per point, the replicas in its finite pairs less one
        dof = 0
        if used.height:
            for _, g in used.group_by(list(by)):
                dof += len(set(g["seed_a"].to_list()) | set(g["seed_b"].to_list())) - 1
        zz = z[ok]
        rms = float(np.sqrt(np.mean(zz**2))) if zz.size else math.nan
        lo = hi = math.nan
        if dof > 0:
            a = (1.0 - level) / 2.0
            lo = rms * math.sqrt(dof / stats.chi2.ppf(1.0 - a, dof))
            hi = rms * math.sqrt(dof / stats.chi2.ppf(a, dof))
        worst = ""
        mx = math.nan
        if zz.size:
            j = int(np.argmax(np.abs(zz)))
            r = used.row(j, named=True)
            mx = float(abs(zz[j]))
            worst = ", ".join(f"{k} {r[k]:g}" if isinstance(r[k], float) else f"{k} {r[k]}"
                              for k in named) + f" (seeds {r['seed_a']}, {r['seed_b']})"
        rows.append({"observable": o, "points": used.select(by).unique().height
                     if used.height else 0, "pairs": int(zz.size), "dof": dof,
                     "rms_z": rms, "rms_z_lo": lo, "rms_z_hi": hi, "max_abs_z": mx,
                     "worst": worst})
    return pl.DataFrame(rows)


def seed_spread(runs: TableLike, observables: Sequence[str] = DEFAULT_OBSERVABLES
                ) -> pl.DataFrame:
    """The many-seed form of the audit: ``runs`` are seeds of one point (rows with ``X`` and
    ``X_se``; pass the steady ones, :func:`steady_rows`). Per observable: ``seeds``, ``mean``,
    ``spread`` (standard deviation of the seeds' means), ``rms_se`` (root mean square of their
    SEs), ``ratio`` = spread / rms_se (1 for honest SEs) and its 95 % band for K seeds,
    1 +- 1.96 / sqrt(2 (K - 1)) (``band_lo``, ``band_hi``), with ``within`` it."""
    d = to_polars(runs)
    k = d.height
    half = 1.96 / math.sqrt(2 * (k - 1)) if k > 1 else math.nan
    rows = []
    for o in observables:
        x = d[o].cast(pl.Float64).to_numpy()
        se = d[f"{o}_se"].cast(pl.Float64).to_numpy()
        spread = float(x.std(ddof=1)) if k > 1 else math.nan
        rms = float(np.sqrt(np.mean(se**2))) if k else math.nan
        ratio = spread / rms if rms > 0 else math.nan
        rows.append({"observable": o, "seeds": k, "mean": float(x.mean()) if k else math.nan,
                     "spread": spread, "rms_se": rms, "ratio": ratio, "band_lo": 1 - half,
                     "band_hi": 1 + half, "within": bool(1 - half <= ratio <= 1 + half)})
    return pl.DataFrame(rows)


def point_fields(path: str | os.PathLike[str]) -> list[str] | None:
    """The point's fields of a campaign's ``points.parquet`` (from its metadata), or None."""
    import pyarrow.parquet as pq

    md = pq.read_schema(path).metadata or {}
    raw = md.get(POINT_FIELDS_KEY)
    return list(json.loads(raw)) if raw else None


def main(argv: Iterable[str] | None = None) -> pl.DataFrame:
    """The command line (module docstring); prints and returns the table."""
    ap = argparse.ArgumentParser(prog="python -m granflow.analysis.coverage",
                                 description=(__doc__ or "").splitlines()[0])
    ap.add_argument("dataset", help="campaign dataset directory (with points.parquet)")
    ap.add_argument("--by", default=None, help="the point's fields, comma-separated (default: "
                    "from the dataset's metadata, less the seed)")
    ap.add_argument("--observables", default=",".join(DEFAULT_OBSERVABLES))
    ap.add_argument("--seed", default="seed")
    a = ap.parse_args(list(argv) if argv is not None else None)
    f = Path(a.dataset) / "points.parquet"
    if not f.exists():
        ap.error(f"no points.parquet in {a.dataset}")
    by = a.by.split(",") if a.by else [c for c in (point_fields(f) or []) if c != a.seed]
    if not by:
        ap.error(f"{f} names no point fields in its metadata: give --by")
    obs = a.observables.split(",")
    tab = coverage(steady_rows(pl.read_parquet(f)), by, obs, a.seed)
    with pl.Config(tbl_rows=-1, tbl_cols=-1, fmt_str_lengths=80, tbl_width_chars=200):
        print(tab)
    return tab


if __name__ == "__main__":
    main()
