"""Study throughput with statistics (issue 20): what a user pays for the scenes' sampling.

    python benchmarks/study_throughput.py [--quick] [--rounds R] [--steps S] \
        [--parts channel cell] [--threads 1 2]

Measures particle-steps per second (N * steps / wall seconds) of the scenes *with* their
statistics against the bare kernel, and, for the channel, against LAMMPS 22Jul2025 computing
comparable statistics on the same state:

- channel: one developed W = 20 channel (W = 20, H = 30, B = 10, phi_bar 0.6, ~6,750 particles,
  kn = 1e5, kt = 2/7 kn, e_n 0.82, mu 0.5, dt = the Channel default 1.2e-4 scaled to kn = 1e5,
  i.e. 1.2e-4 sqrt(10); gravity -y, walls at x = 0 and x = W, periodic y and z) is developed once
  (fill and release, then ``--flow-steps`` steps of flow; cached in benchmarks/out/) and the same
  positions, velocities, spins and diameters go to both codes.
  granflow: a fresh ``Channel(..., bin_width=1, wall_bin=1, sample_every=k, window=w)`` made from
  the state with ``Channel._release`` + ``set_velocities``/``set_angular_velocities``; timed
  ``scene.run(steps)`` followed by ``scene.tables()`` (the sampling and the Arrow tables a user
  pays); "none" = the same with ``sample_every=None`` (no samplers: the bare kernel). The
  set-up force evaluation is outside the timing, as LAMMPS's Loop time excludes its setup.
  LAMMPS (``benchmarks/lammps_peer.py``, scene 'channel', the law of
  ``compare_lammps.lmp_params`` with kn = 1e5 and gamma_n from e_n at the mean pair's m_eff, the
  same skin as granflow's): for statistics every k steps ``compute chunk/atom bin/1d x lower 1.0``
  (the same 20 bins), ``compute stress/atom``, ``fix ave/chunk k w k*w`` of density/mass, vx vy
  vz, spin, the six stress components and temp (``ave one``, to a file), and a ``fix ave/time k 1
  k`` series (kinetic and rotational energy, both walls' forces, centre-of-mass velocity) to a
  file; "none" = no computes beyond the runner's thermo at the ends. Rate from its Loop time.
  1 granflow thread against LAMMPS serial, 2 threads against 2 MPI ranks.
- cell: ``ShearCell(N=2000, seed=1, sample_every=k)`` brought to steady dense flow once
  (``--cell-dev-steps``, cached as a checkpoint), then, from that checkpoint each time,
  ``scene.run(steps)`` + ``scene.tables()`` with observables every 10 and every 250 steps against
  ``sample_every=None``; granflow only.

The configurations are timed in ``--rounds`` interleaved rounds (granflow and LAMMPS alternating,
the order swapped every round: this VM's speed drifts over minutes); the tables give the best of
the rounds and every round's value. The checks the issue is judged on are printed as PASS/FAIL:
channel with statistics every 10 steps >= 2x LAMMPS with the same statistics (1 thread vs serial,
2 threads vs 2 ranks), granflow's channel sampling every 10 steps <= 10 % of the bare step, the
cell's observables every 10 steps <= 15 %. Writes benchmarks/out/study_throughput.json.
"""

from __future__ import annotations

import os

# numpy's OpenBLAS threads spin after each call; on two cores they take the second core from
# granflow's second thread (set before numpy is imported)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys
import tempfile
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import Any

import granflow as gf
import numpy as np
from granflow.io import _jsonable
from granflow.material import MATERIAL_000, kernel_default_skin
from granflow.scenes.cell import ShearCell
from granflow.scenes.channel import Channel

sys.path.insert(0, str(Path(__file__).parent))
import compare_lammps as cl  # noqa: E402
import lammps_peer as lp  # noqa: E402

OUT = Path(__file__).parent / "out"

# the channel workload of issue 20
W, H, B = 20.0, 30.0, 10.0
KN = 1.0e5
KT = KN * 2.0 / 7.0
E_N = 0.82
MU = 0.5
DT = float(MATERIAL_000.with_(kn=KN).dt() or 0.0)  # the channel's dt rule at this kn
SKIN = kernel_default_skin()  # the kernel's default, used by both codes
SEED = 1
FLOW_STEPS = 22_000  # t = 8.3, the flow time of compare_lammps's developed state
# statistics intervals (None = none); a window (ave/chunk Nrepeat) spans WINDOW_STEPS steps
CHANNEL_EVERY: tuple[int | None, ...] = (None, 100, 10, 1)
CELL_N = 2000
CELL_DEV_STEPS = 250_000  # dilute start -> steady dense flow (phi 0.564, I 0.12: "flowing")
CELL_EVERY: tuple[int | None, ...] = (None, 250, 10)
# (LAMMPS run mode, its label) paired with the granflow thread count
LMP_FOR_THREADS = {1: ("serial", "serial"), 2: ("mpi", "2 MPI ranks")}

State = dict[str, Any]
Config = tuple[str, str, Callable[[], float]]


def _label(every: int | None) -> str:
    if every is None:
        return "none"
    return "every step" if every == 1 else f"every {every} steps"


# ----------------------------------------------------------------------------------------------
# the channel


def make_channel(every: int | None, window: int, threads: int) -> Channel:
    # k_t: the kernel's default 2/7 kn (one ulp from LAMMPS's KT = KN * 2 / 7 at kn = 1e5)
    return Channel(W=W, H=H, B=B, phi_bar=0.6, kn=KN, e_n=E_N, mu=MU, dt=DT, skin=SKIN,
                   seed=SEED, bin_width=1.0, wall_bin=1.0, sample_every=every,
                   window=window, threads=threads,
                   preparation="pour")  # the recorded throughput's packing


def channel_state(flow_steps: int) -> State:
    """The developed channel (fill and release, then ``flow_steps`` steps of flow at kn = 1e5),
    cached in benchmarks/out/; shaped as compare_lammps's states (``data_file`` takes it)."""
    OUT.mkdir(exist_ok=True)
    f = OUT / f"study_channel_W{W:g}_H{H:g}_B{B:g}_kn{KN:g}_seed{SEED}_flow{flow_steps}.npz"
    if not f.exists():
        t0 = time.perf_counter()
        ch = make_channel(100, 50, threads=2)
        ch.prepare(progress=False)
        t_prep = time.perf_counter() - t0
        s = ch.core
        s.run(flow_steps)
        np.savez(f, x=s.positions(), v=s.velocities(), omega=s.angular_velocities(),
                 d=s.diameters(), flow_steps=flow_steps, dt=DT, kn=KN, seed=SEED,
                 prep=json.dumps(ch.prep_info), contacts=s.diagnostics()["contacts"])
        print(f"  developed the channel (N = {s.n}, prepare {t_prep:.0f} s, then {flow_steps} "
              f"steps, t_flow = {flow_steps * DT:.3g}) in {time.perf_counter() - t0:.0f} s -> {f}")
    z = np.load(f)
    return {
        "kind": "channel", "x": z["x"], "v": z["v"], "omega": z["omega"], "d": z["d"],
        "lo": np.zeros(3), "hi": np.array([W, H, B]), "periodic": (False, True, True),
        "walls": [(0.0, 1.0), (W, -1.0)], "file": str(f), "prep": json.loads(str(z["prep"])),
        "contacts_per_particle": float(z["contacts"]) / len(z["x"]),
        "vy_mean": float(np.mean(z["v"][:, 1])),
    }  # fmt: skip


def channel_scene(st: State, every: int | None, window: int, threads: int) -> Channel:
    """A fresh Channel with the wanted sampling, started from the state ``st``."""
    sc = make_channel(every, window, threads)
    sc._release(np.array(st["x"]), np.array(st["d"]), dict(st["prep"]))
    sc.core.set_velocities(np.ascontiguousarray(st["v"], dtype=np.float64))
    sc.core.set_angular_velocities(np.ascontiguousarray(st["omega"], dtype=np.float64))
    return sc


def gf_channel_rate(st: State, every: int | None, window: int, steps: int, threads: int,
                    info: dict[str, Any]) -> float:
    sc = channel_scene(st, every, window, threads)
    core = sc.core
    core.compute_forces()  # the set-up evaluation outside the timing (LAMMPS: setup)
    t0 = time.perf_counter()
    sc.run(steps, progress=False)
    tabs = sc.tables()
    rate = core.n * steps / (time.perf_counter() - t0)
    info[f"gf_{_label(every)}_rows"] = {k: t.num_rows for k, t in tabs.items()}
    return rate


def lammps_stats_lines(every: int, window: int) -> list[str]:
    """The LAMMPS statistics for an interval of ``every`` steps (inserted before ``run 0``;
    ``c_ket``, ``c_erot`` and ``c_wsum`` are the runner's channel computes)."""
    stress = " ".join(f"c_sa[{k}]" for k in range(1, 7))
    wall = " ".join(f"c_wsum[{k}]" for k in range(1, 9))
    return [
        "compute cc all chunk/atom bin/1d x lower 1.0 units box",
        "compute sa all stress/atom NULL",
        "compute spin all property/atom omegax omegay omegaz",
        f"fix bins all ave/chunk {every} {window} {every * window} cc density/mass vx vy vz "
        f"c_spin[1] c_spin[2] c_spin[3] {stress} temp ave one file bins.txt",
        "variable vcx equal vcm(all,x)",
        "variable vcy equal vcm(all,y)",
        "variable vcz equal vcm(all,z)",
        f"fix series all ave/time {every} 1 {every} c_ket c_erot {wall} v_vcx v_vcy v_vcz "
        "file series.txt",
    ]


def _lines(path: Path) -> int:
    if not path.exists():
        return 0
    return sum(1 for ln in path.read_text().splitlines() if ln and not ln.startswith("#"))


def lmp_channel_rate(data: Path, gamma_n: float, every: int | None, window: int, steps: int,
                     mode: str, wd: Path, info: dict[str, Any]) -> float:
    extra = [] if every is None else lammps_stats_lines(every, window)
    params = cl.lmp_params(gamma_n, kn=KN, kt=KT, dt=DT, skin=SKIN, thermo_every=steps,
                           extra=extra)
    run_dir = wd / f"lmp_{mode}_{every}"
    r = lp.run(data, params, steps, mode=mode, scene="channel", workdir=run_dir,
               env={"OMP_WAIT_POLICY": "PASSIVE"})
    if every is not None:
        info[f"lmp_{mode}_{_label(every)}_output_lines"] = {
            "bins.txt": _lines(run_dir / "bins.txt"), "series.txt": _lines(run_dir / "series.txt")}
        info["lmp_stats_input"] = extra
    info["lmp_neighbor_builds"] = r["neighbor_builds"]
    info["lmp_ave_neighs_per_atom"] = r["ave_neighs_per_atom"]
    return float(r["particle_steps_per_s"])


# ----------------------------------------------------------------------------------------------
# interleaved rounds


def interleaved(pairs: list[list[Config]], rounds: int) -> list[dict[str, Any]]:
    """Time every configuration once per round, ``rounds`` rounds; within a round the groups in
    ``pairs`` (e.g. granflow and LAMMPS at one setting) run one after the other, their order
    reversed every other round. Each round is one ``compare_lammps._timed_rounds`` pass."""
    flat = [c for grp in pairs for c in grp]
    rows: list[dict[str, Any]] = [
        {"code": c, "mode": m, "rates": [], "round_trip_ns": []} for c, m, _ in flat]
    index = {(c, m): k for k, (c, m, _) in enumerate(flat)}
    for r in range(rounds):
        order = [c for grp in pairs for c in (grp if r % 2 == 0 else grp[::-1])]
        for row in cl._timed_rounds(order, 1):
            k = index[(row["code"], row["mode"])]
            rows[k]["rates"] += row["rates"]
            rows[k]["round_trip_ns"] += row["round_trip_ns"]
        print(f"  round {r + 1}/{rounds} done", flush=True)
    for row in rows:
        row["rate"] = max(row["rates"])
        row["median"] = float(np.median(row["rates"]))
    return rows


def _fmt_all(rates: list[float]) -> str:
    return ", ".join(f"{x:.3g}" for x in rates)


# ----------------------------------------------------------------------------------------------
# parts


def _steps_for(every: int | None, steps: int, window_steps: int) -> int:
    """Statistics every step cost ~10x more: a tenth of the steps (whole windows)."""
    if every == 1:
        return max(window_steps, (steps // 10) // window_steps * window_steps)
    return steps


def part_channel(a: argparse.Namespace, wd: Path) -> dict[str, Any]:
    st = channel_state(a.flow_steps)
    n = len(st["x"])
    m_eff = 0.5 * float(np.mean(cl.masses(st["d"])))
    gamma_n = lp.gamma_n_from_restitution(E_N, KN, m_eff)
    data = cl.data_file(st, wd / "channel_state.data")
    info: dict[str, Any] = {}
    pairs: list[list[Config]] = []
    windows: dict[str, int] = {}
    for t in a.threads:
        mode, lmp_label = LMP_FOR_THREADS[t]
        for every in CHANNEL_EVERY:
            window = max(1, a.window_steps // every) if every else 1
            steps = _steps_for(every, a.steps, a.window_steps)
            windows[_label(every)] = window

            def g(e: int | None = every, w: int = window, s: int = steps, t: int = t) -> float:
                return gf_channel_rate(st, e, w, s, t, info)

            def lm(e: int | None = every, w: int = window, s: int = steps,
                   m: str = mode) -> float:
                return lmp_channel_rate(data, gamma_n, e, w, s, m, wd, info)

            pairs.append([("granflow", f"{t} thread(s), {_label(every)}, {steps} steps", g),
                          ("LAMMPS", f"{lmp_label}, {_label(every)}, {steps} steps", lm)])
    print(f"\n== channel, N = {n} ({st['contacts_per_particle']:.2f} contacts per particle, "
          f"<v_y> = {st['vy_mean']:.3g}), kn = {KN:g}, dt = {DT:.4g}, skin {SKIN:g}; "
          f"{a.rounds} interleaved rounds", flush=True)
    rows = interleaved(pairs, a.rounds)
    tables: dict[str, Any] = {}
    for t in a.threads:
        mode, lmp_label = LMP_FOR_THREADS[t]
        tab = []
        for every in CHANNEL_EVERY:
            gr = next(r for r in rows if r["code"] == "granflow"
                      and r["mode"].startswith(f"{t} thread(s), {_label(every)},"))
            lr = next(r for r in rows if r["code"] == "LAMMPS"
                      and r["mode"].startswith(f"{lmp_label}, {_label(every)},"))
            tab.append({"statistics": _label(every), "every": every,
                        "steps": _steps_for(every, a.steps, a.window_steps),
                        "window": windows[_label(every)], "granflow": gr["rate"],
                        "granflow_rates": gr["rates"], "lammps": lr["rate"],
                        "lammps_rates": lr["rates"], "ratio": gr["rate"] / lr["rate"],
                        "ratio_per_round": [x / y for x, y in
                                            zip(gr["rates"], lr["rates"], strict=True)]})
        none = tab[0]
        for row in tab:
            row["granflow_over_none"] = row["granflow"] / none["granflow"]
            row["lammps_over_none"] = row["lammps"] / none["lammps"]
        tables[f"{t} thread(s) vs LAMMPS {lmp_label}"] = tab
        print(f"\n### granflow {t} thread(s) vs LAMMPS {lmp_label} (best of {a.rounds}; "
              "particle-steps/s)\n")
        print("| statistics | granflow | LAMMPS | granflow / LAMMPS | granflow / none "
              "| LAMMPS / none |")
        print("|---|---|---|---|---|---|")
        for r in tab:
            print(f"| {r['statistics']} | {r['granflow']:.3g} | {r['lammps']:.3g} | "
                  f"{r['ratio']:.2f} | {r['granflow_over_none']:.2f} | "
                  f"{r['lammps_over_none']:.2f} |")
        print("\nevery round:")
        for r in tab:
            print(f"  {r['statistics']:>16}: granflow {_fmt_all(r['granflow_rates'])}; LAMMPS "
                  f"{_fmt_all(r['lammps_rates'])}; ratio "
                  f"{', '.join(f'{x:.2f}' for x in r['ratio_per_round'])}")
    return {"n": n, "kn": KN, "dt": DT, "skin": SKIN, "gamma_n_lammps": gamma_n,
            "flow_steps": a.flow_steps, "state_file": st["file"],
            "contacts_per_particle": st["contacts_per_particle"], "steps": a.steps,
            "window_steps": a.window_steps, "rounds": a.rounds, "rows": rows, "tables": tables,
            **info}


def cell_checkpoint(dev_steps: int) -> Path:
    """The cell in steady dense flow (``dev_steps`` steps from its dilute start), cached."""
    OUT.mkdir(exist_ok=True)
    f = OUT / f"study_cell_N{CELL_N}_seed{SEED}_dev{dev_steps}.ckpt"
    if not f.exists():
        t0 = time.perf_counter()
        c = ShearCell(N=CELL_N, seed=SEED, sample_every=1000, threads=2)
        c.run(dev_steps, progress=False)
        c.save_checkpoint(f)
        s = c.summary()
        print(f"  developed the cell ({dev_steps} steps, state {s.get('state')}, phi "
              f"{s.get('phi', float('nan')):.4f}) in {time.perf_counter() - t0:.0f} s -> {f}")
    return f


def gf_cell_rate(ckpt: Path, every: int | None, steps: int, threads: int,
                 info: dict[str, Any]) -> float:
    c = ShearCell(N=CELL_N, seed=SEED, sample_every=every, threads=threads)
    c.restore(ckpt)
    core = c.core
    core.run(1)  # pool and team set-up outside the timing (as compare_lammps's cell speed)
    t0 = time.perf_counter()
    c.run(steps, progress=False)
    tabs = c.tables()
    rate = core.n * steps / (time.perf_counter() - t0)
    info["phi"] = c._vs / float(core.volume)
    info[f"rows_{_label(every)}"] = {k: t.num_rows for k, t in tabs.items()}
    return rate


def part_cell(a: argparse.Namespace, wd: Path) -> dict[str, Any]:
    ckpt = cell_checkpoint(a.cell_dev_steps)
    info: dict[str, Any] = {}
    pairs: list[list[Config]] = []
    for t in a.threads:
        grp: list[Config] = []
        for every in CELL_EVERY:
            def g(e: int | None = every, t: int = t) -> float:
                return gf_cell_rate(ckpt, e, a.cell_steps, t, info)

            grp.append(("granflow", f"{t} thread(s), {_label(every)}", g))
        pairs.append(grp)
    print(f"\n== cell, N = {CELL_N}, {a.cell_steps} steps from the checkpoint "
          f"({a.cell_dev_steps} steps of development); {a.rounds} interleaved rounds", flush=True)
    rows = interleaved(pairs, a.rounds)
    tables: dict[str, Any] = {}
    for t in a.threads:
        tab = []
        none = next(r for r in rows if r["mode"] == f"{t} thread(s), none")
        for every in CELL_EVERY:
            r = next(r for r in rows if r["mode"] == f"{t} thread(s), {_label(every)}")
            tab.append({"observables": _label(every), "every": every, "rate": r["rate"],
                        "rates": r["rates"], "overhead": 1.0 - r["rate"] / none["rate"]})
        tables[f"{t} thread(s)"] = tab
        print(f"\n### cell, granflow {t} thread(s) (best of {a.rounds}; particle-steps/s)\n")
        print("| observables | particle-steps/s | overhead vs none | every round |")
        print("|---|---|---|---|")
        for r in tab:
            print(f"| {r['observables']} | {r['rate']:.3g} | {100 * r['overhead']:.1f} % | "
                  f"{_fmt_all(r['rates'])} |")
    return {"n": CELL_N, "steps": a.cell_steps, "dev_steps": a.cell_dev_steps,
            "checkpoint": str(ckpt), "rows": rows, "tables": tables, **info}


def checks(result: dict[str, Any]) -> list[dict[str, Any]]:
    out = []
    ch = result.get("channel", {}).get("tables", {})
    for name, tab in ch.items():
        by = {r["every"]: r for r in tab}
        if 10 in by:
            r = by[10]
            out.append({"check": f"channel every 10 steps, granflow {name}: >= 2x LAMMPS",
                        "value": r["ratio"], "target": 2.0, "pass": r["ratio"] >= 2.0})
            out.append({"check": f"channel every 10 steps, granflow {name.split(' vs ')[0]}: "
                                 "rate >= 0.9 rate_none (sampling <= 10 %)",
                        "value": r["granflow_over_none"], "target": 0.9,
                        "pass": r["granflow_over_none"] >= 0.9})
    for name, tab in result.get("cell", {}).get("tables", {}).items():
        by = {r["every"]: r for r in tab}
        if 10 in by:
            ov = by[10]["overhead"]
            out.append({"check": f"cell observables every 10 steps, {name}: overhead <= 15 %",
                        "value": ov, "target": 0.15, "pass": ov <= 0.15})
    print("\n== checks")
    for c in out:
        print(f"{'PASS' if c['pass'] else 'FAIL'}  {c['check']}: {c['value']:.3g} "
              f"(target {c['target']:g})")
    return out


PARTS = ("channel", "cell")


def _kernel_stamp() -> str:
    """The installed kernel module and its modification time (a rebuild during a run shows)."""
    from granflow import _core

    p = Path(_core.__file__)
    return f"{p} {datetime.fromtimestamp(p.stat().st_mtime).isoformat(timespec='seconds')}"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small steps: a smoke run (~1 s each)")
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds (best of)")
    ap.add_argument("--steps", type=int, default=None,
                    help="channel steps per timing (statistics every step: a tenth)")
    ap.add_argument("--window-steps", type=int, default=None,
                    help="steps per statistics window (window = this / k samples)")
    ap.add_argument("--flow-steps", type=int, default=FLOW_STEPS,
                    help="channel flow steps after the release (cached state)")
    ap.add_argument("--cell-steps", type=int, default=None, help="cell steps per timing")
    ap.add_argument("--cell-dev-steps", type=int, default=CELL_DEV_STEPS,
                    help="cell steps to steady dense flow (cached checkpoint)")
    ap.add_argument("--parts", nargs="+", default=list(PARTS), choices=PARTS)
    ap.add_argument("--threads", nargs="+", type=int, default=[1, 2], choices=[1, 2])
    ap.add_argument("--out", default=str(OUT / "study_throughput.json"))
    a = ap.parse_args(argv)
    for k, (small, full) in {"steps": (1000, 15_000), "window_steps": (200, 1000),
                             "cell_steps": (10_000, 100_000)}.items():
        if getattr(a, k) is None:
            setattr(a, k, small if a.quick else full)
    if a.steps % a.window_steps:
        ap.error("--steps must be a multiple of --window-steps (whole windows in both codes)")
    result: dict[str, Any] = {
        "args": vars(a), "date": datetime.now().isoformat(timespec="seconds"),
        "machine": platform.processor() or platform.machine(), "granflow": gf.__version__,
        "lammps": lp.lammps_env()["lmp"],
        "command": "python benchmarks/study_throughput.py " + " ".join(sys.argv[1:]),
        "kernel_at_start": _kernel_stamp(),
    }
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="study_throughput_") as tmp:
        for p in a.parts:
            t0 = time.perf_counter()
            result[p] = globals()[f"part_{p}"](a, Path(tmp))
            result[p + "_seconds"] = time.perf_counter() - t0
            out.write_text(json.dumps(_jsonable(result), indent=1))
    result["kernel_at_end"] = _kernel_stamp()
    if result["kernel_at_end"] != result["kernel_at_start"]:
        print("WARNING: the installed granflow kernel changed during the run: "
              f"{result['kernel_at_start']} -> {result['kernel_at_end']}")
    result["checks"] = checks(result)
    out.write_text(json.dumps(_jsonable(result), indent=1))
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
