"""granflow against LAMMPS 22Jul2025 from the same initial states (issue 6): step-0 forces,
short-run statistics, trajectory divergence, a sheared dense packing, and speed.

    python benchmarks/compare_lammps.py [--quick] [--parts forces run traj shear speed]

Every check builds one state, writes it as a LAMMPS data file (``granflow.io``), and runs the
same steps with the same parameters in both codes; LAMMPS is driven by
``benchmarks/lammps_peer.py`` (its own venv, ``/work/venv-lammps`` or ``$LAMMPS_VENV``).

- forces: contact forces, torques and wall forces at step 0 on a flowing channel state and on a
  dense periodic packing, with omega = 0 and omega != 0, against each other and against a numpy
  reference that implements either code's conventions (lever arm, step-0 slip);
- run: kinetic energy and wall stress of the channel over a short run, block-averaged SEs;
- traj: max position difference against step on the periodic packing, with round-off baselines;
- shear: granflow's stress-controlled cell to steady flow, then LAMMPS ``fix deform xy erate``
  at its shear rate on the same packing (speed, phi, pressure, stress ratio);
- speed: particle-steps/s on the channel workload of the issue (granflow 1 and 2 threads; LAMMPS
  serial, 2 OpenMP threads, 2 MPI ranks) and the ratios.

Prints a table per part and writes benchmarks/out/compare_lammps.json. The flowing channel
state and the packings are cached in benchmarks/out/.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import granflow as gf
import numpy as np
from granflow.analysis.compare import difference_z
from granflow.analysis.stats import blocking, mean_se
from granflow.io import _jsonable, write_lammps_data
from granflow.material import kernel_default_skin
from granflow.packing import dense_periodic_packing
from granflow.scenes.channel import Channel

sys.path.insert(0, str(Path(__file__).parent))
import lammps_peer as lp  # noqa: E402
from state_sim import simulation  # noqa: E402

OUT = Path(__file__).parent / "out"

# the channel workload of issue 6
W, H, B = 20.0, 30.0, 10.0
PHI_BAR = 0.60
KN = 1.0e6
KT = KN * 2.0 / 7.0  # the same double LAMMPS computes for kt = NULL
E_N = 0.82
MU = 0.5
DT = 1.2e-4
SKIN = 0.2
G = 1.0
DENSITY = 1.0
# flow after the release: t = 8.4 reaches the issue's "developed flow" (~0.9 contacts per
# particle; 0.16 at t = 2.4, 0.81 at t = 6; the bed keeps accelerating slowly)
FLOW_STEPS = 70_000

Array = np.ndarray
State = dict[str, Any]


# ----------------------------------------------------------------------------------------------
# states


def channel_state(flow_steps: int = FLOW_STEPS, seed: int = 1, threads: int = 1) -> State:
    """A flowing channel (granflow's Channel: fill and release, then ``flow_steps`` steps of
    flow), cached in benchmarks/out/ so that repeated runs reuse it."""
    OUT.mkdir(exist_ok=True)
    f = OUT / f"channel_W{W:g}_H{H:g}_B{B:g}_seed{seed}_flow{flow_steps}.npz"
    if not f.exists():
        t0 = time.perf_counter()
        ch = Channel(W=W, H=H, B=B, phi_bar=PHI_BAR, kn=KN, e_n=E_N, mu=MU, dt=DT, skin=SKIN,
                     density=DENSITY, seed=seed, threads=threads,
                     preparation="pour")  # the recorded comparison's packing
        ch.prepare(progress=False)
        s = ch.core
        s.run(flow_steps)
        np.savez(f, x=s.positions(), v=s.velocities(), omega=s.angular_velocities(),
                 d=s.diameters(), W=W, H=H, B=B, flow_steps=flow_steps, seed=seed)
        print(f"  prepared the flowing channel (N = {s.n}, t_flow = {flow_steps * DT:g}) in "
              f"{time.perf_counter() - t0:.0f} s -> {f}")
    z = np.load(f)
    return {
        "kind": "channel", "x": z["x"], "v": z["v"], "omega": z["omega"], "d": z["d"],
        "lo": np.zeros(3), "hi": np.array([W, H, B]), "periodic": (False, True, True),
        "walls": [(0.0, 1.0), (W, -1.0)], "file": str(f),
    }  # fmt: skip


def packing_state(n: int, seed: int = 1) -> State:
    """A dense (phi = 0.6) polydisperse periodic packing (same cache as kernel_throughput.py),
    agitated with normal(0, 0.05) velocities as kernel_throughput.py does."""
    OUT.mkdir(exist_ok=True)
    f = OUT / f"packing_{n}_{seed}.npz"
    if not f.exists():
        x, d, box = dense_periodic_packing(gf.sizes.CHANNEL_MIX, n, phi=0.6, seed=seed)
        np.savez(f, x=x, d=d, L=np.asarray(box.length))
    z = np.load(f)
    v = np.random.default_rng(0).normal(0.0, 0.05, size=z["x"].shape)
    return {
        "kind": "packing", "x": z["x"], "v": v, "omega": np.zeros_like(v), "d": z["d"],
        "lo": np.zeros(3), "hi": np.asarray(z["L"], float), "periodic": (True, True, True),
        "walls": [], "file": str(f),
    }  # fmt: skip


def masses(d: Array) -> Array:
    return DENSITY * math.pi / 6.0 * d**3


def gamma_n_workload(d: Array) -> float:
    """LAMMPS's single gamma_n for e_n = 0.82 at the typical m_eff (two spheres of mean mass),
    as lammps_peer's CLI does; granflow uses it as its rate damping xi_n."""
    return lp.gamma_n_from_restitution(E_N, KN, 0.5 * float(np.mean(masses(d))))


def lmp_params(gamma_n: float, **kw: Any) -> dict[str, Any]:
    p = {"kn": KN, "kt": KT, "gamma_n": gamma_n, "gamma_t": 0.5 * gamma_n, "mu": MU, "dt": DT,
         "skin": SKIN, "g": G, "wall_style": "granular"}  # textbook walls (NOTES_lammps.md)
    p.update(kw)
    return p


def gf_sim(st: State, gamma_n: float | None, threads: int = 1, omega: bool = True,
           skin: float = SKIN, dt: float = DT) -> gf.Simulation:
    """granflow on ``st``: rate damping xi_n = gamma_n (the law LAMMPS has), or the workload's
    restitution form e_n if gamma_n is None."""
    if gamma_n is None:
        law = gf.ContactLaw(kn=KN, e_n=E_N, mu=MU, kt=KT, xi_t_ratio=0.5)
    else:
        law = gf.ContactLaw(kn=KN, e_n=None, xi_n=gamma_n, mu=MU, kt=KT, xi_t_ratio=0.5)
    return simulation(st, law, density=DENSITY, dt=dt, skin=skin,
                      gravity=G if st["kind"] == "channel" else None, threads=threads,
                      omega=omega)  # fmt: skip


def data_file(st: State, path: Path, omega: bool = True) -> Path:
    """The hand-off: granflow writes the LAMMPS data file (ids 1..N in granflow's id order)."""
    return write_lammps_data(path, st["x"], st["d"], DENSITY, tuple(st["lo"]), tuple(st["hi"]),
                             velocities=st["v"],
                             omega=st["omega"] if omega else np.zeros_like(st["v"]))


# ----------------------------------------------------------------------------------------------
# step 0: numpy reference with either code's conventions


def reference_step0(st: State, gamma_n: float, conv: str, omega: bool = True) -> dict[str, Any]:
    """Step-0 contact forces, torques and wall forces (force *on* each wall) for the Hooke law with
    rate damping and zero tangential history, O(N^2) in chunks.

    conv 'lammps': lever arm R_i (pairs and walls), a step-0 tangential dashpot force above
    mu |F_n| is set to 0 (LAMMPS rescales only a nonzero history). conv 'granflow': lever arm
    l_i = r R_i/(R_i+R_j) (pairs), the gap (walls), the step-0 force is capped at mu |F_n|.
    Also returns which particles touch a contact that slips at step 0."""
    x, v, d = st["x"], st["v"], st["d"]
    w = st["omega"] if omega else np.zeros_like(v)
    n = len(x)
    rad = 0.5 * d
    m = masses(d)
    L = st["hi"] - st["lo"]
    per = np.asarray(st["periodic"], bool)
    gn, gt = gamma_n, 0.5 * gamma_n
    f = np.zeros((n, 3))
    t = np.zeros((n, 3))
    slip_p = np.zeros(n, bool)
    n_contacts = n_slip = 0

    def law(nv: Array, delta: Array, vrel: Array, meff: Array) -> tuple[Array, Array, Array]:
        vn = np.einsum("ij,ij->i", vrel, nv)
        fn = KN * delta - meff * gn * vn
        ft = -(meff * gt)[:, None] * (vrel - vn[:, None] * nv)
        mag = np.linalg.norm(ft, axis=1)
        lim = MU * np.abs(fn)
        slip = mag > lim
        if conv == "lammps":
            ft[slip] = 0.0
        else:
            ft[slip] *= (lim[slip] / mag[slip])[:, None]
        return fn[:, None] * nv + ft, ft, slip

    for gi, jj, dv, rsq in lp.contact_pairs(x, rad, L, per):
        r = np.sqrt(rsq)
        nv = dv / r[:, None]
        rsum = rad[gi] + rad[jj]
        delta = rsum - r
        meff = m[gi] * m[jj] / (m[gi] + m[jj])
        if conv == "lammps":
            ai, aj = rad[gi], rad[jj]
        else:
            ai, aj = r * rad[gi] / rsum, r * rad[jj] / rsum
        wsum = ai[:, None] * w[gi] + aj[:, None] * w[jj]
        vrel = v[gi] - v[jj] - np.cross(wsum, nv)
        fij, ft, slip = law(nv, delta, vrel, meff)
        np.add.at(f, gi, fij)
        np.add.at(t, gi, -ai[:, None] * np.cross(nv, ft))
        slip_p[gi[slip]] = True
        n_contacts += len(gi)
        n_slip += int(slip.sum())
    wall_f = []
    for pos, sign in st["walls"]:
        gap = sign * (x[:, 0] - pos)
        idx = np.nonzero(gap < rad)[0]
        nv = np.zeros((len(idx), 3))
        nv[:, 0] = sign
        arm = rad[idx] if conv == "lammps" else gap[idx]
        vrel = v[idx] - np.cross(arm[:, None] * w[idx], nv)
        fw, ft, slip = law(nv, rad[idx] - gap[idx], vrel, m[idx])
        np.add.at(f, idx, fw)
        np.add.at(t, idx, -arm[:, None] * np.cross(nv, ft))
        slip_p[idx[slip]] = True
        wall_f.append(-fw.sum(axis=0))
        n_slip += int(slip.sum())
    return {"f": f, "t": t, "wall": np.array(wall_f).reshape(-1, 3), "slip": slip_p,
            "pair_contacts": n_contacts // 2, "slipping_contacts": n_slip}


def _rel(a: Array, b: Array, scale: float, mask: Array | None = None) -> float:
    e = np.linalg.norm(a - b, axis=1)
    if mask is not None:
        e = e[mask]
    return float(e.max(initial=0.0) / scale) if scale > 0 else float("nan")


def forces_case(st: State, gamma_n: float, omega: bool, wd: Path) -> dict[str, Any]:
    """One step-0 comparison: granflow and LAMMPS forces/torques/wall forces plus references."""
    sim = gf_sim(st, gamma_n, omega=omega)
    sim.core.compute_forces()  # the set-up evaluation: no history increment (as LAMMPS's)
    f_gf = sim.get_forces()
    if st["kind"] == "channel":
        f_gf[:, 1] += sim.core.masses() * G  # granflow's force includes gravity m g (-y)
    t_gf = sim.get_torques()
    scene = "channel" if st["kind"] == "channel" else "periodic"
    path = data_file(st, wd / f"{st['kind']}_w{int(omega)}.data", omega=omega)
    r = lp.run(path, lmp_params(gamma_n), 0, scene=scene)
    f_l, t_l = r["f0"], r["t0"]
    ref_g = reference_step0(st, gamma_n, "granflow", omega)
    ref_l = reference_step0(st, gamma_n, "lammps", omega)
    fs = float(np.linalg.norm(f_l, axis=1).max())
    ts = float(np.linalg.norm(t_l, axis=1).max())
    clean = ~ref_l["slip"]
    out: dict[str, Any] = {
        "state": st["kind"], "n": len(f_l), "omega": omega,
        "pair_contacts": ref_l["pair_contacts"], "step0_slipping_contacts":
        ref_l["slipping_contacts"], "particles_touching_step0_slip": int((~clean).sum()),
        "max_force": fs, "max_torque": ts,
        # the headline: per-particle |f_gf - f_lmp| / max |f|
        "force_gf_vs_lmp": _rel(f_gf, f_l, fs),
        "force_gf_vs_lmp_no_step0_slip": _rel(f_gf, f_l, fs, clean),
        # the difference is the one the conventions predict
        "force_diff_minus_predicted": _rel(f_gf - f_l, ref_g["f"] - ref_l["f"], fs),
        "force_gf_vs_ref_gf": _rel(f_gf, ref_g["f"], fs),
        "force_lmp_vs_ref_lmp": _rel(f_l, ref_l["f"], fs),
        "torque_gf_vs_lmp": _rel(t_gf, t_l, ts),
        "torque_gf_vs_lmp_no_step0_slip": _rel(t_gf, t_l, ts, clean),
        "torque_diff_minus_predicted": _rel(t_gf - t_l, ref_g["t"] - ref_l["t"], ts),
        "torque_gf_vs_ref_gf": _rel(t_gf, ref_g["t"], ts),
        "torque_lmp_vs_ref_lmp": _rel(t_l, ref_l["t"], ts),
    }  # fmt: skip
    # torque ratio: with omega = 0 both codes have the same F_t, so the torques differ only by
    # the lever arm, l_i / R_i = r/(R_i+R_j) for pairs and gap/R for walls: 1 - O(overlap/d)
    sel = clean & (np.linalg.norm(t_l, axis=1) > 1e-6 * ts)
    tr = np.einsum("ij,ij->i", t_gf[sel], t_l[sel]) / np.einsum("ij,ij->i", t_l[sel], t_l[sel])
    out["torque_ratio_gf_over_lmp_min_max"] = [float(tr.min(initial=1)), float(tr.max(initial=1))]
    if st["kind"] == "channel":
        wf_gf = np.asarray(sim.core.wall_forces())
        wf_l = -np.array([r["wall_force0"]["lo"], r["wall_force0"]["hi"]])  # force on the wall
        wsc = float(np.abs(wf_l).max())
        out["wall_force_gf"] = wf_gf.tolist()
        out["wall_force_lmp"] = wf_l.tolist()
        out["wall_gf_vs_lmp"] = float(np.abs(wf_gf - wf_l).max() / wsc)
        # the normal component does not see the step-0 slip convention
        out["wall_normal_gf_vs_lmp"] = float(np.abs(wf_gf[:, 0] - wf_l[:, 0]).max() / wsc)
        out["wall_diff_minus_predicted"] = float(
            np.abs((wf_gf - wf_l) - (ref_g["wall"] - ref_l["wall"])).max() / wsc)
    return out


def part_forces(a: argparse.Namespace, wd: Path) -> list[dict[str, Any]]:
    rows = []
    ch = channel_state(a.flow_steps)
    pk = packing_state(a.packing_n)
    for st in (ch, pk):
        gn = gamma_n_workload(st["d"])
        if st["kind"] == "packing":
            # a spinning packing for the lever-arm check (the channel has its flow's spins)
            st = dict(st, omega=np.random.default_rng(1).normal(0.0, 0.1, size=st["v"].shape))
        for omega in (False, True):
            rows.append(forces_case(st, gn, omega, wd))
    print("\n== step-0 forces (relative to max |f| / max |t|; 'pred' = difference minus what "
          "the conventions predict)")
    print(f"{'state':>8} {'omega':>5} {'N':>5} {'slip0':>5} {'f gf-lmp':>9} {'f no-slip':>9} "
          f"{'f pred':>9} {'t gf-lmp':>9} {'t pred':>9} {'gf-ref':>9} {'lmp-ref':>9} "
          f"{'wall':>9} {'wall n':>9} {'wall pred':>9}")
    for r in rows:
        print(f"{r['state']:>8} {int(r['omega']):>5} {r['n']:>5} "
              f"{r['step0_slipping_contacts']:>5} {r['force_gf_vs_lmp']:>9.1e} "
              f"{r['force_gf_vs_lmp_no_step0_slip']:>9.1e} {r['force_diff_minus_predicted']:>9.1e} "
              f"{r['torque_gf_vs_lmp']:>9.1e} {r['torque_diff_minus_predicted']:>9.1e} "
              f"{r['force_gf_vs_ref_gf']:>9.1e} {r['force_lmp_vs_ref_lmp']:>9.1e} "
              f"{r.get('wall_gf_vs_lmp', float('nan')):>9.1e} "
              f"{r.get('wall_normal_gf_vs_lmp', float('nan')):>9.1e} "
              f"{r.get('wall_diff_minus_predicted', float('nan')):>9.1e}")
    return rows


# ----------------------------------------------------------------------------------------------
# a short run: kinetic energy and wall stress in the channel


def part_run(a: argparse.Namespace, wd: Path) -> dict[str, Any]:
    st = channel_state(a.flow_steps)
    gn = gamma_n_workload(st["d"])
    every, steps = a.sample_every, a.run_steps
    sim = gf_sim(st, gn)
    area = H * B
    g: dict[str, list[float]] = {k: [] for k in ("ke_trans", "ke_rot", "lo_xx", "lo_xy",
                                                   "hi_xx", "hi_xy")}

    def sample() -> None:
        e = sim.energies()
        wf = np.asarray(sim.core.wall_forces())  # force of the particles on each wall
        g["ke_trans"].append(e["kinetic_translational"])
        g["ke_rot"].append(e["kinetic_rotational"])
        g["lo_xx"].append(wf[0, 0] / area)
        g["lo_xy"].append(wf[0, 1] / area)
        g["hi_xx"].append(wf[1, 0] / area)
        g["hi_xy"].append(wf[1, 1] / area)

    sim.core.compute_forces()
    sample()
    t0 = time.perf_counter()
    for _ in range(steps // every):
        sim.core.run(every)
        sample()
    t_gf = time.perf_counter() - t0
    path = data_file(st, wd / "channel_run.data")
    r = lp.run(path, lmp_params(gn, thermo_every=every), steps, scene="channel")
    th = r["thermo"]
    lm = {
        "ke_trans": th["ke_trans"], "ke_rot": th["ke_rot"],
        "lo_xx": -th["wall_lo_fx"] / area, "lo_xy": -th["wall_lo_fy"] / area,
        "hi_xx": -th["wall_hi_fx"] / area, "hi_xy": -th["wall_hi_fy"] / area,
    }  # fmt: skip
    out: dict[str, Any] = {"n": len(st["x"]), "steps": steps, "sample_every": every,
                           "gf_seconds": t_gf, "lmp_loop_seconds": r["loop_time_s"],
                           "quantities": {}}
    print(f"\n== channel, {steps} steps from the same state (t = {steps * DT:g}), samples every "
          f"{every} steps, step 0 excluded; SE by block averaging")
    print(f"{'quantity':>9} {'granflow':>12} {'SE':>9} {'LAMMPS':>12} {'SE':>9} {'diff/SE':>8} "
          f"{'max rel. diff, samples 1-10':>27}")
    for k in g:
        a_g, a_l = np.asarray(g[k]), np.asarray(lm[k])
        m_g, m_l = blocking(a_g[1:], every * DT), blocking(a_l[1:], every * DT)
        _, se, z = difference_z(m_g.mean, m_g.se, m_l.mean, m_l.se)
        # samples 1-10 (step 0 differs by the set-up slip convention, see part 'forces')
        early = float(np.max(np.abs(a_g[1:11] - a_l[1:11])) / np.mean(np.abs(a_l[1:11])))
        out["quantities"][k] = {
            "granflow": m_g.mean, "granflow_se": m_g.se, "granflow_converged": m_g.converged,
            "lammps": m_l.mean, "lammps_se": m_l.se, "lammps_converged": m_l.converged,
            "diff_over_se": z, "step0_gf": float(a_g[0]), "step0_lmp": float(a_l[0]),
            "max_rel_diff_samples_1_10": early,
            "series_granflow": a_g.tolist(), "series_lammps": a_l.tolist(),
        }  # fmt: skip
        print(f"{k:>9} {m_g.mean:>12.5g} {m_g.se:>9.2g} {m_l.mean:>12.5g} {m_l.se:>9.2g} "
              f"{z:>8.2f} {early:>27.2e}")
    return out


# ----------------------------------------------------------------------------------------------
# trajectories on the periodic packing


def _read_frames(path: Path) -> dict[int, Array]:
    """A LAMMPS custom dump (id xu yu zu, sorted by id) as {step: (N, 3)}."""
    frames: dict[int, Array] = {}
    lines = path.read_text().splitlines()
    i = 0
    while i < len(lines):
        if lines[i].startswith("ITEM: TIMESTEP"):
            step = int(lines[i + 1])
            n = int(lines[i + 3])
            k = i + 9  # after 'ITEM: ATOMS ...'
            data = np.array([ln.split() for ln in lines[k:k + n]], dtype=np.float64)
            frames[step] = data[np.argsort(data[:, 0]), 1:4]
            i = k + n
        else:
            i += 1
    return frames


def _lmp_traj(path: Path, params: dict[str, Any], steps: int, every: int, mode: str,
              wd: Path) -> dict[int, Array]:
    run_dir = wd / f"traj_{mode}"
    extra = [f"dump traj all custom {every} traj.dump id xu yu zu",
             "dump_modify traj sort id format float %.17g"]
    lp.run(path, dict(params, extra=extra, thermo_every=steps), steps, mode=mode,
           scene="periodic", workdir=run_dir)
    return _read_frames(run_dir / "traj.dump")


def part_traj(a: argparse.Namespace, wd: Path) -> dict[str, Any]:
    """Max position difference against step, from two starts: the agitated packing (a few
    contacts slip at set-up, where the codes differ by convention) and the same packing at rest
    (v = omega = 0: identical step-0 forces, so only the integration differs). The at-rest start
    is repeated at dt/2 (same physical time): a difference of the discretisation halves, a
    round-off-seeded one does not."""
    base = packing_state(a.packing_n)
    gn = gamma_n_workload(base["d"])
    out: dict[str, Any] = {"n": len(base["x"])}
    for start, fac in (("agitated", 1), ("at_rest", 1), ("at_rest_half_dt", 2)):
        steps, every = a.traj_steps * fac, max(1, a.traj_steps // 40) * fac
        dt = DT / fac
        st = base if start == "agitated" else dict(base, v=np.zeros_like(base["v"]))
        path = data_file(st, wd / f"packing_traj_{start}.data")

        def gf_traj(x0: Array, st: State = st, steps: int = steps, every: int = every,
                    dt: float = dt) -> dict[int, Array]:
            sim = gf_sim(dict(st, x=x0), gn, dt=dt)
            fr = {0: sim.core.unwrapped_positions()}
            for k in range(every, steps + 1, every):
                sim.core.run(every)
                fr[k] = sim.core.unwrapped_positions()
            return fr

        g = gf_traj(st["x"])
        lm = _lmp_traj(path, lmp_params(gn, dt=dt), steps, every, "serial", wd)
        baselines = fac == 1
        if baselines:
            # round-off baseline 1: granflow with every coordinate moved by one ulp
            g_ulp = gf_traj(np.nextafter(st["x"], np.inf))
            # round-off baseline 2: LAMMPS on 2 MPI ranks (another summation order)
            lm2 = _lmp_traj(path, lmp_params(gn), steps, every, "mpi", wd)
        rows = []
        for k in sorted(g):
            if k not in lm:
                continue
            row = {"step": k, "time": k * dt, "gf_vs_lmp": float(np.abs(g[k] - lm[k]).max()),
                   "gf_vs_lmp_rms": float(np.sqrt(np.mean((g[k] - lm[k]) ** 2))),
                   "displacement_rms": float(np.sqrt(np.mean((lm[k] - lm[0]) ** 2)))}
            if baselines:
                row["gf_vs_gf_ulp"] = float(np.abs(g[k] - g_ulp[k]).max())
                row["lmp_serial_vs_mpi"] = (float(np.abs(lm[k] - lm2[k]).max()) if k in lm2
                                            else float("nan"))
            rows.append(row)
        out[start] = {"steps": steps, "every": every, "dt": dt, "rows": rows}
        print(f"\n== trajectories, periodic packing N = {len(st['x'])}, start {start}, dt = "
              f"{dt:g}: max |x_a - x_b| (d units)")
        print(f"{'step':>7} {'time':>7} {'gf vs lmp':>10} {'(rms)':>9} {'gf vs gf+1ulp':>14} "
              f"{'lmp ser vs mpi':>15} {'rms displ.':>11}")
        for r in rows[:: max(1, len(rows) // 10)]:
            print(f"{r['step']:>7} {r['time']:>7.4f} {r['gf_vs_lmp']:>10.2e} "
                  f"{r['gf_vs_lmp_rms']:>9.2e} "
                  f"{r.get('gf_vs_gf_ulp', float('nan')):>14.2e} "
                  f"{r.get('lmp_serial_vs_mpi', float('nan')):>15.2e} "
                  f"{r['displacement_rms']:>11.2e}")
        if baselines:
            # growth rate of a one-ulp perturbation while it is small (1e-13 .. 1e-6 d): the
            # chaotic amplification any two codes' round-off differences undergo
            tt = np.array([r["time"] for r in rows])
            ee = np.array([r["gf_vs_gf_ulp"] for r in rows])
            ok = (ee > 1e-13) & (ee < 1e-6)
            if ok.sum() >= 3:
                lam = float(np.polyfit(tt[ok], np.log(ee[ok]), 1)[0])
                out[start]["ulp_growth_rate"] = lam
                print(f"   one-ulp perturbation grows as exp({lam:.0f} t): e-folding time "
                      f"{1 / lam:.3g} = {1 / lam / dt:.0f} steps")
    return out


# ----------------------------------------------------------------------------------------------
# sheared dense packing


def _lammps_box(h: Array, o: Array, x: Array, v: Array) -> dict[str, Any]:
    """granflow's general cell (columns = cell vectors) as a LAMMPS triclinic box: rotate so that
    a is along x and b in the xy plane (QR), reduce the tilts into LAMMPS's limits by a change of
    lattice basis (the same periodic packing), and re-wrap the particles."""
    q, r = np.linalg.qr(h)
    sg = np.sign(np.diag(r))
    q, r = q * sg, sg[:, None] * r  # positive diagonal
    a_, b_, c_ = r[:, 0].copy(), r[:, 1].copy(), r[:, 2].copy()
    c_ -= round(c_[1] / b_[1]) * b_
    c_ -= round(c_[0] / a_[0]) * a_
    b_ -= round(b_[0] / a_[0]) * a_
    hl = np.column_stack([a_, b_, c_])
    xl = (x - o) @ q  # rotate: x_L = Q^T (x - o)
    s = np.linalg.solve(hl, xl.T).T
    s -= np.floor(s)
    return {"x": s @ hl.T, "v": v @ q, "hi": np.diag(hl).copy(),
            "tilt": np.array([hl[0, 1], hl[0, 2], hl[1, 2]])}


def part_shear(a: argparse.Namespace, wd: Path) -> dict[str, Any]:
    from granflow.scenes.cell import ShearCell

    n, steps = a.cell_n, a.cell_steps
    cell = ShearCell(N=n, mu=0.3, p_ext=1e-4, tau_ratio=0.5, seed=1, threads=1)
    t0 = time.perf_counter()
    cell.run(steps, progress=False)
    t_prep = time.perf_counter() - t0
    # granflow's speed on this workload: a timed stretch of the steady flow
    core = cell.core
    t0 = time.perf_counter()
    core.run(a.shear_steps)
    gf_rate = core.n * a.shear_steps / (time.perf_counter() - t0)
    s = cell.tables()["series"].to_pydict()
    half = len(s["t"]) // 2
    dts = cell.sample_every * core.dt

    def stat(col: str) -> tuple[float, float]:
        m = mean_se(np.asarray(s[col][half:]), dts)
        return m.value, m.se

    def invariants(sig: Array) -> tuple[float, float]:
        p = float(np.trace(sig) / 3.0)
        dev = sig - p * np.eye(3)
        return p, float(np.sqrt(0.5 * np.sum(dev * dev)))

    sc = np.array([[np.mean(s[f"sigma_c_{i}{j}"][half:]) for j in "xyz"] for i in "xyz"])
    p_c, tau_c = invariants(0.5 * (sc + sc.T))
    gd, gd_se = stat("shear_rate")
    phi, phi_se = stat("phi")
    rate = 2.0 * gd  # simple shear with the same |D|: sqrt(D:D/2) = rate/2
    h, o = (np.asarray(z) for z in core.cell())
    box = _lammps_box(h, o, core.positions(), core.velocities())
    d = core.diameters()
    st = lp.state_from_arrays(box["x"], d, np.zeros(3), box["hi"], density=1.0, v=box["v"],
                              omega=core.angular_velocities(), tilt=box["tilt"])
    phi_now = float(np.sum(np.pi / 6 * d**3) / abs(np.linalg.det(h)))
    gamma_n = 0.5 / cell.t_c  # the cell's law: kn = kt, xi_n = 0.5/t_c, xi_t = xi_n/2, mu
    kn = cell.mat.kn_value
    params = {"kn": kn, "kt": kn, "gamma_n": gamma_n, "gamma_t": 0.5 * gamma_n,
              "mu": cell.mat.mu_value, "dt": core.dt, "skin": kernel_default_skin(),
              "shear_rate": rate,
              "add_streaming": True, "thermo_every": a.shear_steps}
    every = max(1, a.shear_steps // 100)
    params["extra"] = [
        "compute pv all pressure NULL virial",  # contact (pair virial) stress only
        f"fix pvout all ave/time {every} 1 {every} c_pv[1] c_pv[2] c_pv[3] c_pv[4] c_pv[5] "
        "c_pv[6] file pv.txt",
    ]
    run_dir = wd / "sheared"
    r = lp.run(st, params, a.shear_steps, scene="sheared", workdir=run_dir)
    pv = np.loadtxt(run_dir / "pv.txt", comments="#")
    pv = pv[len(pv) // 2:, 1:]  # second half of the run; columns xx yy zz xy xz yz
    pt = np.array([[pv[:, 0], pv[:, 3], pv[:, 4]], [pv[:, 3], pv[:, 1], pv[:, 5]],
                   [pv[:, 4], pv[:, 5], pv[:, 2]]])
    p_l, tau_l = invariants(pt.mean(axis=2))
    p_ser = mean_se(pt[0, 0] / 3 + pt[1, 1] / 3 + pt[2, 2] / 3, every * core.dt)

    def ratio_se(series: Array, dt_sample: float) -> float:
        """SE (block averaging) of tau/p from a (samples, 3, 3) stress series: the SE of the
        per-sample ratio, which the ratio of the means shares to first order."""
        r = [(lambda pq: pq[1] / pq[0])(invariants(0.5 * (m + m.T))) for m in series]
        return mean_se(np.asarray(r), dt_sample).se

    gf_series = np.stack([[np.asarray(s[f"sigma_c_{i}{j}"][half:]) for j in "xyz"]
                          for i in "xyz"]).transpose(2, 0, 1)
    gf_ratio_se = ratio_se(gf_series, dts)
    lmp_ratio_se = ratio_se(pt.transpose(2, 0, 1), every * core.dt)
    out = {
        "n": core.n, "cell_steps": steps, "cell_prep_seconds": t_prep,
        "shear_steps": a.shear_steps, "strain_lammps": rate * a.shear_steps * core.dt,
        "gf_shear_rate_gd": gd, "gf_shear_rate_gd_se": gd_se, "lammps_erate": rate,
        "gf_phi": phi, "gf_phi_se": phi_se, "phi_handoff": phi_now,
        "gf_p_c": p_c, "gf_tau_c_over_p_c": tau_c / p_c,
        "gf_tau_c_over_p_c_se": gf_ratio_se,
        "lmp_p_c": p_l, "lmp_p_c_se": p_ser.se, "lmp_tau_c_over_p_c": tau_l / p_l,
        "lmp_tau_c_over_p_c_se": lmp_ratio_se,
        "gf_particle_steps_per_s": gf_rate, "lmp_particle_steps_per_s": r["particle_steps_per_s"],
        "gf_state": cell.summary().get("state"),
    }  # fmt: skip
    print(f"\n== sheared dense packing, N = {core.n}: granflow stress-controlled cell "
          f"({steps} steps, state {out['gf_state']}), then LAMMPS fix deform xy erate "
          f"{rate:.4g} for {a.shear_steps} steps (strain {out['strain_lammps']:.2f})")
    print(f"{'':>10} {'phi':>8} {'p_c':>10} {'tau_c/p_c':>9} {'SE':>7} {'p-steps/s':>10}")
    print(f"{'granflow':>10} {phi:>8.4f} {p_c:>10.3e} {tau_c / p_c:>9.3f} {gf_ratio_se:>7.3f} "
          f"{gf_rate:>10.3e}")
    print(f"{'LAMMPS':>10} {phi_now:>8.4f} {p_l:>10.3e} {tau_l / p_l:>9.3f} {lmp_ratio_se:>7.3f} "
          f"{r['particle_steps_per_s']:>10.3e}")
    diff = tau_c / p_c - tau_l / p_l
    print(f"  tau/p difference {diff:+.3f} = {diff / np.hypot(gf_ratio_se, lmp_ratio_se):+.1f} "
          "combined SE")
    out["speed"] = _shear_speed(a, core, st, params)
    return out


def _shear_speed(a: argparse.Namespace, core: Any, st: dict[str, Any],
                 params: dict[str, Any]) -> dict[str, Any]:
    """Speed on the sheared packing, as on the channel: granflow's cell going on from its
    steady state at 1 and 2 threads, LAMMPS's ``fix deform`` on the packing handed over (serial,
    2 OpenMP threads, 2 MPI ranks), ``--shear-speed-steps`` each, ``--repeat`` interleaved
    rounds (``_timed_rounds``). Not like for like in granflow's disfavour: the cell integrates
    the Parrinello-Rahman cell dynamics (virial and kinetic stress every step), LAMMPS a
    prescribed deformation."""
    steps = a.shear_speed_steps
    params = {**params, "thermo_every": steps}
    params.pop("extra", None)

    def gf_rate(threads: int) -> float:
        core.threads = threads
        core.run(1)  # pool and team set-up outside the timing
        t0 = time.perf_counter()
        core.run(steps)
        rate = core.n * steps / (time.perf_counter() - t0)
        core.threads = 1
        return rate

    configs: list[tuple[str, str, Any]] = [
        ("granflow", f"{t} thread(s)", lambda t=t: gf_rate(t)) for t in (1, 2)]
    for mode, threads, label in LMP_MODES:
        def lmp_rate(m: str = mode, t: int = threads) -> float:
            r = lp.run(st, params, steps, mode=m, threads=t, scene="sheared",
                       env={"OMP_WAIT_POLICY": a.omp_wait_policy})
            return float(r["particle_steps_per_s"])

        configs.append(("LAMMPS", label, lmp_rate))
    rows = _timed_rounds(configs, a.repeat)
    ratios = _speed_table(f"sheared packing N = {core.n}, {steps} steps ({a.repeat} interleaved "
                          "rounds; "
                          "LAMMPS: Loop time; granflow: run() wall time)", rows,
                          "1 thread(s)", "2 thread(s)")
    return {"steps": steps, "repeat": a.repeat, "rows": rows, "ratios": ratios}


# LAMMPS's configurations in the speed tables: (mode, OpenMP threads, label)
LMP_MODES = (("serial", 1, "serial"), ("omp", 2, "2 OpenMP threads"), ("mpi", 1, "2 MPI ranks"))


def _timed_rounds(configs: list[tuple[str, str, Any]], repeat: int) -> list[dict[str, Any]]:
    """Time every configuration ``(code, mode, fn)`` once per round, ``repeat`` rounds, the
    configurations interleaved within a round: this VM's speed drifts by 5-10 % (and a second
    core's by up to 40 %) over minutes, and interleaving spreads a slow spell over all
    configurations instead of charging it to whichever ran then. Each row keeps every
    round's rate (``rates``) and its best (``rate``)."""
    from granflow import _core

    rates: list[list[float]] = [[] for _ in configs]
    # the cores' cache-line round trip just before each run (`granflow.probe`): 3-4x higher
    # when the VM's two cores are placed far apart, and two threads then run far slower
    # (NOTES.md, eighth session)
    trips: list[list[float]] = [[] for _ in configs]
    for _ in range(repeat):
        for k, (_, _, fn) in enumerate(configs):
            trips[k].append(_core.core_round_trip_ns(100_000))
            rates[k].append(float(fn()))
    return [{"code": c, "mode": m, "rate": max(r), "median": float(np.median(r)), "rates": r,
             "round_trip_ns": t}
            for (c, m, _), r, t in zip(configs, rates, trips, strict=True)]


def _speed_table(title: str, rows: list[dict[str, Any]], gf1: str,
                 gf2: str) -> dict[str, float]:
    """Print a speed table (granflow's rows ``gf1``/``gf2`` at 1 and 2 threads, LAMMPS's in
    ``LMP_MODES``) and return the ratios: of the best rates, and the median over rounds of
    each round's ratio (the two codes timed minutes apart at most, ``_timed_rounds``)."""
    by = {(r["code"], r["mode"]): r for r in rows}
    g1, g2 = by[("granflow", gf1)], by[("granflow", gf2)]
    ser = by[("LAMMPS", "serial")]
    omp, mpi = by[("LAMMPS", "2 OpenMP threads")], by[("LAMMPS", "2 MPI ranks")]

    def paired(a: list[float], b: list[float]) -> float:
        return float(np.median(np.asarray(a) / np.asarray(b)))

    best2 = [max(o, m) for o, m in zip(omp["rates"], mpi["rates"], strict=True)]
    ratios = {"gf1/lmp_serial": g1["rate"] / ser["rate"], "gf2/lmp_omp2": g2["rate"] / omp["rate"],
              "gf2/lmp_mpi2": g2["rate"] / mpi["rate"],
              "gf2/best_lmp_2core": g2["rate"] / max(omp["rate"], mpi["rate"]),
              "gf2/gf1": g2["rate"] / g1["rate"]}
    per_round = {"gf1/lmp_serial": paired(g1["rates"], ser["rates"]),
                 "gf2/lmp_omp2": paired(g2["rates"], omp["rates"]),
                 "gf2/lmp_mpi2": paired(g2["rates"], mpi["rates"]),
                 "gf2/best_lmp_2core": paired(g2["rates"], best2),
                 "gf2/gf1": paired(g2["rates"], g1["rates"])}
    print(f"\n== speed, {title}")
    print(f"{'':>9} {'':>28} {'best':>11} {'median':>11}   every round")
    for r in rows:
        each = " ".join(f"{x:.3e}" for x in r["rates"])
        print(f"{r['code']:>9} {r['mode']:>28} {r['rate']:>11.3e} {r['median']:>11.3e}   {each}")
    print("cross-core round trip before each run, ns (3-4x higher when the cores are far apart):")
    for r in rows:
        each = " ".join(f"{x:9.0f}" for x in r["round_trip_ns"])
        print(f"{r['code']:>9} {r['mode']:>28} {'':>23}   {each}")
    print(f"{'ratio':>20} {'of best':>8} {'median of rounds':>17}")
    for k, v in ratios.items():
        print(f"{k:>20} {v:8.2f} {per_round[k]:17.2f}")
    return {**ratios, **{f"{k} (median of rounds)": v for k, v in per_round.items()}}


# ----------------------------------------------------------------------------------------------
# speed on the channel workload


def part_speed(a: argparse.Namespace, wd: Path) -> dict[str, Any]:
    st = channel_state(a.flow_steps)
    n = len(st["x"])
    steps = a.speed_steps
    gn = gamma_n_workload(st["d"])
    info: dict[str, Any] = {}

    def gf_rate(threads: int, damping: str) -> float:
        sim = gf_sim(st, None if damping == "e_n" else gn, threads=threads)
        sim.core.compute_forces()  # set-up outside the timing, as LAMMPS's Loop time
        t0 = time.perf_counter()
        sim.core.run(steps)
        rate = n * steps / (time.perf_counter() - t0)
        info["gf_contacts_per_particle_end"] = sim.diagnostics()["contacts"] / n
        return rate

    configs: list[tuple[str, str, Any]] = [
        ("granflow", f"{t} thread(s), {dm} damping", lambda t=t, dm=dm: gf_rate(t, dm))
        for t, dm in ((1, "e_n"), (2, "e_n"), (1, "xi_n"))]
    path = data_file(st, wd / "channel_speed.data")
    for mode, threads, label in LMP_MODES:
        def lmp_rate(m: str = mode, t: int = threads) -> float:
            r = lp.run(path, lmp_params(gn, thermo_every=steps), steps, mode=m, threads=t,
                       scene="channel", env={"OMP_WAIT_POLICY": a.omp_wait_policy})
            info["lmp_neighbor_builds"] = r["neighbor_builds"]
            info["lmp_ave_neighs_per_atom"] = r["ave_neighs_per_atom"]
            return float(r["particle_steps_per_s"])

        configs.append(("LAMMPS", label, lmp_rate))
    rows = _timed_rounds(configs, a.repeat)
    ratios = _speed_table(f"channel workload N = {n}, {steps} steps ({a.repeat} "
                          "interleaved rounds; LAMMPS: Loop time; granflow: run() wall time "
                          "after the set-up evaluation)", rows, "1 thread(s), e_n damping",
                          "2 thread(s), e_n damping")
    print(f"  workload: {info.get('gf_contacts_per_particle_end', 0):.2f} contacts per particle "
          f"(granflow, end), LAMMPS {info.get('lmp_ave_neighs_per_atom')} neighbours per atom, "
          f"{info.get('lmp_neighbor_builds')} rebuilds in {steps} steps")
    return {"n": n, "steps": steps, "repeat": a.repeat, "rows": rows, "ratios": ratios, **info}


# ----------------------------------------------------------------------------------------------


PARTS = ("forces", "run", "traj", "shear", "speed")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small and fast version of every part")
    ap.add_argument("--parts", nargs="+", default=list(PARTS),
                    help=f"parts to run, comma- or space-separated, of {PARTS}")
    ap.add_argument("--flow-steps", type=int, default=FLOW_STEPS,
                    help="flow steps after the channel's fill and release (cached state)")
    ap.add_argument("--packing-n", type=int, default=None, help="periodic packing size")
    ap.add_argument("--run-steps", type=int, default=None)
    ap.add_argument("--sample-every", type=int, default=50)
    ap.add_argument("--traj-steps", type=int, default=None)
    ap.add_argument("--cell-n", type=int, default=None)
    ap.add_argument("--cell-steps", type=int, default=None, help="granflow cell run to steady flow")
    ap.add_argument("--shear-steps", type=int, default=None, help="steps of the sheared runs")
    ap.add_argument("--speed-steps", type=int, default=None)
    ap.add_argument("--shear-speed-steps", type=int, default=None,
                    help="steps of each timed run on the sheared packing")
    ap.add_argument("--repeat", type=int, default=1, help="speed: best of REPEAT runs")
    ap.add_argument("--omp-wait-policy", default="PASSIVE", choices=["PASSIVE", "ACTIVE"],
                    help="LAMMPS OpenMP threads; PASSIVE survives a loaded machine")
    ap.add_argument("--out", default=str(OUT / "compare_lammps.json"))
    a = ap.parse_args(argv)
    q = a.quick
    defaults = {"packing_n": (2000, 5000), "run_steps": (2000, 5000), "traj_steps": (1000, 3000),
                "cell_n": (500, 2000), "cell_steps": (60_000, 150_000),
                "shear_steps": (20_000, 100_000), "speed_steps": (2000, 20_000),
                "shear_speed_steps": (5000, 20_000)}
    for k, (small, full) in defaults.items():
        if getattr(a, k) is None:
            setattr(a, k, small if q else full)
    parts = [p.strip() for arg in a.parts for p in arg.split(",") if p.strip()]
    bad = set(parts) - set(PARTS)
    if bad:
        ap.error(f"unknown parts {sorted(bad)}: allowed {PARTS}")
    result: dict[str, Any] = {"args": vars(a), "lammps": lp.lammps_env()["lmp"],
                              "granflow": gf.__version__}
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if out.exists():  # keep the parts not rerun
        try:
            result = {**json.loads(out.read_text()), **result}
        except json.JSONDecodeError:
            pass
    with tempfile.TemporaryDirectory(prefix="compare_lammps_") as tmp:
        wd = Path(tmp)
        for p in parts:
            t0 = time.perf_counter()
            result[p] = globals()[f"part_{p}"](a, wd)
            result[p + "_seconds"] = time.perf_counter() - t0
            out.write_text(json.dumps(_jsonable(result), indent=1))
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
