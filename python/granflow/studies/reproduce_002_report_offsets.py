"""The 002 report's section that decides the offsets from 002's laws: for each friction with
002's complete laws and each of mu1, phi, mu2, the offset at our own I per pressure against
the largest difference this code (granflow against LAMMPS, same protocol and states) and the
protocol (stress- against rate-controlled cell) leave room for; what neither explains is
002's set-up."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import polars as pl

from granflow.analysis.compare import AGREE_SIGMA

from ._campaign import md_table

#: 002's quantities whose offsets are decided, in the report's order
DECIDED = ("mu1", "phi", "mu2")
#: the column of the offset's least magnitude less its errors over the pressures
LEAST = f"least |offset| - {AGREE_SIGMA:g} SE"


def _lammps_rows(t: pl.DataFrame, q: str) -> pl.DataFrame:
    """The rows of granflow-against-LAMMPS tables (benchmarks/lammps_rate_cell.py; ``table``
    tells one pressure's from another's) that check 002's quantity ``q``, as mu_s, I, diff,
    se. LAMMPS's table has mu = |sigma_xy| /
    sigma_yy, not mu1 = tau/p: they differ by the factor sigma_yy/p = 1 - (N1 - N2)/(3p),
    which both codes share within the N rows, so a code difference in mu1 is one in mu to
    first order. mu2 = (N1 + 2 N2)/(2p) (the projection on D^2's deviator in simple shear,
    src/sampling/cell_obs.rs's shear_input); N1 and N2 come from the same runs with an
    unknown correlation, so its SE is the bound se(N1)/2 + se(N2), not a quadrature sum."""
    if q in ("mu1", "phi"):
        return (t.filter(pl.col("quantity") == ("mu" if q == "mu1" else "phi"))
                .select("mu_s", "I", "diff", pl.col("diff_se").alias("se")))
    n = t.filter(pl.col("quantity").is_in(["N1_p", "N2_p"])).pivot(
        on="quantity", index=["table", "mu_s", "I"], values=["diff", "diff_se"])
    if not n.height:
        return pl.DataFrame(schema={"mu_s": pl.Float64, "I": pl.Float64, "diff": pl.Float64,
                                    "se": pl.Float64})
    return n.select("mu_s", "I",
                    (pl.col("diff_N1_p") / 2 + pl.col("diff_N2_p")).alias("diff"),
                    (pl.col("diff_se_N1_p") / 2 + pl.col("diff_se_N2_p")).alias("se"))


def _room(rows: pl.DataFrame) -> tuple[float, int]:
    """The largest |difference| + AGREE_SIGMA SE over ``rows`` (what a comparison that agrees
    within its errors still allows) and the number of rows; (nan, 0) without rows."""
    if not rows.height:
        return float("nan"), 0
    room = rows["diff"].abs() + AGREE_SIGMA * rows["se"]
    return float(room.max()), rows.height


def decided_table(off: pl.DataFrame, lammps: Sequence[pl.DataFrame],
                  equivalence: pl.DataFrame | None) -> pl.DataFrame:
    """Per mu_s of ``off`` (:func:`reproduce_002_report.offsets`) and quantity of DECIDED:
    the offset from 002's law at each pressure, the room this code leaves (the LAMMPS tables
    ``lammps``, every pressure pooled) and the protocol (``equivalence``), and the decision.
    An offset is 002's set-up where at every pressure its magnitude less AGREE_SIGMA SEs
    exceeds the sum of both rooms; 'not decided' where a room is unmeasured or that margin
    is not met."""
    rows: list[dict[str, Any]] = []
    code_all = (pl.concat([t.with_columns(pl.lit(k).alias("table"))
                           for k, t in enumerate(lammps)], how="vertical_relaxed")
                if lammps else None)
    for mu in sorted(set(off["mu_s"].to_list())):
        g = off.filter(pl.col("mu_s") == mu).sort("p_ext", descending=True)
        for q in DECIDED:
            v, e = g[f"{q} - paper"].to_numpy(), g[f"{q} - paper SE"].to_numpy()
            code, n_code = (_room(_lammps_rows(code_all, q).filter(pl.col("mu_s") == mu))
                            if code_all is not None else (float("nan"), 0))
            proto, n_proto = (_room(equivalence.filter((pl.col("mu_s") == mu)
                                                       & (pl.col("quantity") == q))
                                    .select("diff", "se"))
                              if equivalence is not None else (float("nan"), 0))
            least = float(np.min(np.abs(v) - AGREE_SIGMA * e))
            room = code + proto
            signs = set(np.sign(v).tolist())
            if not (np.isfinite(room) and n_code and n_proto):
                decision = "not decided (a check is missing)"
            elif least > room and len(signs) == 1:
                decision = f"002's set-up ({least / room:.1f}x the room)"
            else:
                decision = "not decided (within the room)"
            rows.append({
                "mu_s": mu, "quantity": q,
                "offset from 002 (by p_ext)": ", ".join(
                    f"{a:+.4f} ± {s:.4f} ({p:.0e})"
                    for a, s, p in zip(v, e, g["p_ext"], strict=True)),
                LEAST: least,
                "this code: room (rows)": f"{code:.4f} ({n_code})",
                "protocol: room (rows)": f"{proto:.4f} ({n_proto})",
                "decided": decision})
    return pl.DataFrame(rows)


def decided_lines(off: pl.DataFrame, lammps: Sequence[pl.DataFrame],
                  equivalence: pl.DataFrame | None) -> list[str]:
    """The section's report lines (empty without offsets or without either check)."""
    if not off.height or not (lammps or equivalence is not None):
        return []
    t = decided_table(off, lammps, equivalence)
    n_set = int(t["decided"].str.starts_with("002's set-up").sum())
    return [
        "## The offsets, decided", "",
        "Each offset of our points from 002's law at our own I (the table 'Against the "
        "paper's curves at our I', per pressure) against the room the checks above leave: "
        f"'this code' is the largest |granflow - LAMMPS| + {AGREE_SIGMA:g} combined SEs over "
        "the LAMMPS rows of that mu_s at every pressure (mu for mu1: |sigma_xy|/sigma_yy and "
        "tau/p differ by a factor both codes share; mu2 from N1/p + 2 N2/p over 2, its SE "
        "bounded as if N1 and N2 were fully correlated), 'protocol' the same over the stress- "
        "against rate-controlled rows (p_ext = 1e-4). The offset is 002's set-up where at "
        f"every pressure it keeps one sign and |offset| - {AGREE_SIGMA:g} SE exceeds both "
        "rooms together; the checks cover I = 0.005-0.165, the offsets the fitted points "
        "(I up to 0.5). 'Set-up' is all that differs between 002's runs and ours beyond the "
        "contact law and protocol checked here (its preparation, run lengths, averaging, the "
        "printed constants' rounding): this campaign does not separate those.", "",
        f"**{n_set} of {t.height} offsets are 002's set-up** by this rule.", "",
        md_table(t, {"mu_s": "g", LEAST: ".4f"}), ""]
