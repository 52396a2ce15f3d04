"""Parquet datasets with metadata, snapshots for viewers."""

import xml.etree.ElementTree as ET

import granflow as gf
import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.dataset as ds
from granflow import io


def test_parquet_metadata_and_hive_dataset(tmp_path):
    for mu in (0.1, 0.5):
        for seed in (1, 2):
            t = pa.table({"x": np.arange(3.0), "u_y": np.full(3, mu)})
            d = io.hive_dir(tmp_path, {"mu": mu, "seed": seed})
            io.write_parquet(t, d / "bins.parquet", params={"mu": mu}, seed=seed)
    files = sorted(tmp_path.rglob("*.parquet"))
    assert len(files) == 4 and not list(tmp_path.rglob("*.tmp"))
    assert io.read_params(files[0])["mu"] in (0.1, 0.5)
    dset = ds.dataset(tmp_path, format="parquet", partitioning="hive")
    tab = dset.to_table()
    assert tab.num_rows == 12 and set(tab.column_names) >= {"x", "u_y", "mu", "seed"}
    df = pl.scan_parquet(str(tmp_path / "**/*.parquet"), hive_partitioning=True).collect()
    assert df.height == 12
    assert (df.filter(pl.col("mu") == 0.5)["u_y"] == 0.5).all()


def test_snapshots(tmp_path, gas, make_sim):
    box, x, d, v = gas
    s = make_sim(box, x, d, v)
    s.run(10)
    p = io.snapshot(s, tmp_path / "snap.xyz")
    lines = p.read_text().splitlines()
    assert int(lines[0]) == s.n and 'Lattice="8 0 0 0 8 0 0 0 8"' in lines[1]
    row = np.array(lines[2].split()[1:], float)
    assert row.shape == (13,)
    np.testing.assert_allclose(row[:3], s.get_positions()[0], rtol=1e-9)
    q = io.snapshot(s, tmp_path / "snap.vtp")
    root = ET.parse(q).getroot()
    piece = root.find("PolyData/Piece")
    assert int(piece.get("NumberOfPoints")) == s.n
    names = {a.get("Name") for a in root.iter("DataArray")}
    assert {"diameter", "velocity", "omega", "force", "Points"} <= names
    diam = np.array(root.find("PolyData/Piece/PointData/DataArray").text.split(), float)
    np.testing.assert_allclose(diam, d)
    try:
        io.snapshot(s, tmp_path / "snap.png")
    except gf.ParameterError as e:
        assert "xyz" in str(e)
    else:
        raise AssertionError("bad format accepted")


def test_lammps_data_roundtrip(tmp_path, gas):
    box, x, d, v = gas
    w = np.random.default_rng(1).normal(size=x.shape)
    p = io.write_lammps_data(tmp_path / "in.data", x, d, 1.0, (0, 0, 0), box.length, v, w)
    r = io.read_lammps_data(p)
    np.testing.assert_array_equal(r["x"], x)
    np.testing.assert_array_equal(r["diameter"], d)
    np.testing.assert_array_equal(r["v"], v)
    np.testing.assert_array_equal(r["omega"], w)
    assert r["hi"] == tuple(box.length)
    sim = io.simulation_from_lammps(p, gf.ContactLaw(kn=1e5))
    np.testing.assert_array_equal(sim.get_velocities(), v)
    # image flags unwrap, ids are sorted
    (tmp_path / "img.data").write_text(
        "x\n\n2 atoms\n1 atom types\n0 10 xlo xhi\n0 10 ylo yhi\n0 10 zlo zhi\n\n"
        "Atoms # sphere\n\n2 1 1.0 1.0 1 1 1 1 0 0\n1 1 1.0 1.0 5 5 5 0 0 0\n"
    )
    r = io.read_lammps_data(tmp_path / "img.data")
    assert r["ids"].tolist() == [1, 2] and r["x"][1, 0] == 11.0
    (tmp_path / "bad.data").write_text("x\n\n1 atoms\n\nAtoms # atomic\n\n1 1 0 0 0\n")
    try:
        io.read_lammps_data(tmp_path / "bad.data")
    except gf.GranflowIOError as e:
        assert "sphere" in str(e)
    else:
        raise AssertionError("atomic style accepted")
