"""Files: Parquet result datasets (atomic, with the run's parameters in the metadata), particle
snapshots for OVITO/ParaView (extended XYZ, VTK PolyData .vtp), and LAMMPS data files.

Every file is written to a temporary name in the same directory and renamed into place, so a
file either exists complete or not at all.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from granflow._core import __version__
from granflow.errors import GranflowIOError, ParameterError


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success fsync and rename it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj


def run_metadata(params: Mapping[str, Any], seed: int | None = None) -> dict[bytes, bytes]:
    """File-level metadata: the full parameter set, granflow's version and the seed."""
    return {
        b"granflow.version": __version__.encode(),
        b"granflow.params": json.dumps(_jsonable(params), sort_keys=True).encode(),
        b"granflow.seed": str(seed).encode(),
    }


def write_parquet(
    table: pa.Table,
    path: str | os.PathLike,
    params: Mapping[str, Any] | None = None,
    seed: int | None = None,
) -> Path:
    """Write ``table`` as one Parquet file (atomically) with the run's metadata."""
    md = dict(table.schema.metadata or {})
    md.update(run_metadata(params or {}, seed))
    table = table.replace_schema_metadata(md)
    path = Path(path)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
    return path


def read_params(path: str | os.PathLike) -> dict[str, Any]:
    """The parameters stored in a Parquet file written by granflow."""
    md = pq.read_schema(path).metadata or {}
    if b"granflow.params" not in md:
        raise GranflowIOError(f"{path}: no granflow parameters in the file metadata")
    return json.loads(md[b"granflow.params"])


def hive_dir(root: str | os.PathLike, partition: Mapping[str, Any]) -> Path:
    """``root/key=value/...`` for a hive-style partitioned dataset (keys in the given order)."""
    p = Path(root)
    for k, v in partition.items():
        if not str(k).isidentifier():
            raise ParameterError(f"invalid partition key {k!r}: allowed identifiers")
        p = p / f"{k}={v}"
    return p


def write_manifest(run_dir: str | os.PathLike, manifest: Mapping[str, Any]) -> Path:
    """A small JSON manifest beside the run's files (atomic)."""
    path = Path(run_dir) / "manifest.json"
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(_jsonable(manifest), indent=1, sort_keys=True))
    return path


# -- snapshots ---------------------------------------------------------------------------
def write_xyz(
    path: str | os.PathLike,
    positions: np.ndarray,
    diameters: np.ndarray,
    velocities: np.ndarray,
    omega: np.ndarray,
    forces: np.ndarray,
    cell: np.ndarray,
    origin: np.ndarray,
    pbc: tuple[bool, bool, bool],
    time: float,
    step: int,
    append: bool = False,
) -> None:
    """Extended XYZ (OVITO, ASE): Lattice from the cell vectors, Properties with radius,
    velocity, spin and force. ``append`` adds a frame (not atomic; use one file per frame for
    crash safety)."""
    n = len(diameters)
    lat = " ".join(f"{c:.10g}" for c in np.asarray(cell).T.ravel())
    header = (
        f'Lattice="{lat}" Origin="{" ".join(f"{o:.10g}" for o in origin)}" '
        "Properties=species:S:1:pos:R:3:radius:R:1:velo:R:3:omega:R:3:force:R:3 "
        f'Time={time:.10g} Timestep={step} pbc="{" ".join("T" if p else "F" for p in pbc)}"'
    )
    data = np.column_stack([positions, 0.5 * diameters, velocities, omega, forces])
    lines = [str(n), header]
    lines += ["P " + " ".join(f"{v:.10g}" for v in row) for row in data]
    text = "\n".join(lines) + "\n"
    if append:
        with open(path, "a") as f:
            f.write(text)
    else:
        with atomic_path(path) as tmp:
            tmp.write_text(text)


def _vtk_array(name: str, arr: np.ndarray, ncomp: int, kind: str = "Float64") -> str:
    fmt = "%.10g" if kind == "Float64" else "%d"
    body = " ".join(fmt % v for v in np.asarray(arr).ravel())
    comp = f' NumberOfComponents="{ncomp}"' if ncomp > 1 else ""
    return f'<DataArray type="{kind}" Name="{name}"{comp} format="ascii">{body}</DataArray>'


def write_vtp(
    path: str | os.PathLike,
    positions: np.ndarray,
    diameters: np.ndarray,
    velocities: np.ndarray,
    omega: np.ndarray,
    forces: np.ndarray,
) -> None:
    """VTK PolyData (.vtp, XML, ASCII) point cloud for ParaView with diameter, velocity, spin
    and force per particle (use a Glyph filter scaled by ``diameter`` to draw spheres)."""
    n = len(diameters)
    conn = np.arange(n)
    xml = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian">\n<PolyData>\n'
        f'<Piece NumberOfPoints="{n}" NumberOfVerts="{n}">\n'
        '<PointData Scalars="diameter" Vectors="velocity">\n'
        + _vtk_array("diameter", diameters, 1)
        + "\n"
        + _vtk_array("velocity", velocities, 3)
        + "\n"
        + _vtk_array("omega", omega, 3)
        + "\n"
        + _vtk_array("force", forces, 3)
        + "\n</PointData>\n<Points>\n"
        + _vtk_array("Points", positions, 3)
        + "\n</Points>\n<Verts>\n"
        + _vtk_array("connectivity", conn, 1, "Int64")
        + "\n"
        + _vtk_array("offsets", conn + 1, 1, "Int64")
        + "\n</Verts>\n</Piece>\n</PolyData>\n</VTKFile>\n"
    )
    with atomic_path(path) as tmp:
        tmp.write_text(xml)


def snapshot(sim: Any, path: str | os.PathLike, fmt: str | None = None) -> Path:
    """Write a particle snapshot of a Simulation or scene (format from the suffix:
    ``.xyz`` extended XYZ, ``.vtp`` VTK PolyData)."""
    path = Path(path)
    fmt = fmt or path.suffix.lstrip(".")
    core = sim.core
    x, v, w, f = core.positions(), core.velocities(), core.angular_velocities(), core.forces()
    d = core.diameters()
    if fmt == "xyz":
        cell, origin = core.cell()
        write_xyz(path, x, d, v, w, f, np.asarray(cell), np.asarray(origin),
                  getattr(sim, "pbc", (True, True, True)), core.time, core.step)
    elif fmt == "vtp":
        write_vtp(path, x, d, v, w, f)
    else:
        raise ParameterError(f"invalid snapshot format {fmt!r}: allowed 'xyz' or 'vtp'")
    return path


# -- LAMMPS data files (atom_style sphere) ------------------------------------------------
def _r(v: Any) -> str:
    """Shortest round-trip text of a float (numpy scalars included)."""
    return repr(float(v))


def write_lammps_data(
    path: str | os.PathLike,
    positions: np.ndarray,
    diameters: np.ndarray,
    density: float | np.ndarray,
    box_lo: tuple[float, float, float],
    box_hi: tuple[float, float, float],
    velocities: np.ndarray | None = None,
    omega: np.ndarray | None = None,
    tilt: tuple[float, float, float] | None = None,
) -> Path:
    """Write a LAMMPS data file, ``atom_style sphere`` (id type diameter density x y z), with a
    Velocities section (id vx vy vz wx wy wz) when velocities are given; full precision."""
    x = np.asarray(positions, float)
    d = np.asarray(diameters, float)
    n = len(d)
    rho = np.broadcast_to(np.asarray(density, float), (n,))
    lines = ["LAMMPS data file written by granflow " + __version__, "", f"{n} atoms",
             "1 atom types", ""]
    for k, ax in enumerate("xyz"):
        lines.append(f"{_r(box_lo[k])} {_r(box_hi[k])} {ax}lo {ax}hi")
    if tilt is not None:
        lines.append(f"{_r(tilt[0])} {_r(tilt[1])} {_r(tilt[2])} xy xz yz")
    lines += ["", "Atoms # sphere", ""]
    for i in range(n):
        lines.append(f"{i + 1} 1 {_r(d[i])} {_r(rho[i])} {_r(x[i, 0])} {_r(x[i, 1])} {_r(x[i, 2])}")
    if velocities is not None:
        v = np.asarray(velocities, float)
        w = np.zeros_like(v) if omega is None else np.asarray(omega, float)
        lines += ["", "Velocities", ""]
        for i in range(n):
            vals = " ".join(_r(c) for c in (*v[i], *w[i]))
            lines.append(f"{i + 1} {vals}")
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return path


def read_lammps_data(path: str | os.PathLike) -> dict[str, Any]:
    """Read a LAMMPS data file with ``atom_style sphere`` atoms (``id type diameter density x y
    z [ix iy iz]``) and an optional Velocities section. Returns arrays sorted by atom id:
    ``ids, type, diameter, density, x, v, omega`` and the box ``lo, hi, tilt``. Positions are
    unwrapped with image flags when present."""
    text = Path(path).read_text().splitlines()
    lo = [0.0, 0.0, 0.0]
    hi = [0.0, 0.0, 0.0]
    tilt = (0.0, 0.0, 0.0)
    natoms = None
    section = None
    atoms: list[list[float]] = []
    vels: list[list[float]] = []
    for raw in text[1:]:
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        toks = line.split()
        head = raw.strip().split("#")[0].strip()
        if head in ("Atoms", "Velocities") or head.split()[0] in ("Atoms", "Velocities",
                                                                  "Masses", "Bonds"):
            section = head.split()[0]
            if section == "Atoms" and "#" in raw and "sphere" not in raw.split("#", 1)[1]:
                raise GranflowIOError(
                    f"{path}: Atoms section is '{raw.split('#', 1)[1].strip()}', "
                    "granflow reads atom_style sphere"
                )
            continue
        if section is None:
            if len(toks) >= 2 and toks[-1] == "atoms":
                natoms = int(toks[0])
            for k, ax in enumerate("xyz"):
                if toks[-2:] == [f"{ax}lo", f"{ax}hi"]:
                    lo[k], hi[k] = float(toks[0]), float(toks[1])
            if toks[-3:] == ["xy", "xz", "yz"]:
                tilt = (float(toks[0]), float(toks[1]), float(toks[2]))
            continue
        if section == "Atoms":
            if len(toks) not in (7, 10):
                raise GranflowIOError(
                    f"{path}: atom line '{line}' has {len(toks)} columns: atom_style sphere has "
                    "7 (id type diameter density x y z) or 10 (with image flags)"
                )
            atoms.append([float(t) for t in toks])
        elif section == "Velocities":
            vels.append([float(t) for t in toks[:7]])
    if natoms is not None and len(atoms) != natoms:
        raise GranflowIOError(f"{path}: header says {natoms} atoms, found {len(atoms)}")
    if not atoms:
        raise GranflowIOError(f"{path}: no atoms")
    a = np.array(sorted(atoms, key=lambda r: r[0]))
    ids = a[:, 0].astype(int)
    x = a[:, 4:7].copy()
    if a.shape[1] == 10:
        L = np.asarray(hi) - np.asarray(lo)
        x += a[:, 7:10] * L
    out: dict[str, Any] = {
        "ids": ids, "type": a[:, 1].astype(int), "diameter": a[:, 2], "density": a[:, 3],
        "x": x, "v": None, "omega": None, "lo": tuple(lo), "hi": tuple(hi), "tilt": tilt,
    }
    if vels:
        vm = {int(r[0]): r[1:] for r in vels}
        vv = np.array([vm.get(i, [0.0] * 6) for i in ids])
        out["v"], out["omega"] = vv[:, :3], vv[:, 3:6]
    return out


def simulation_from_lammps(path: str | os.PathLike, law: Any = None, **kw: Any) -> Any:
    """A :class:`granflow.Simulation` from a LAMMPS data file (orthogonal periodic box unless
    ``box=`` is given). A single density is required (granflow's particles share one)."""
    from granflow.simulation import Box, ContactLaw, Simulation

    data = read_lammps_data(path)
    rho = np.unique(data["density"])
    if len(rho) != 1:
        raise ParameterError(
            f"invalid density: {len(rho)} different values in {path}: allowed a single density"
        )
    if any(t != 0.0 for t in data["tilt"]):
        raise ParameterError("invalid box: triclinic data file: allowed an orthogonal box here "
                             "(use the cell scene for triclinic states)")
    lo, hi = np.asarray(data["lo"]), np.asarray(data["hi"])
    box = kw.pop("box", Box(length=tuple(hi - lo), lo=tuple(lo)))
    return Simulation(data["x"], data["diameter"], box, law or ContactLaw(),
                      density=float(rho[0]), velocities=data["v"],
                      angular_velocities=data["omega"], **kw)
