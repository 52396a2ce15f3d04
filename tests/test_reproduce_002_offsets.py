"""granflow.studies.reproduce_002_report_offsets: the offsets from 002's laws decided against
the room the LAMMPS and stress/rate checks leave, on made-up tables whose answer is known."""

from __future__ import annotations

import polars as pl
import pytest
from granflow.studies.reproduce_002_report_offsets import (
    LEAST,
    decided_lines,
    decided_table,
)


def offsets(mu1: tuple[float, float, float], se: float = 0.0003) -> pl.DataFrame:
    """002's offsets at mu_s = 0.3 at three pressures, mu1 as given, phi and mu2 small."""
    return pl.DataFrame({
        "mu_s": [0.3] * 3, "p_ext": [1e-4, 1e-5, 1e-6], "points": [5] * 3,
        "mu1 - paper": list(mu1), "mu1 - paper SE": [se] * 3,
        "mu2 - paper": [0.001] * 3, "mu2 - paper SE": [0.001] * 3,
        "phi - paper": [0.0001] * 3, "phi - paper SE": [0.0001] * 3})


def lammps(d_mu: float = 0.001, se: float = 0.001, d_n1: float = 0.004,
           d_n2: float = 0.002, se_n: float = 0.003) -> pl.DataFrame:
    """One pressure's granflow-against-LAMMPS table at mu_s = 0.3, two I's alike."""
    rows = []
    for i in (0.05, 0.15):
        for q, d, s in (("mu", d_mu, se), ("phi", 0.0002, 0.0002), ("N1_p", d_n1, se_n),
                        ("N2_p", d_n2, se_n), ("syy_pext", 0.0, 0.001)):
            rows.append({"mu_s": 0.3, "I": i, "quantity": q, "replicas_granflow": 3,
                         "replicas_lammps": 3, "granflow": 0.0, "granflow_se": s,
                         "lammps": 0.0, "lammps_se": s, "diff": d, "diff_se": s,
                         "z": d / s, "verdict": "agrees"})
    return pl.DataFrame(rows)


def equivalence(d: float = 0.0005, se: float = 0.0005) -> pl.DataFrame:
    return pl.DataFrame([{"mu_s": 0.3, "tau_ratio": 0.4, "quantity": q, "diff": d, "se": se,
                          "z": d / se, "verdict": "agrees"} for q in ("mu1", "phi", "mu2")])


def row(t: pl.DataFrame, q: str) -> dict:
    return t.filter(pl.col("quantity") == q).row(0, named=True)


def test_an_offset_beyond_both_rooms_is_the_setup_and_one_within_is_not_decided():
    t = decided_table(offsets((0.03, 0.032, 0.029)), [lammps(), lammps()], equivalence())
    mu1 = row(t, "mu1")
    # rooms: code |0.001| + 2 * 0.001 = 0.003, protocol 0.0005 + 2 * 0.0005 = 0.0015
    assert mu1["this code: room (rows)"] == "0.0030 (4)"
    assert mu1["protocol: room (rows)"] == "0.0015 (1)"
    assert mu1[LEAST] == pytest.approx(0.029 - 2 * 0.0003)
    assert mu1["decided"].startswith("002's set-up")
    assert row(t, "phi")["decided"] == "not decided (within the room)"
    small = decided_table(offsets((0.004, 0.005, 0.004)), [lammps()], equivalence())
    assert row(small, "mu1")["decided"] == "not decided (within the room)"


def test_mu2_is_checked_through_n1_plus_2_n2_with_a_correlated_se_bound():
    t = decided_table(offsets((0.03,) * 3), [lammps(d_n1=0.004, d_n2=-0.003, se_n=0.002)],
                      equivalence())
    # (0.004 + 2 (-0.003)) / 2 = -0.001; SE bound 0.002 / 2 + 0.002 = 0.003; room 0.007
    assert row(t, "mu2")["this code: room (rows)"] == "0.0070 (2)"


def test_an_offset_that_changes_sign_with_pressure_is_not_decided():
    t = decided_table(offsets((0.03, -0.03, 0.03)), [lammps()], equivalence())
    assert row(t, "mu1")["decided"] == "not decided (within the room)"


def test_a_missing_check_leaves_every_offset_undecided():
    t = decided_table(offsets((0.03,) * 3), [lammps()], None)
    assert set(t["decided"]) == {"not decided (a check is missing)"}
    assert decided_lines(offsets((0.03,) * 3), [], None) == []
    lines = decided_lines(offsets((0.03,) * 3), [lammps()], equivalence())
    assert lines[0] == "## The offsets, decided"
    assert any(s.startswith("**1 of 3 offsets are 002's set-up**") for s in lines)


def test_the_report_reads_every_pressures_lammps_table_and_the_equivalence(tmp_path):
    from granflow.studies.reproduce_002_report import check_tables

    out = tmp_path / "reproduce_002"
    out.mkdir()
    assert check_tables(out) == ([], None)
    for name in ("lammps_rate_cell", "lammps_rate_cell_p1e-6"):
        (tmp_path / name).mkdir()
        lammps().write_parquet(tmp_path / name / "table.parquet")
    (tmp_path / "rate_cell").mkdir()
    equivalence().write_parquet(tmp_path / "rate_cell" / "equivalence.parquet")
    tables, eq = check_tables(out)
    assert len(tables) == 2 and eq is not None and eq.height == 3
    t = decided_table(offsets((0.03,) * 3), tables, eq)
    assert row(t, "mu1")["this code: room (rows)"] == "0.0030 (4)"
