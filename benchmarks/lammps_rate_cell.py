"""granflow's rate-controlled cell against LAMMPS 22Jul2025 on the same protocol, from the same
state (issue 35, item 2).

    python benchmarks/lammps_rate_cell.py --mu 0 0.3 --I 0.005 0.015 0.05 0.15 --seeds 1 2 3 \
        --steps 200000 --strain 10 --every 100 [--tau-p 0.1] [--out DIR] [--only-table]
    python benchmarks/lammps_rate_cell.py --p-ext 1e-5 --mu 0 --I 0.05 0.15 --seeds 1 2 3 \
        --strain 10 --out DIR_P [--reference DIR] [--thin 3]

``--p-ext`` runs another of 002's pressures (file names gain ``_p<p_ext>``); ``--reference``
adds each code's change from another pressure's runs at the same I (shift_table: if both codes
shift alike, the pressure dependence is the particles' stiffness, not this code); ``--thin``
thins the series for committing (thin_series).

What it does, per point (mu_s, I) and seed (N = 2000, p_ext a/kn = 1e-4, normal "yy"):

1. granflow: ``RateCell(N, mu=mu_s, p_ext, inertial_number=I, normal="yy", seed, threads=1)``
   and ``prepare()``: the dilute start compacted under p_ext alone, then the switch to the
   imposed rate L_xy = dv_x/dy = ``cell.shear_rate`` = 2 I sqrt(p_ext/rho)/a with sigma_yy held
   at p_ext (x and z lengths fixed). The state at the switch is handed to LAMMPS (kept in
   OUT/handoff/, written as OUT/lammps/<run>/data.lmp): positions, total velocities (granflow's
   peculiar ones plus the streaming L_xy y, the y measured from the box's lower face), angular
   velocities, diameters, density and the triclinic box (granflow's H; its tilts reduced into
   LAMMPS's limits by a change of lattice basis and the particles re-wrapped,
   ``compare_lammps._lammps_box``).
2. Both codes run ``--steps`` steps (or more where ``--strain`` needs them) at the same dt
   from that state: granflow ``cell.run(steps)``;
   LAMMPS ``fix deform/pressure 1 y pressure P_EXT GAIN xy erate/rescale RATE remap v flip yes``
   (x, z fixed; the tilt moves at RATE times the current y length, as granflow's
   dH_xy/dt = L_xy H_yy), ``fix nve/sphere``, ``pair_style gran/hooke/history`` with
   ``comm_modify vel yes``. LAMMPS's stress is ``compute pressure`` with the temperature
   ``compute temp/deform`` (the kinetic part from velocities less the box's streaming profile,
   i.e. peculiar ones, as granflow's; it works with deform/pressure: without it N1/p would carry
   rho phi (RATE L_y)^2/3, ~2.5 p at I = 0.15, and the smoke run's N1/p agrees with granflow's),
   also used by the fix's controller (``fix_modify temp press``).
3. Each run's series (every ``--every`` steps, after the switch): t (from the switch), phi,
   sigma_xx, sigma_yy, sigma_zz, sigma_xy (total stress, contact + kinetic). Both codes'
   stresses are compressive-positive with sigma_ab = (1/V)[sum r_ij,a f_ij,b + sum m v'_a v'_b]
   (granflow's 2.11; LAMMPS's pressure tensor P_ab, whose virial is sum r_a f_b too), so
   sigma_xy < 0 under the positive shear dv_x/dy > 0 in both (checked by the smoke run; no sign
   is flipped). Written to OUT/series/{code}_mu{mu_s}_I{I}_s{seed}.parquet as soon as a run is
   done (with a .json of its wall time and speed); an existing file is not run again.
4. Per run: the steady part starts at the MSER start of phi, p and mu
   (``granflow.analysis.rheology.cell_steady_start`` on those columns; at least the first
   ``--drop`` fraction is dropped as well, default 0.1); means and blocking SEs
   (``granflow.analysis.stats.blocking``) of the per-sample ratios mu = -sigma_xy/sigma_yy
   (= |sigma_xy|/sigma_yy while sigma_xy < 0), N1/p = (sigma_xx - sigma_yy)/p,
   N2/p = (sigma_yy - sigma_zz)/p with p = tr(sigma)/3, of phi, and of sigma_yy/p_ext (the
   controller check: 1 within its SE in both codes). LAMMPS's sigma_xx is taken without the
   box slip's kinetic term (without_slip, box_slip: its dilating box slides past the
   material, which temp/deform reads as x velocity fluctuation).
5. Per point: the replicas' means (``granflow.analysis.replicas.replica_mean``, all seeds) of
   each code, and per quantity granflow - LAMMPS, its combined SE sqrt(se_g^2 + se_l^2), z and
   the verdict ("agrees" if |z| <= 2). Printed and written to OUT/table.parquet (the per-run
   values to OUT/runs.parquet).

Material mapping (002's, ``MATERIAL_002`` / ``cell.parameters()["law"]``): granflow's Hooke law
with rate damping is LAMMPS ``gran/hooke/history Kn Kt gamma_n gamma_t xmu 1`` with Kn = kn,
Kt = kt = kn, gamma_n = xi_n = 0.5/t_c (t_c the "collision" reading, the mean pair's collision
time with that damping), gamma_t = xi_t = xi_t_ratio xi_n = gamma_n/2, xmu = mu_s; both damping
forces are m_eff gamma v. LJ units with a = 1 (mean diameter ~1), kn = 1, density 1 (mass
rho pi d^3/6 in both: LAMMPS's rmass = density 4/3 pi r^3). Diameters uniform in [0.9, 1.1].
Neighbour skin: granflow's kernel default. Known differences in the contact algebra (lever arm
R_i against r R_i/(R_i+R_j), the dashpot's velocity at the half step; benchmarks/NOTES_lammps.md)
are O(overlap/d) and O(dt omega_c).

The protocol against 002's (the reproduce_002 campaign): 002's cell is stress-controlled
(p_ext and tau_ext imposed, the rate follows, Parrinello-Rahman on the whole cell); here the rate
is imposed and only sigma_yy is controlled, x and z fixed: the same steady rheology if mu(I),
phi(I) do not depend on which is imposed (issue item 3 checks that in granflow). mu here is the
plain ratio -sigma_xy/sigma_yy, not 002's mu1 (the deviatoric projection on D), and N1, N2 are
the normal-stress differences in the flow frame (x flow, y gradient, z vorticity).

The two normal-stress controllers differ: granflow's barostat is second order (cell mass W_g,
dP_g,yy/dt = V (sigma_yy - p_ext), the breathing affine through the streaming velocity L_yy y);
LAMMPS's is first order, d ln L_y/dt = GAIN (P_yy - p_ext) (``normalize/pressure yes`` is
accepted by 22Jul2025 but has no effect, checked, so GAIN is in 1/(time pressure)), and with
``remap v`` its breathing enters at the periodic y boundary (positions are not rescaled): a
compression loads the contacts across that face at once, a dilation opens them and the bulk
follows at the speed of sound and of the flow's rearrangement. Neither gain changes the steady
mean: in a steady state the time average of the drive is zero, so <sigma_yy> = p_ext in both;
while the packing still dilates or compacts, LAMMPS's proportional controller lags by the
offset d ln L_y/dt / GAIN (granflow's barostat, with its momentum, does not), so its transient
is longer (at I = 0.15 about 250 time units against granflow's ~100) and the MSER start drops it.
GAIN = 1/(B_yy tau_p), where B_yy = dsigma_yy/deps_yy = (1/V) sum_c kn r_y^4/r^2 is the contact
network's stiffness under an affine eps_yy at the hand-off and tau_p (``--tau-p``, t_c) the
response time to a compression. The default, 0.1 t_c, is of the order of granflow's own barostat
time 1/Omega = sqrt(W_g/(V B_yy)) at the hand-off (0.29-0.32 t_c at 2000 particles, printed per
run), a third of it because the dilation, which the flow needs after the switch, is what lags:
with tau_p = 0.32 t_c LAMMPS's sigma_yy came down to p_ext 600 time units after the switch at
mu_s = 0, I = 0.15 (from phi 0.635 to 0.572), with 0.1 t_c in 300, with 0.05 t_c in 130. The
loop is stable while dt/tau_p is well below 1 (0.2 at the default, dt = 0.02 t_c); at
tau_p ~ 0.01 t_c the box rings step by step and the sampled sigma_yy is aliased (seen).

Runs go one at a time on one core (granflow threads=1, LAMMPS serial); each prints its wall time
and speed. ``--only-table`` recomputes the table from OUT/series without running anything.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
from granflow.analysis.compare import agrees, difference_z
from granflow.analysis.replicas import replica_mean
from granflow.analysis.rheology import cell_steady_start
from granflow.analysis.stats import blocking
from granflow.material import kernel_default_skin
from granflow.scenes import RateCell

sys.path.insert(0, str(Path(__file__).parent))
import lammps_peer as lp  # noqa: E402
from compare_lammps import _lammps_box  # noqa: E402

OUT = Path(__file__).parent / "out" / "lammps_rate_cell"
N = 2000
P_EXT = 1e-4
CODES = ("granflow", "lammps")
SERIES_COLUMNS = ("t", "phi", "sigma_xx", "sigma_yy", "sigma_zz", "sigma_xy")
QUANTITIES = ("mu", "phi", "N1_p", "N2_p", "syy_pext")
#: LAMMPS's controller response time to a compression, in t_c (module docstring)
TAU_P = 0.1

Array = np.ndarray


# ----------------------------------------------------------------------------------------------
# names and files


def point_name(mu_s: float, inertial: float, seed: int) -> str:
    """The file stem of one (mu_s, I, seed) (with the size and p_ext where they are not the
    issue's)."""
    size = "" if N == 2000 else f"_N{N}"
    pressure = "" if P_EXT == 1e-4 else f"_p{P_EXT:g}"
    return f"mu{mu_s:g}_I{inertial:g}_s{seed}{size}{pressure}"


def series_path(out: Path, code: str, mu_s: float, inertial: float, seed: int) -> Path:
    """Where a run's series goes."""
    return out / "series" / f"{code}_{point_name(mu_s, inertial, seed)}.parquet"


def _write_json(path: Path, obj: dict[str, Any]) -> None:
    path.write_text(json.dumps(obj, indent=1, default=float))


# ----------------------------------------------------------------------------------------------
# granflow: prepare, hand-off, run


def make_cell(mu_s: float, inertial: float, seed: int, every: int) -> RateCell:
    """The point's granflow cell (not prepared)."""
    return RateCell(N=N, mu=mu_s, p_ext=P_EXT, inertial_number=inertial, normal="yy", seed=seed,
                    sample_every=every, threads=1)


def contact_stiffness_yy(cell: RateCell) -> float:
    """B = dsigma_yy/deps_yy of the contact network under an affine strain eps_yy (Hooke,
    the current contacts): (1/V) sum_c kn r_y^4 / r^2."""
    core = cell.core
    core.compute_forces()  # the contact list of the current positions (no step is taken)
    _, r, _ = core.contacts()
    r = np.asarray(r)
    if len(r) == 0:
        return math.nan
    r2 = np.einsum("ij,ij->i", r, r)
    kn = float(cell.mat.kn_value)
    return float(kn * np.sum(r[:, 1] ** 4 / r2) / float(core.volume))


def handoff(cell: RateCell) -> dict[str, Any]:
    """The prepared cell's state as a LAMMPS state (``lammps_peer.state_from_arrays``) plus
    what the LAMMPS run needs: rate, dt, law, skin, and the controller's numbers."""
    core = cell.core
    h, o = (np.asarray(z) for z in core.cell())
    box = _lammps_box(h, o, core.positions(), core.velocities())
    v = np.array(box["v"], dtype=np.float64)
    rate = float(cell.shear_rate)
    v[:, 0] += rate * box["x"][:, 1]  # the streaming at the switch, from the box's lower face
    d = core.diameters()
    st = lp.state_from_arrays(box["x"], d, np.zeros(3), box["hi"], density=cell.mat.density,
                              v=v, omega=core.angular_velocities(), tilt=box["tilt"])
    law = cell.mat.law(d).as_dict()
    vol = float(core.volume)
    b_yy = contact_stiffness_yy(cell)
    omega_bar = math.sqrt(vol * b_yy / cell.w_g)  # granflow's barostat frequency at the switch
    obs = dict(core.domain_observables())
    return {
        "state": st, "rate": rate, "dt": float(core.dt), "t_c": float(cell.t_c),
        "kn": float(law["kn"]), "kt": float(law["kt"]), "gamma_n": float(law["xi_n"]),
        "gamma_t": float(law["xi_n"] * law["xi_t_ratio"]), "mu": float(law["mu"]),
        "density": float(cell.mat.density), "skin": float(kernel_default_skin()),
        "p_ext": float(cell.p_ext), "volume": vol, "solid_volume": float(np.sum(np.pi / 6 * d**3)),
        "B_yy": b_yy, "W_g": float(cell.w_g), "barostat_time": 1.0 / omega_bar,
        "n": int(core.n), "L_yy_switch": float(obs.get("L_yy", math.nan)),
        "H": h.tolist(), "shear_start_time": cell.shear_start_time,
    }  # fmt: skip


def granflow_series(cell: RateCell) -> pl.DataFrame:
    """The cell's series after the switch, as the common columns (t from the switch)."""
    s = pl.from_arrow(cell.tables()["series"])
    assert isinstance(s, pl.DataFrame)
    t0 = float(cell.shear_start_time or 0.0)
    s = s.filter(pl.col("t") > t0 + 1e-9 * max(1.0, t0))
    return s.select((pl.col("t") - t0).alias("t"), *[pl.col(c) for c in SERIES_COLUMNS[1:]])


# ----------------------------------------------------------------------------------------------
# LAMMPS


def lammps_gain(ho: dict[str, Any], tau_p: float | None) -> tuple[float, float]:
    """GAIN of ``fix deform/pressure y pressure P GAIN`` (1/(time pressure); no
    ``normalize/pressure``, which 22Jul2025 accepts but ignores: checked) for a response time
    1/(GAIN B_yy) of ``tau_p`` t_c (None: granflow's barostat time at the hand-off), and that
    time."""
    tau = ho["barostat_time"] if tau_p is None else tau_p * ho["t_c"]
    return 1.0 / (tau * ho["B_yy"]), tau


def run_steps(cell: RateCell, steps: int, strain: float | None) -> int:
    """The shear steps of a point: ``steps``, or more where ``strain`` needs them (the
    imposed rate times the run's time)."""
    if strain is None:
        return steps
    dt = cell.timestep
    assert dt is not None
    return max(steps, math.ceil(strain / (cell.shear_rate * dt)))


def lammps_input(ho: dict[str, Any], steps: int, every: int, gain: float) -> str:
    """The LAMMPS input: read data.lmp, shear at the rate with sigma_yy controlled, write the
    stress tensor (temp/deform kinetic part) and the box every ``every`` steps to series.txt."""
    f = lp._f
    law = (f"{f(ho['kn'])} {f(ho['kt'])} {f(ho['gamma_n'])} {f(ho['gamma_t'])} {f(ho['mu'])} 1")
    lines = [
        "# written by benchmarks/lammps_rate_cell.py",
        "units lj",
        "atom_style sphere",
        "atom_modify map array",
        "dimension 3",
        "boundary p p p",
        "newton on",
        "comm_modify vel yes",
        "read_data data.lmp",
        f"neighbor {f(ho['skin'])} bin",
        "neigh_modify every 1 delay 0 check yes",
        f"pair_style gran/hooke/history {law}",
        "pair_coeff * *",
        f"timestep {f(ho['dt'])}",
        "fix integ all nve/sphere",
        # the kinetic stress from the velocities less the box's streaming profile (peculiar)
        "compute tdef all temp/deform",
        "compute pdef all pressure tdef",
        "variable vol equal vol",
        "variable lx equal lx",
        "variable ly equal ly",
        "variable lz equal lz",
        "variable xy equal xy",
        # the material's mass-weighted mean x velocity against the stream temp/deform subtracts
        # (RATE (y - ylo): the tilt rate is RATE l_y): the box slip that without_slip removes
        f"variable mslip atom mass*(vx-{f(ho['rate'])}*(y-ylo))",
        "compute mslip all reduce sum v_mslip",
        "variable slip equal c_mslip/mass(all)",
        # defined before the deformation so that the stress and the box are sampled at the same
        # configuration (the deform fix changes the box at the end of the step, after this)
        f"fix series all ave/time {int(every)} 1 {int(every)} c_pdef[1] c_pdef[2] c_pdef[3] "
        "c_pdef[4] c_pdef[5] c_pdef[6] v_vol v_lx v_ly v_lz v_xy v_slip file series.txt "
        "format \" %.17g\"",
        f"fix shear all deform/pressure 1 y pressure {f(ho['p_ext'])} {f(gain)} "
        f"xy erate/rescale {f(ho['rate'])} remap v flip yes",
        "fix_modify shear temp tdef press pdef",
        "thermo_style custom step time c_pdef[2] v_ly v_xy",
        "thermo_modify norm no format float %.17g",
        f"thermo {max(1, steps // 10)}",
        f"run {int(steps)}",
        "write_data end.data nocoeff",
    ]
    return "\n".join(lines) + "\n"


def run_lammps(ho: dict[str, Any], steps: int, every: int, gain: float,
               workdir: Path) -> tuple[pl.DataFrame, dict[str, Any]]:
    """Run LAMMPS serially from the hand-off; the common series and the run's facts."""
    workdir.mkdir(parents=True, exist_ok=True)
    st = ho["state"]
    lp.write_data(workdir / "data.lmp", st["ids"], st["x"], st["diameter"], st["density"],
                  v=st["v"], omega=st["omega"], box_lo=st["box_lo"], box_hi=st["box_hi"],
                  tilt=st["tilt"])
    (workdir / "in.lmp").write_text(lammps_input(ho, steps, every, gain))
    pre, env = lp.command("serial")
    cmd = pre + ["-in", "in.lmp", "-log", "log.lammps", "-screen", "none", "-nocite"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    log = (workdir / "log.lammps").read_text() if (workdir / "log.lammps").exists() else ""
    if proc.returncode != 0:
        err = [ln for ln in log.splitlines() if "ERROR" in ln]
        raise RuntimeError(f"LAMMPS failed (rc={proc.returncode}) in {workdir}: "
                           + ("; ".join(err) or proc.stderr[-2000:] or proc.stdout[-2000:]))
    lg = lp.parse_log(log)
    a = np.loadtxt(workdir / "series.txt", comments="#", ndmin=2)
    # columns: step, Pxx Pyy Pzz Pxy Pxz Pyz, vol, lx, ly, lz, xy, slip
    a = a[a[:, 0] > 0]
    vol = a[:, 7]
    df = pl.DataFrame({
        "t": a[:, 0] * ho["dt"], "phi": ho["solid_volume"] / vol,
        "sigma_xx": a[:, 1], "sigma_yy": a[:, 2], "sigma_zz": a[:, 3], "sigma_xy": a[:, 4],
        "lx": a[:, 8], "ly": a[:, 9], "lz": a[:, 10], "xy": a[:, 11], "slip_vx": a[:, 12],
    })  # fmt: skip
    loop = lg["loops"][-1] if lg["loops"] else None
    facts = {"wall_s": wall, "loop_s": loop["seconds"] if loop else math.nan,
             "neighbor_builds": lg["neighbor_builds"],
             "dangerous_builds": lg["dangerous_builds"],
             "warnings": sorted({ln.strip() for ln in log.splitlines() if "WARNING" in ln})[:10]}
    return df, facts


def tilt_rate_check(df: pl.DataFrame, rate: float, dt_sample: float) -> tuple[float, float]:
    """LAMMPS's tilt rate against rate * l_y (flips undone: a jump by l_x): the largest relative
    deviation over one sample interval (l_y's breathing within it, known only at the samples,
    bounds it) and that of the whole run's mean rate against rate <l_y>."""
    xy, ly, lx = (df[c].to_numpy() for c in ("xy", "ly", "lx"))
    dxy = np.diff(xy)
    dxy -= np.round(dxy / lx[1:]) * lx[1:]  # undo the flips
    if not len(dxy):
        return math.nan, math.nan
    expect = rate * 0.5 * (ly[1:] + ly[:-1]) * dt_sample
    return (float(np.max(np.abs(dxy / expect - 1.0))),
            float(np.sum(dxy) / np.sum(expect) - 1.0))


# ----------------------------------------------------------------------------------------------
# per run and per point


def derived(df: pl.DataFrame, p_ext: float) -> pl.DataFrame:
    """The per-sample ratios: p, mu = -sigma_xy/sigma_yy, N1/p, N2/p, sigma_yy/p_ext."""
    p = (pl.col("sigma_xx") + pl.col("sigma_yy") + pl.col("sigma_zz")) / 3.0
    return df.with_columns(p.alias("p")).with_columns(
        (-pl.col("sigma_xy") / pl.col("sigma_yy")).alias("mu"),
        ((pl.col("sigma_xx") - pl.col("sigma_yy")) / pl.col("p")).alias("N1_p"),
        ((pl.col("sigma_yy") - pl.col("sigma_zz")) / pl.col("p")).alias("N2_p"),
        (pl.col("sigma_yy") / p_ext).alias("syy_pext"),
    )


def without_slip(df: pl.DataFrame, ho: dict[str, Any]) -> pl.DataFrame:
    """A LAMMPS series with the box slip's kinetic term taken out of sigma_xx (box_slip):
    rho phi dv^2, dv the material's mass-weighted mean v_x less the stream, measured at each
    sample (``slip_vx``) where the series has it, else RATE (l_y - l_y0)/2, the lower face's
    displacement when the box dilates about its centre (the series committed before
    ``slip_vx`` was written; measured: the end states' mean slip matches it within 0.002
    RATE l_y, benchmarks/NOTES.md). Without it LAMMPS's N1/p reads the material's uniform
    slide past the box's stream as normal stress (+0.016-0.021 at I = 0.15)."""
    dv = (pl.col("slip_vx") if "slip_vx" in df.columns
          else ho["rate"] * (pl.col("ly") - ho["H"][1][1]) / 2.0)
    return df.with_columns(pl.col("sigma_xx") - ho["density"] * pl.col("phi") * dv**2)


def mser_start(df: pl.DataFrame, p_ext: float) -> tuple[float, bool]:
    """The MSER steady start on phi, p, mu of a series (its time) and whether it settled."""
    d = derived(df, p_ext)
    ss = cell_steady_start(d, key_columns=("phi", "p", "mu"))
    return float(d["t"][int(ss.index)]), bool(ss.settled)


def run_stats(df: pl.DataFrame, p_ext: float, drop: float,
              start_at: tuple[float, bool] | None = None) -> dict[str, Any]:
    """Steady start (MSER on phi, p, mu, or ``start_at``: the (time, settled) of the MSER
    start taken on the full series before it was thinned; at least ``drop`` of the run) and
    each quantity's mean and blocking SE over the steady part."""
    d = derived(df, p_ext)
    t = d["t"].to_numpy()
    t0, settled = start_at if start_at is not None else mser_start(df, p_ext)
    start = max(int(np.searchsorted(t, t0)), int(math.ceil(drop * len(t))))
    dts = float(t[1] - t[0]) if len(t) > 1 else 1.0
    row: dict[str, Any] = {"samples": len(t), "steady_start": start, "t_steady": float(t[start]),
                           "settled": settled, "t_end": float(t[-1])}
    for q in QUANTITIES:
        b = blocking(d[q].to_numpy()[start:], dts)
        row[q], row[f"{q}_se"], row[f"{q}_tau"] = b.mean, b.se, b.tau
        row[f"{q}_converged"] = bool(b.converged)
    return row


def _both_codes(g: pl.DataFrame) -> tuple[dict[str, Any], dict[str, Any]] | None:
    """granflow's and LAMMPS's rows of one group (a point, or a point and quantity); None
    unless both codes are there."""
    by = {r["code"]: r for r in g.iter_rows(named=True)}
    return (by["granflow"], by["lammps"]) if all(c in by for c in CODES) else None


def read_series(out: Path, f: Path) -> pl.DataFrame:
    """The series ``f`` (OUT/series/<code>_<run>.parquet), LAMMPS's without its box slip's
    kinetic term (without_slip)."""
    df = pl.read_parquet(f)
    code, name = f.stem.split("_", 1)
    return without_slip(df, granflow_handoff(out, name)) if code == "lammps" else df


def granflow_handoff(out: Path, name: str) -> dict[str, Any]:
    """The hand-off facts (rate, dt, H at the switch, p_ext, density, ...) of run ``name``
    (point_name), from its granflow series' .json."""
    meta = out / "series" / f"granflow_{name}.json"
    return dict(json.loads(meta.read_text())["handoff"])


def build_tables(out: Path, mus: list[float], inertials: list[float], seeds: list[int],
                 drop: float) -> tuple[pl.DataFrame, pl.DataFrame]:
    """Per-run statistics of every series present, and the per-point comparison table."""
    runs = []
    for mu_s in mus:
        for inertial in inertials:
            for seed in seeds:
                for code in CODES:
                    f = series_path(out, code, mu_s, inertial, seed)
                    if not f.exists():
                        continue
                    row = {"code": code, "mu_s": mu_s, "I": inertial, "seed": seed}
                    j = f.with_suffix(".json")
                    meta = json.loads(j.read_text()) if j.exists() else {}
                    start = meta.get("mser_start_full")  # (thinned: the full series' start)
                    row.update(run_stats(read_series(out, f), P_EXT, drop,
                                         tuple(start) if start else None))
                    runs.append(row)
    if not runs:
        return pl.DataFrame(), pl.DataFrame()
    rdf = pl.from_dicts(runs, infer_schema_length=None)
    rep = replica_mean(rdf, ["code", "mu_s", "I"], list(QUANTITIES))
    rows = []
    for (mu_s, inertial), g in rep.group_by(["mu_s", "I"], maintain_order=True):
        pair = _both_codes(g)
        if pair is None:
            continue
        gf, lm = pair
        for q in QUANTITIES:
            diff, se, z = difference_z(gf[q], gf[f"{q}_se"], lm[q], lm[f"{q}_se"])
            rows.append({
                "mu_s": mu_s, "I": inertial, "quantity": q,
                "replicas_granflow": gf["replicas"], "replicas_lammps": lm["replicas"],
                "granflow": gf[q], "granflow_se": gf[f"{q}_se"],
                "lammps": lm[q], "lammps_se": lm[f"{q}_se"], "diff": diff, "diff_se": se, "z": z,
                "verdict": "agrees" if agrees(z) else ("differs" if math.isfinite(z)
                                                                else "no SE"),
            })  # fmt: skip
    return rdf, pl.from_dicts(rows, infer_schema_length=None) if rows else pl.DataFrame()


def shift_table(runs: pl.DataFrame, reference: pl.DataFrame) -> pl.DataFrame:
    """Each code's change from ``reference`` (another pressure's runs.parquet, the same points)
    to ``runs``, per (mu_s, I) and quantity: the shift, its combined SE and z; and whether the
    two codes shift alike (``codes_z``: granflow's shift less LAMMPS's over their combined SE).
    The stiffness check of 002's pressure collapse: if the shift is physics (p d/kn), both
    codes show it; if it is this code, only granflow does."""
    rows = []
    keys = ["code", "mu_s", "I"]
    now = replica_mean(runs, keys, list(QUANTITIES))
    ref = replica_mean(reference, keys, list(QUANTITIES))
    for r in now.iter_rows(named=True):
        m = ref.filter((pl.col("code") == r["code"]) & (pl.col("mu_s") == r["mu_s"])
                       & (pl.col("I") == r["I"]))
        if m.is_empty():
            continue
        r0 = m.row(0, named=True)
        for q in QUANTITIES:
            d, se, z = difference_z(r[q], r[f"{q}_se"], r0[q], r0[f"{q}_se"])
            rows.append({"mu_s": r["mu_s"], "I": r["I"], "quantity": q, "code": r["code"],
                         "shift": d, "shift_se": se, "z": z})
    if not rows:
        return pl.DataFrame()
    tab = pl.from_dicts(rows)
    out = []
    for (mu_s, inertial, q), g in tab.group_by(["mu_s", "I", "quantity"], maintain_order=True):
        pair = _both_codes(g)
        if pair is None:
            continue
        gf, lm = pair
        _, _, cz = difference_z(gf["shift"], gf["shift_se"], lm["shift"], lm["shift_se"])
        out.append({"mu_s": mu_s, "I": inertial, "quantity": q,
                    "shift_granflow": gf["shift"], "shift_granflow_se": gf["shift_se"],
                    "z_granflow": gf["z"], "shift_lammps": lm["shift"],
                    "shift_lammps_se": lm["shift_se"], "z_lammps": lm["z"], "codes_z": cz,
                    "codes": "shift alike" if agrees(cz) else "shift apart"})
    return pl.from_dicts(out) if out else pl.DataFrame()


def print_shift(shift: pl.DataFrame, p_ref: str) -> None:
    """The shift table, one line per point and quantity."""
    print(f"\nchange from the reference ({p_ref}) in each code; codes_z: granflow's shift less "
          "LAMMPS's over the combined SE")
    print(f"{'mu_s':>5} {'I':>6} {'quantity':>9} {'granflow shift':>22} {'LAMMPS shift':>22} "
          f"{'codes_z':>7}")
    for r in shift.iter_rows(named=True):
        cells = [f"{r[f'shift_{c}']:>+10.5f} ± {r[f'shift_{c}_se']:<7.5f} (z {r[f'z_{c}']:+.1f})"
                 for c in CODES]
        print(f"{r['mu_s']:>5g} {r['I']:>6g} {r['quantity']:>9} {cells[0]} {cells[1]} "
              f"{r['codes_z']:>+7.2f}  {r['codes']}")


def print_table(table: pl.DataFrame) -> None:
    """The comparison table, one line per point and quantity."""
    if table.is_empty():
        print("no point has both codes yet")
        return
    print(f"\n{'mu_s':>5} {'I':>6} {'quantity':>9} {'granflow':>20} {'LAMMPS':>20} "
          f"{'diff':>10} {'z':>6}  verdict")
    for r in table.iter_rows(named=True):
        print(f"{r['mu_s']:>5g} {r['I']:>6g} {r['quantity']:>9} "
              f"{r['granflow']:>11.5f} ± {r['granflow_se']:<7.5f} "
              f"{r['lammps']:>11.5f} ± {r['lammps_se']:<7.5f} {r['diff']:>+10.5f} "
              f"{r['z']:>+6.2f}  {r['verdict']}")


def box_slip(out: Path) -> pl.DataFrame:
    """LAMMPS's material against its box's streaming profile at the end of each run (from
    OUT/lammps/<run>/end.data, where kept): the mass-weighted mean of v_x - RATE (y - ylo),
    over RATE l_y, against -(l_y - l_y0)/(2 l_y), the lower face's displacement if the box
    dilated about its centre. ``fix deform/pressure`` with ``remap v`` moves the faces without
    moving the particles, so the stream that ``compute temp/deform`` subtracts (from the lower
    face) slides past the material by RATE times the face's displacement, and the "peculiar"
    velocities keep that uniform offset dv: the kinetic sigma_xx gains rho phi dv^2 (the
    ``n1_bias`` column, over p_ext); sigma_xy and sigma_yy do not (the mean v'_y is zero).
    granflow's breathing is affine (positions move with the stream), so it has none."""
    rows = []
    for end in sorted((out / "lammps").glob("*/end.data")):
        name = end.parent.name
        if not (out / "series" / f"granflow_{name}.json").exists():
            continue
        ho = granflow_handoff(out, name)
        d = lp.read_data(end)
        lo, hi = d["box_lo"], d["box_hi"]
        ly, m = hi[1] - lo[1], d["mass"]
        dv = float(np.sum(m * (d["v"][:, 0] - ho["rate"] * (d["x"][:, 1] - lo[1]))) / m.sum())
        vol = float(np.prod(hi - lo))
        rows.append({"run": name, "rate": ho["rate"], "l_y0": ho["H"][1][1], "l_y": ly,
                     "slip": dv / (ho["rate"] * ly),
                     "slip_from_dilation": -(ly - ho["H"][1][1]) / (2 * ly),
                     "n1_bias": float(m.sum()) / vol * dv**2 / ho["p_ext"]})
    return pl.from_dicts(rows) if rows else pl.DataFrame()


def thin_series(out: Path, k: int) -> int:
    """Keep every ``k``-th sample of each series in OUT/series not thinned before (its .json
    records ``thinned``; ``every`` becomes the kept spacing): a lower pressure needs
    sqrt(1e-4/p_ext) times the steps for the same strain, so its series are thinned to the
    p_ext = 1e-4 runs' samples per unit strain before they are committed. The statistics are
    blocking SEs of correlated samples, which thinning below the correlation time leaves
    alone; the MSER start is not (taken on the thinned series it moved granflow's means at
    1e-6 by up to 1.7 SE), so the full series' start goes to the .json (``mser_start_full``)
    and the table keeps it. Returns the number of series thinned."""
    done = 0
    for f in sorted((out / "series").glob("*.parquet")):
        meta_path = f.with_suffix(".json")
        meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
        if "thinned" in meta:
            continue
        meta["mser_start_full"] = list(mser_start(read_series(out, f), P_EXT))
        pl.read_parquet(f).gather_every(k).write_parquet(f)
        meta["sampled_every"] = meta.get("every")
        meta["every"] = meta["sampled_every"] * k if meta["sampled_every"] else None
        meta["thinned"] = k
        _write_json(meta_path, meta)
        done += 1
    return done


# ----------------------------------------------------------------------------------------------
# one (point, seed)


def run_one(out: Path, mu_s: float, inertial: float, seed: int, steps: int, every: int,
            tau_p: float | None, strain: float | None = None) -> None:
    """Both codes on one (mu_s, I, seed), each skipped if its series exists: ``steps`` shear
    steps, or more where ``strain`` needs them."""
    name = point_name(mu_s, inertial, seed)
    steps = run_steps(make_cell(mu_s, inertial, seed, every), steps, strain)
    f_gf = series_path(out, "granflow", mu_s, inertial, seed)
    f_lm = series_path(out, "lammps", mu_s, inertial, seed)
    f_ho = out / "handoff" / f"{name}.npz"
    if f_gf.exists() and f_lm.exists():
        print(f"{name}: both series present, skipped")
        return
    for sub in ("series", "handoff", "lammps"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    ho: dict[str, Any]
    if not f_gf.exists() or not f_ho.exists():
        cell = make_cell(mu_s, inertial, seed, every)
        t0 = time.perf_counter()
        cell.prepare(progress=False)
        t_prep = time.perf_counter() - t0
        ho = handoff(cell)
        st = ho["state"]
        np.savez(f_ho, **{k: v for k, v in st.items() if v is not None and k != "natoms"},
                 meta=json.dumps({k: v for k, v in ho.items() if k != "state"}, default=float))
        print(f"{name}: granflow prepared in {t_prep:.0f} s (switch at t = "
              f"{ho['shear_start_time']:.4g}, phi = {ho['solid_volume'] / ho['volume']:.4f}, "
              f"rate {ho['rate']:.4g}, B_yy = {ho['B_yy']:.3g}, barostat time "
              f"{ho['barostat_time'] / ho['t_c']:.3g} t_c)")
        if not f_gf.exists():
            t0 = time.perf_counter()
            cell.run(steps, progress=False)
            wall = time.perf_counter() - t0
            df = granflow_series(cell)
            df.write_parquet(f_gf)
            _write_json(f_gf.with_suffix(".json"), {
                "wall_s": wall, "prepare_s": t_prep, "steps": steps, "every": every,
                "n": ho["n"], "steps_per_s": steps / wall,
                "particle_steps_per_s": ho["n"] * steps / wall,
                "handoff": {k: v for k, v in ho.items() if k != "state"}})
            print(f"{name}: granflow {steps} steps in {wall:.1f} s ({steps / wall:.0f} steps/s, "
                  f"{ho['n'] * steps / wall:.3g} particle-steps/s)")
    else:
        z = np.load(f_ho)
        ho = json.loads(str(z["meta"]))
        ho["state"] = {k: z[k] for k in z.files if k != "meta"}
    if not f_lm.exists():
        gain, tau = lammps_gain(ho, tau_p)
        wd = out / "lammps" / name
        df, facts = run_lammps(ho, steps, every, gain, wd)
        df.write_parquet(f_lm)
        dts = every * ho["dt"]
        tilt_dev, tilt_mean = tilt_rate_check(df, ho["rate"], dts)
        _write_json(f_lm.with_suffix(".json"), {
            **facts, "steps": steps, "every": every, "n": ho["n"], "gain": gain,
            "response_time": tau, "response_time_tc": tau / ho["t_c"],
            "gain_per_tc_normalised": gain * ho["t_c"] * ho["p_ext"],
            "tilt_rate_max_rel_dev": tilt_dev, "tilt_rate_mean_rel_dev": tilt_mean,
            "steps_per_s": steps / facts["wall_s"],
            "particle_steps_per_s": ho["n"] * steps / facts["wall_s"]})
        print(f"{name}: LAMMPS {steps} steps in {facts['wall_s']:.1f} s (loop "
              f"{facts['loop_s']:.1f} s, {steps / facts['wall_s']:.0f} steps/s, "
              f"{ho['n'] * steps / facts['wall_s']:.3g} particle-steps/s); gain {gain:.4g} "
              f"(response {tau / ho['t_c']:.3g} t_c); tilt rate / (rate l_y) - 1: {tilt_mean:+.1e} "
              f"over the run, <= {tilt_dev:.1e} per sample interval")
        for w in facts["warnings"]:
            print(f"   LAMMPS: {w}")


# ----------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> None:
    """The command line (module docstring)."""
    global N, P_EXT
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--mu", type=float, nargs="+", default=[0.0, 0.3], help="mu_s values")
    ap.add_argument("--I", type=float, nargs="+", default=[0.005, 0.015, 0.05, 0.15],
                    help="inertial numbers (the imposed rate at p_ext)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="replicas")
    ap.add_argument("--steps", type=int, default=400_000, help="shear steps per run (both)")
    ap.add_argument("--strain", type=float, default=None,
                    help="run each point at least this shear strain (rate x time; more steps "
                         "than --steps at small I)")
    ap.add_argument("--every", type=int, default=100, help="steps between samples")
    ap.add_argument("--tau-p", type=float, default=TAU_P,
                    help="LAMMPS's sigma_yy controller response time 1/(GAIN B_yy) in t_c "
                         "(module docstring)")
    ap.add_argument("--n", type=int, default=N,
                    help="the cell's N (solid volume in mean particles; the issue's 2000)")
    ap.add_argument("--p-ext", type=float, default=P_EXT,
                    help="the held sigma_yy in kn/a (the issue's 1e-4; 002's other pressures "
                         "are 1e-5 and 1e-6: the same I then needs sqrt(1e-4/p_ext) times the "
                         "steps)")
    ap.add_argument("--drop", type=float, default=0.1,
                    help="fraction of each run dropped at least (besides the MSER start)")
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--reference", default=None,
                    help="another pressure's OUT (its runs.parquet): print and write "
                         "OUT/shift.parquet, each code's change from it (shift_table)")
    ap.add_argument("--slip", action="store_true",
                    help="print and write OUT/slip.parquet: LAMMPS's material against its "
                         "box's stream at each run's end (box_slip)")
    ap.add_argument("--thin", type=int, default=None,
                    help="keep every K-th sample of the series in OUT not thinned before, "
                         "then build the table (thin_series; for committing low-pressure runs)")
    ap.add_argument("--only-table", action="store_true",
                    help="recompute the table from the series present; run nothing")
    a = ap.parse_args(argv)
    N = a.n  # read by make_cell and point_name
    if not (math.isfinite(a.p_ext) and a.p_ext > 0):
        ap.error(f"--p-ext must be finite and > 0, got {a.p_ext}")
    P_EXT = a.p_ext  # read by make_cell, point_name and build_tables
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.thin is not None:
        if a.thin < 1:
            ap.error(f"--thin must be >= 1, got {a.thin}")
        print(f"thinned {thin_series(out, a.thin)} series: every {a.thin}-th sample kept")
    if not a.only_table:
        for mu_s in a.mu:
            for inertial in a.I:
                for seed in a.seeds:
                    run_one(out, mu_s, inertial, seed, a.steps, a.every, a.tau_p, a.strain)
    runs, table = build_tables(out, a.mu, a.I, a.seeds, a.drop)
    if not runs.is_empty():
        runs.write_parquet(out / "runs.parquet")
        print(f"\nper run (steady part): {out / 'runs.parquet'}")
        cols = ["code", "mu_s", "I", "seed", "t_steady", "t_end", "settled", *QUANTITIES]
        with pl.Config(tbl_rows=200, tbl_cols=20, float_precision=5, tbl_width_chars=200):
            print(runs.select(cols))
    print_table(table)
    if not table.is_empty():
        table.write_parquet(out / "table.parquet")
        print(f"wrote {out / 'table.parquet'}")
    if a.slip:
        slip = box_slip(out)
        if slip.is_empty():
            print("no LAMMPS end state (OUT/lammps/<run>/end.data) to measure the slip on")
        else:
            with pl.Config(tbl_rows=100, tbl_width_chars=200, float_precision=4):
                print(slip)
            slip.write_parquet(out / "slip.parquet")
            print(f"wrote {out / 'slip.parquet'}")
    if a.reference is not None and not runs.is_empty():
        ref = pl.read_parquet(Path(a.reference) / "runs.parquet")
        shift = shift_table(runs, ref)
        if shift.is_empty():
            print(f"no point of {a.reference} matches these runs")
        else:
            print_shift(shift, a.reference)
            shift.write_parquet(out / "shift.parquet")
            print(f"wrote {out / 'shift.parquet'}")


if __name__ == "__main__":
    main()
