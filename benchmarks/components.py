"""Leave out what a scene does not need: the components each simulation contains, the memory
each part allocates, and the particle-steps per second each reaches.

    python benchmarks/components.py [--steps 2000]

Cases: the same dense periodic packing with and without friction; a channel and a cell of
similar size. Writes benchmarks/out/components.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import granflow as gf
import numpy as np
from granflow.packing import dense_periodic_packing
from granflow.scenes.cell import ShearCell
from granflow.scenes.channel import Channel

OUT = Path(__file__).parent / "out"


def rate(core, steps: int) -> float:
    core.run(50)
    t0 = time.perf_counter()
    core.run(steps)
    return core.n * steps / (time.perf_counter() - t0)


def report(name: str, core, steps: int) -> dict:
    mem = dict(core.memory())
    r = {"case": name, "n": core.n, "components": core.components(), "memory": mem,
         "bytes_per_particle": sum(mem.values()) / core.n,
         "particle_steps_per_s": rate(core, steps)}
    print(f"\n== {name}: N = {core.n}, {r['particle_steps_per_s']:.3e} particle-steps/s, "
          f"{r['bytes_per_particle']:.0f} B/particle")
    for c in r["components"]:
        print("   ", c)
    print("    memory:", {k: v for k, v in mem.items()})
    return r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()
    rows = []
    x, d, box = dense_periodic_packing(gf.sizes.CHANNEL_MIX, 6000, phi=0.6, seed=4)
    v = np.random.default_rng(0).normal(0, 0.05, size=(len(d), 3))
    for mu in (0.5, 0.0):
        s = gf.Simulation(x, d, box, gf.ContactLaw(kn=1e6, e_n=0.82, mu=mu), velocities=v,
                          dt=1.2e-4, skin=0.2, threads=a.threads)
        rows.append(report(f"periodic packing, mu = {mu}", s.core, a.steps))
    ch = Channel(W=20, H=30, B=10, phi_bar=0.6, kn=1e6, seed=1, threads=a.threads,
                 preparation="pour")  # the recorded timings' packing
    ch.prepare()
    rows.append(report("channel (walls, gravity)", ch.core, a.steps))
    cell = ShearCell(N=6000, p_ext=1e-4, tau_ratio=0.5, seed=1, threads=a.threads)
    cell.run(20_000)
    rows.append(report("stress-controlled cell (compacting)", cell.core, a.steps))
    OUT.mkdir(exist_ok=True)
    (OUT / "components.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
