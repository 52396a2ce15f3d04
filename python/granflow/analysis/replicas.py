"""A campaign point's value from its independent replicas (runs with different seeds): their
mean, and an SE that holds across seeds.

Two estimates of the variance of the replicas' mean ``xbar = sum(x_i) / k``:

* within: ``sum(se_i^2) / k^2``, from each run's own (blocking) SE;
* between: ``s^2 / k``, ``s`` the replicas' standard deviation, inflated by the small-sample
  factor ``t_{k-1}(0.8413)`` (the Student quantile of a one-sigma interval with k - 1 degrees
  of freedom: 1.32 for 3 replicas, 1.84 for 2) so that xbar +- SE is a 68 % interval.

The point's SE is the larger of the two: honest run SEs make them agree (to the between
estimate's own ~50 % scatter at k = 3), and where the runs' SEs are too small (a slow mode
they do not see) the replicas' spread shows it. Both are kept beside it.

Whether the replicas agree at all: ``Q = sum_i (x_i - xw)^2 / se_i^2`` (``xw`` their
inverse-variance mean) is chi-squared with k - 1 degrees of freedom when they sample one
steady state with honest SEs; ``X_agree_p`` is its upper tail. A point whose replicas disagree
far beyond their errors (:data:`DISAGREE_P`) has no reproducible steady state at this run
length (near a runaway the flow wanders for thousands of t_c): a campaign lists it and does
not fit it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import polars as pl
from scipy import stats

from .stats.weighted import weighted_mean
from .tables import TableLike, to_polars

__all__ = ["DISAGREE_P", "MIN_REPLICAS", "mean_profiles", "replica_mean", "small_sample_factor"]

#: fewest replicas for a between-replica SE (one replica: the within SE alone)
MIN_REPLICAS = 2
#: replicas whose agreement test gives p below this disagree (a 3.3-sigma event for honest
#: SEs; with ~40 points and 4 quantities, ~0.2 false alarms per campaign)
DISAGREE_P = 1e-3


def small_sample_factor(k: int) -> float:
    """``t_{k-1}(Phi(1))``: the factor that makes ``s / sqrt(k)`` of ``k`` replicas a
    one-sigma (68.3 %) half-width; NaN for ``k < 2``."""
    if k < MIN_REPLICAS:
        return math.nan
    return float(stats.t.ppf(stats.norm.cdf(1.0), k - 1))


def replica_mean(df: TableLike, by: Sequence[str],
                 observables: Sequence[str] | None = None) -> pl.DataFrame:
    """One row per group of ``by`` (a campaign point; the caller passes only the replicas that
    count, e.g. flowing and stationary ones): ``replicas`` (k), and per observable ``X`` (a
    column ``X`` with ``X_se`` beside it; default every such pair): ``X`` the replicas' mean,
    ``X_se_within``, ``X_se_between`` (module docstring; NaN for one replica) and ``X_se`` the
    larger, and ``X_agree_p`` (the replicas' agreement test, module docstring; NaN for one
    replica). A replica without a finite ``X_se`` (too little data for its own SE) makes the
    group's ``X_se_within``, and so ``X_se``, NaN."""
    d = to_polars(df)
    obs = list(observables) if observables is not None else [
        c for c in d.columns if f"{c}_se" in d.columns and c not in by]
    groups = []
    for key, g in d.group_by(list(by), maintain_order=True):
        k = g.height
        row: dict[str, object] = dict(zip(by, key, strict=True))
        row["replicas"] = k
        fac = small_sample_factor(k)
        for o in obs:
            x = g[o].cast(pl.Float64).to_numpy()
            se = g[f"{o}_se"].cast(pl.Float64).to_numpy()
            mean = float(x.mean())
            within = (math.sqrt(float((se**2).sum())) / k
                      if all(math.isfinite(v) for v in se) else math.nan)
            between = (fac * float(x.std(ddof=1)) / math.sqrt(k) if k >= MIN_REPLICAS
                       else math.nan)
            row[o] = mean
            row[f"{o}_se"] = (max(within, between) if math.isfinite(between) else within)
            agree = math.nan
            if k >= MIN_REPLICAS and math.isfinite(within) and (se > 0).all():
                w = 1.0 / se**2
                q = float((w * (x - weighted_mean(x, se)[0]) ** 2).sum())
                agree = float(stats.chi2.sf(q, k - 1))
            row[f"{o}_agree_p"] = agree
            row[f"{o}_se_within"] = within
            row[f"{o}_se_between"] = between
        groups.append(row)
    return pl.from_dicts(groups, infer_schema_length=None).sort(list(by)) if groups \
        else pl.DataFrame()


def mean_profiles(profiles: TableLike, by: Sequence[str], at: str = "xi",
                  keep: Sequence[str] = (), labels: Sequence[str] = ()) -> pl.DataFrame:
    """Binned profiles of replicas (one row per run and bin) averaged bin by bin: one row per
    group of ``by`` (a campaign point; pass only the replicas that count) and bin ``at``, with
    every profile quantity (a column ``X`` with ``X_se`` beside it, ``by`` and ``at`` aside)
    as :func:`replica_mean` gives it. ``keep``: columns equal for every replica of a bin (its
    edges), taken from the first; ``labels``: per-bin labels (a zone), the one most replicas
    give (the first of a tie)."""
    d = to_polars(profiles)
    if not d.height:
        return d
    key = [*by, at]
    qs = [c for c in d.columns if f"{c}_se" in d.columns and c not in key]
    d = d.with_columns(*(pl.col(c).cast(pl.Float64) for c in (*qs, *(f"{q}_se" for q in qs))))
    out = replica_mean(d, key, qs)
    if keep:
        out = out.join(d.group_by(key, maintain_order=True).agg(pl.col(list(keep)).first()),
                       on=key, how="left")
    for name in labels:
        # (the most common label, first-seen order breaking a tie)
        mode = (d.group_by([*key, name], maintain_order=True).len()
                .sort("len", descending=True, maintain_order=True)
                .group_by(key, maintain_order=True).agg(pl.col(name).first()))
        out = out.join(mode, on=key, how="left")
    return out.sort(key)
