"""Scaling with N on the channel workload: particle-steps per second (1 and 2 threads) and
resident bytes per particle at N ~ 5e3, 2e4, 1e5, 1e6.

    python benchmarks/scaling.py [--max-n 1000000] [--budget 1e8] [--threads 1 2] [--lammps]

The flowing channel state of compare_lammps.py (W = 20, H = 30, B = 10 d, 6754 particles,
kn = 1e6, e_n = 0.82, mu = 0.5, dt = 1.2e-4, skin 0.2; cached in benchmarks/out/) is tiled, so
every size is a flowing channel-like state made in seconds:
- ``--grow HB`` (default): repeated along the two periodic axes (H and B grow, W stays 20 d).
  The tiled state is exactly periodic, so the local structure, contacts and neighbours per
  particle are those of the small channel at every N (the cost per particle is comparable).
- ``--grow WH``: copies also stacked across the wall direction (W grows). A copy's wall layer
  then faces the next copy's (centres at least R - overlap from the old wall plane: no large
  overlaps), but the two flat layers barely touch and the interface dilates: contacts per
  particle drop from 0.9 to ~0.5-0.7 within a few hundred steps.
Each size runs in its own process so that the resident-memory growth is clean. Memory is
reported twice: the kernel's own count (``Simulation.memory()`` totals) and the growth of the
process's resident set (/proc/self/statm) from before the simulation is built to after its
first steps. Writes benchmarks/out/scaling.json and prints a table.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
import compare_lammps as cl  # noqa: E402  (the cached flowing channel state lives there)
from kernel_throughput import rss_bytes  # noqa: E402
from tiling import pair_counts, tile  # noqa: E402

OUT = HERE / "out"
SIZES = (5_000, 20_000, 100_000, 1_000_000)


def tiled(n_target: int, flow_steps: int, grow: str) -> dict[str, Any]:
    """The cached channel state tiled to about ``n_target`` particles (a state dict as
    ``compare_lammps.channel_state`` returns, plus ``copies``)."""
    st = cl.channel_state(flow_steps)
    ta, tb = pair_counts(n_target, len(st["x"]))
    return tile(st, (ta, tb, 1) if grow == "WH" else (1, ta, tb))


def steps_for(budget: float, n: int) -> int:
    return int(min(2000, max(100, budget / n)))


def lammps_rate(n_target: int, budget: float, flow_steps: int, grow: str,
                wd: Path) -> float:
    """LAMMPS serial on the same tiled state, the same steps as granflow (Loop time)."""
    import lammps_peer as lp

    st = tiled(n_target, flow_steps, grow)
    n = len(st["d"])
    steps = steps_for(budget, n)
    path = cl.data_file(st, wd / f"tiled_{n}.data")
    gn = cl.gamma_n_workload(st["d"])
    r = lp.run(path, cl.lmp_params(gn, thermo_every=steps), steps, mode="serial", threads=1,
               scene="channel")
    return float(r["particle_steps_per_s"])


def one(n_target: int, threads: list[int], budget: float, flow_steps: int,
        grow: str) -> dict[str, Any]:
    """Build and time one size (run in a child process)."""
    st = tiled(n_target, flow_steps, grow)
    nx, ny, nz = st["copies"]
    n = len(st["d"])
    width, height, depth = st["hi"]
    rss0 = rss_bytes()
    t0 = time.perf_counter()
    sim = cl.gf_sim(st, None, threads=threads[0])  # the workload's restitution law
    sim.core.run(20)  # set-up evaluation, first rebuilds and history allocations
    t_build = time.perf_counter() - t0
    rss1 = rss_bytes()
    mem = sim.memory()
    steps = steps_for(budget, n)
    rates = {}
    for t in threads:
        sim.set_threads(t)
        sim.core.run(10)
        t0 = time.perf_counter()
        sim.core.run(steps)
        rates[t] = n * steps / (time.perf_counter() - t0)
    return {
        "n_target": n_target, "n": n, "grow": grow, "copies": [nx, ny, nz], "W": width,
        "H": height, "B": depth, "steps": steps, "build_seconds": t_build,
        "particle_steps_per_s": {str(k): r for k, r in rates.items()},
        "kernel_bytes_per_particle": sum(mem.values()) / n,
        "rss_growth_bytes_per_particle": max(rss1 - rss0, 0) / n,
        "contacts_per_particle": sim.diagnostics()["contacts"] / n,
        "memory": mem,
    }  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-n", type=float, default=1e6, help="largest target size")
    ap.add_argument("--sizes", type=float, nargs="+", default=list(SIZES))
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--budget", type=float, default=1e8,
                    help="particle-steps per timing (steps = budget/N within [100, 2000])")
    ap.add_argument("--flow-steps", type=int, default=None,
                    help="flow steps of the cached channel state (compare_lammps's default)")
    ap.add_argument("--grow", default="HB", choices=["HB", "WH"],
                    help="axes along which the small channel is tiled (see above)")
    ap.add_argument("--lammps", action="store_true",
                    help="also time LAMMPS serial on each tiled state (the peer's own scaling; "
                         "needs benchmarks/lammps_env.sh sourced)")
    ap.add_argument("--one", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--out", default=str(OUT / "scaling.json"))
    a = ap.parse_args(argv)
    if a.flow_steps is None:
        a.flow_steps = cl.FLOW_STEPS
    if a.one is not None:
        print(json.dumps(one(int(a.one), a.threads, a.budget, a.flow_steps, a.grow)))
        return
    # make the cached state here, not in the first child (its freed memory would hide that
    # child's resident-set growth)
    cl.channel_state(a.flow_steps)
    rows = []
    thr = " ".join(f"{f'{t} thr p-steps/s':>17}" for t in a.threads)
    print(f"tiled along {a.grow}")
    lmp_head = f"{'LAMMPS serial':>14}" if a.lammps else ""
    print(f"{'N':>9} {'tiles':>8} {'steps':>5} {'build s':>7} {thr} {'kernel B/p':>10} "
          f"{'RSS B/p':>8} {'contacts/p':>10} {lmp_head}")
    tmp = tempfile.TemporaryDirectory(prefix="scaling_")
    for n in a.sizes:
        if n > a.max_n:
            continue
        cmd = [sys.executable, __file__, "--one", str(n), "--budget", str(a.budget),
               "--flow-steps", str(a.flow_steps), "--grow", a.grow,
               "--threads", *map(str, a.threads)]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise RuntimeError(f"N = {n:g} failed:\n{proc.stderr[-3000:]}")
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        rows.append(r)
        rates = " ".join(f"{r['particle_steps_per_s'][str(t)]:>17.3e}" for t in a.threads)
        lmp = ""
        if a.lammps:
            r["lammps_serial_particle_steps_per_s"] = lammps_rate(
                int(n), a.budget, a.flow_steps, a.grow, Path(tmp.name))
            lmp = f"{r['lammps_serial_particle_steps_per_s']:>14.3e}"
        tiles = "x".join(map(str, r["copies"]))
        print(f"{r['n']:>9} {tiles:>8} {r['steps']:>5} "
              f"{r['build_seconds']:>7.1f} {rates} {r['kernel_bytes_per_particle']:>10.0f} "
              f"{r['rss_growth_bytes_per_particle']:>8.0f} {r['contacts_per_particle']:>10.2f} "
              f"{lmp}", flush=True)
    tmp.cleanup()
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(rows, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
