"""The 000 report's section on the plug's order: is the unsheared centre, packed
above 000's ~0.63 in narrow channels, a crystal against the flat walls or a dense amorphous
packing? From each steady run's last state (the campaign's ``order.parquet``,
granflow.studies.reproduce_000.order_rows: Steinhardt Q6 and the ten Wolde crystal-like
fraction per bin, granflow.analysis.order), over the bins of the run's plug and its wall bin
(the half profiles' zones), beside the plug's phi."""

from __future__ import annotations

from collections.abc import Sequence

import polars as pl

from granflow.analysis.order import CUTOFF

from ._campaign import md_table, pm

#: crystal-like fraction above which a region counts as ordered (a crystal nucleus spans a
#: few percent of a random packing's spheres at most: granflow.analysis.order's tests)
ORDERED = 0.05


def run_order(order: pl.DataFrame, profiles: pl.DataFrame, by: Sequence[str]
              ) -> pl.DataFrame:
    """Per run of ``order`` (its last state's bins across the channel) and zone ("plug" and
    "wall", by the run's half profile in ``profiles``, both halves of the channel): Q6
    averaged over the zone's bond ends, and the crystal-like fraction and coordination Z
    over its spheres; ``Q6_random``, 1/sqrt(bond ends), what a random packing of as many bonds
    gives. A run: a point's fields ``by`` and its seed. Empty where either table is."""
    if not order.height or not profiles.height:
        return pl.DataFrame()
    run = [*by, "seed"]
    # (a bin of the whole width sits at xi = min(x, W - x) of the half profile's bins)
    o = order.with_columns(pl.col("xi").round(6).alias("_xi"))
    z = profiles.select(*run, pl.col("xi").round(6).alias("_xi"), "zone")
    d = o.join(z, on=[*run, "_xi"], how="inner").filter(pl.col("zone").is_in(["plug", "wall"]))
    return d.group_by([*run, "zone"], maintain_order=True).agg(
        ((pl.col("Q6") * pl.col("bonds")).sum() / pl.col("bonds").sum()).alias("Q6"),
        ((pl.col("crystal_fraction") * pl.col("particles")).sum()
         / pl.col("particles").sum()).alias("crystal_fraction"),
        (pl.col("bonds").sum() / pl.col("particles").sum()).alias("Z"),
        pl.col("particles").sum().alias("spheres"),
        (1.0 / pl.col("bonds").sum().sqrt()).alias("Q6_random"),
        pl.col("t").first().alias("t")).sort([*run, "zone"])


def order_table(runs: pl.DataFrame, values: pl.DataFrame, by: Sequence[str]) -> pl.DataFrame:
    """Per point: the plug's and the wall bin's Q6 and crystal-like fraction over its
    replicas (mean, and the range where there are several) beside the point's φ plug
    (``values``: the replica means of the report; a point: its fields ``by``)."""
    if not runs.height:
        return pl.DataFrame()
    wide = runs.pivot(on="zone", index=[*by, "seed"],
                      values=["Q6", "Q6_random", "crystal_fraction"])
    rows = []
    for key, g in wide.group_by(list(by), maintain_order=True):
        row = dict(zip(by, key, strict=True))
        out = {"W": row["W"], "φ̄": row["phi_bar"], "replicas": g.height}
        for col, label in (("Q6_plug", "Q6 plug"), ("Q6_random_plug", "random Q6 plug"),
                           ("crystal_fraction_plug", "crystal plug"),
                           ("Q6_wall", "Q6 wall bin"),
                           ("crystal_fraction_wall", "crystal wall bin")):
            x = (g[col].drop_nulls() if col in g.columns else pl.Series([], dtype=pl.Float64)
                 ).to_numpy()
            out[label] = (f"{x.mean():.3f}" + (f" ({x.min():.3f}-{x.max():.3f})"
                                               if x.size > 1 else "")) if x.size else "-"
        v = values.filter(*(pl.col(c) == row[c] for c in by))
        # (pm: "-" where the point's plug has no value, as where its blocks are too few)
        out["φ plug"] = (pm(v["phi_plug"][0], v["phi_plug_se"][0], 4)
                         if v.height and v["phi_plug"][0] is not None else "-")
        rows.append(out)
    return pl.DataFrame(rows).sort("W", "φ̄")


def order_lines(order: pl.DataFrame, profiles: pl.DataFrame, values: pl.DataFrame,
                by: Sequence[str]) -> list[str]:
    """The section's lines (a point: its fields ``by``); none where no steady run has its
    order measured."""
    runs = run_order(order, profiles, by)
    if not runs.height:
        return []
    tab = order_table(runs, values, by)
    plug = runs.filter(pl.col("zone") == "plug")
    ordered = plug.filter(pl.col("crystal_fraction") > ORDERED)
    lines = ["### The plug's order", "",
             "Is the plug a crystal grown against the flat walls, or a dense amorphous "
             "packing? Bond-orientational order of each steady run's last state "
             "(`order.parquet`: Steinhardt Q6 and the ten Wolde crystal-like fraction per bin, "
             f"granflow.analysis.order; bonds within {CUTOFF:g} mean diameters): Q6 averaged "
             "over the "
             "plug's bond ends (both halves), and the fraction of its spheres that are "
             "crystal-like, beside the wall bin (layered against the wall) and the plug's φ. "
             "For reference, an fcc crystal of one orientation has Q6 = 0.5745 and a "
             "crystal-like fraction of 1 (any orientation); a random packing Q6 ~ "
             "1/√(bond ends) (the column 'random Q6') and a fraction near 0. Replicas: mean "
             "(range); φ plug: the replica mean and its SE.", "",
             md_table(tab), ""]
    if plug.height:
        q6, xtal = plug["Q6"].to_numpy(), plug["crystal_fraction"].to_numpy()
        rnd = plug["Q6_random"].to_numpy()
        verdict = (f"**The plug is amorphous in every run**: at most {xtal.max():.1%} of its "
                   f"spheres are crystal-like. Its Q6, {q6.min():.3f}-{q6.max():.3f}, is "
                   f"{(q6 / rnd).min():.1f}-{(q6 / rnd).max():.1f} times a random packing's: "
                   "some orientation held in common, weaker than the layered wall bin's, and no "
                   "crystal. So its φ "
                   "above 000's ~0.63 is not crystallisation against the walls: what is left "
                   "is mass conservation (dilated wall zones squeeze the plug) or the "
                   "preparation (the plug is never sheared once formed: φ plug's SE between "
                   "replicas against its SE within runs, above, tells how much the rain leaves "
                   "behind)."
                   if not ordered.height else
                   f"**{ordered.height} of {plug.height} runs have an ordered plug** (more "
                   f"than {ORDERED:.0%} of its spheres crystal-like): "
                   + "; ".join(f"W = {r['W']:g}, φ̄ = {r['phi_bar']:g}, seed {r['seed']}: "
                               f"{r['crystal_fraction']:.1%}"
                               for r in ordered.iter_rows(named=True)) + ".")
        lines += [verdict, ""]
    return lines
