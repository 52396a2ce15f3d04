"""Kernel throughput: particle-steps per second and resident bytes per particle for a dense
(phi ~ 0.6) frictional polydisperse periodic packing, 1 and 2 threads.

    python benchmarks/kernel_throughput.py [--sizes 5000 20000 100000] [--steps 2000]

Prints a table and writes benchmarks/out/kernel_throughput.json. Packings are cached in
benchmarks/out/ (building one is slower than the benchmark itself).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from pathlib import Path

import granflow as gf
import numpy as np
from granflow.packing import dense_periodic_packing

OUT = Path(__file__).parent / "out"


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def packing(n: int, seed: int = 1):
    OUT.mkdir(exist_ok=True)
    f = OUT / f"packing_{n}_{seed}.npz"
    if f.exists():
        z = np.load(f)
        return z["x"], z["d"], gf.Box(length=tuple(z["L"]))
    t0 = time.perf_counter()
    x, d, box = dense_periodic_packing(gf.sizes.CHANNEL_MIX, n, phi=0.6, seed=seed)
    print(f"  built packing N={len(d)} in {time.perf_counter() - t0:.1f} s")
    np.savez(f, x=x, d=d, L=np.asarray(box.length))
    return x, d, box


def measure(n: int, threads: int, steps: int, mu: float = 0.5) -> dict:
    x, d, box = packing(n)
    rng = np.random.default_rng(0)
    v = rng.normal(0, 0.05, size=(len(d), 3))  # a sheared-like agitation keeps contacts changing
    rss0 = rss_bytes()
    law = gf.ContactLaw(kn=1e6, e_n=0.82, mu=mu)
    sim = gf.Simulation(x, d, box, law, velocities=v, dt=1.2e-4, skin=0.2, threads=threads)
    sim.run(100, progress=False)  # warm-up
    t0 = time.perf_counter()
    sim.run(steps, progress=False)
    el = time.perf_counter() - t0
    rss1 = rss_bytes()
    mem = sim.memory()
    return {
        "n": len(d),
        "threads": threads,
        "mu": mu,
        "steps": steps,
        "seconds": el,
        "particle_steps_per_s": len(d) * steps / el,
        "kernel_bytes_per_particle": sum(mem.values()) / len(d),
        "rss_delta_bytes_per_particle": max(rss1 - rss0, 0) / len(d),
        "contacts_per_particle": sim.diagnostics()["contacts"] / len(d),
        "memory": mem,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[5000, 20000, 100000])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    a = ap.parse_args()
    rows = []
    print(f"{'N':>8} {'thr':>4} {'mu':>4} {'p-steps/s':>11} {'B/particle':>11} {'contacts/p':>10}")
    for n in a.sizes:
        for t in a.threads:
            for mu in (0.5, 0.0):
                r = measure(n, t, a.steps, mu)
                rows.append(r)
                print(
                    f"{r['n']:>8} {t:>4} {mu:>4} {r['particle_steps_per_s']:>11.3e} "
                    f"{r['kernel_bytes_per_particle']:>11.0f} {r['contacts_per_particle']:>10.2f}"
                )
    OUT.mkdir(exist_ok=True)
    (OUT / "kernel_throughput.json").write_text(json.dumps(rows, indent=1))
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
