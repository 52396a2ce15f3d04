"""What friction costs: the same jammed packing (same contacts) stepped with the frictional and
the frictionless law.

    python benchmarks/friction_cost.py [--n 20000] [--packing frictionless|frictional]
                                       [--steps S] [--repeat 15] [--threads 1]

The packing must be at rest under both laws, or the comparison times the packing's collapse
instead of the law: a packing jammed with friction at phi = 0.625 is below frictionless
jamming, so without friction it flies apart (the fastest particle moves 0.16 d in 40 steps and
the lists are rebuilt twice: a quarter of the frictionless run's time, measured with the step
bench). Hence two preparations:

- ``frictionless`` (default): the spheres are grown to phi = 0.65 (above frictionless jamming
  for this size mix) and relaxed without friction and with strong damping (e_n = 0.1). The
  packing is then in force balance without friction, and so with friction too (tangential
  forces start at zero and stay zero while nothing slides): both laws see the same contacts
  and no motion but vibration. 200 steps per timing.
- ``frictional``: the earlier preparation (phi = 0.625 relaxed with mu = 0.5; 40 steps per
  timing, so that the frictionless run keeps its contacts), kept for comparison.

Each law starts from the same positions at rest; the two laws alternate within the repeats
(this VM drifts by 5-10 % over minutes), best of ``--repeat``. Prints particle-steps per
second, contacts per particle, the largest displacement over a timed run (beyond half the skin,
0.1 d, the lists must be rebuilt) and the ratio.
"""

from __future__ import annotations

import argparse
import time

import granflow as gf
import numpy as np
from granflow.packing import dense_periodic_packing

LAW = {"kn": 1e6, "e_n": 0.82}
DT = 1.2e-4
SKIN = 0.2


def packing(kind: str, n: int, threads: int) -> tuple[np.ndarray, np.ndarray, gf.Box]:
    """Positions, diameters and box of a packing at rest (see the module docstring)."""
    x, d, box = dense_periodic_packing(gf.sizes.CHANNEL_MIX, n, phi=0.625, seed=4)
    if kind == "frictionless":
        # grow the spheres in place to phi = 0.65, then relax without friction
        d = d * (0.65 / 0.625) ** (1 / 3)
        prep, steps = gf.ContactLaw(mu=0.0, kn=LAW["kn"], e_n=0.1), 8000
    else:
        prep, steps = gf.ContactLaw(mu=0.5, **LAW), 2000
    s = gf.Simulation(x, d, box, prep, dt=DT, skin=SKIN, threads=threads)
    s.run(steps, progress=False)
    return s.get_positions(), d, box


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20_000)
    ap.add_argument("--packing", choices=["frictionless", "frictional"], default="frictionless")
    ap.add_argument("--steps", type=int, default=None,
                    help="steps per timing (default 200 for the frictionless packing, 40 else)")
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()
    steps = a.steps or (200 if a.packing == "frictionless" else 40)
    xj, d, box = packing(a.packing, a.n, a.threads)
    length = np.asarray(box.length)
    rate = {0.5: 0.0, 0.0: 0.0}
    cs: dict[float, list[float]] = {0.5: [], 0.0: []}
    moved: dict[float, float] = {0.5: 0.0, 0.0: 0.0}
    for _ in range(a.repeat):
        for mu in (0.5, 0.0):
            t = gf.Simulation(xj, d, box, gf.ContactLaw(mu=mu, **LAW), dt=DT, skin=SKIN,
                              threads=a.threads)
            t.run(1, progress=False)  # list build and set-up outside the timing
            x0 = t.get_positions()
            t0 = time.perf_counter()
            t.run(steps, progress=False)
            rate[mu] = max(rate[mu], t.n * steps / (time.perf_counter() - t0))
            cs[mu].append(t.diagnostics()["contacts"] / t.n)
            dx = t.get_positions() - x0
            dx -= np.round(dx / length) * length
            moved[mu] = max(moved[mu], float(np.sqrt((dx**2).sum(axis=1)).max()))
    print(f"packing: {a.packing}, N = {len(d)}, {steps} steps per timing, best of {a.repeat}")
    for mu in (0.5, 0.0):
        print(f"mu = {mu}: {rate[mu]:.3e} particle-steps/s, {np.mean(cs[mu]):.2f} "
              f"contacts/particle, largest displacement {moved[mu]:.3f} (diameters ~1)")
    print(f"frictionless / frictional: {rate[0.0] / rate[0.5]:.2f}")


if __name__ == "__main__":
    main()
