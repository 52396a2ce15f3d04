"""What friction costs: the same jammed packing (same contacts) stepped with the frictional and
the frictionless law.

    python benchmarks/friction_cost.py [--n 20000] [--steps 40] [--repeat 15]

A dense polydisperse periodic packing (phi = 0.625) is relaxed with mu = 0.5 into a jammed
state; each law then starts from those positions at rest, and a short run (a frictionless
packing would relax and lose its contacts in a few hundred steps) is timed, best of --repeat.
Prints particle-steps per second, contacts per particle and the ratio.
"""

from __future__ import annotations

import argparse
import time

import granflow as gf
import numpy as np
from granflow.packing import dense_periodic_packing


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20_000)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args()
    x, d, box = dense_periodic_packing(gf.sizes.CHANNEL_MIX, a.n, phi=0.625, seed=4)
    law = {"kn": 1e6, "e_n": 0.82}
    s = gf.Simulation(x, d, box, gf.ContactLaw(mu=0.5, **law), dt=1.2e-4, skin=0.2,
                      threads=a.threads)
    s.run(2000)
    xj = s.get_positions()
    # the two laws alternate within the repeats, so that a slow spell of the machine (this
    # VM drifts by 5-10 % over minutes) weighs on both alike
    rate = {0.5: 0.0, 0.0: 0.0}
    cs: dict[float, list[float]] = {0.5: [], 0.0: []}
    for _ in range(a.repeat):
        for mu in (0.5, 0.0):
            t = gf.Simulation(xj, d, box, gf.ContactLaw(mu=mu, **law), dt=1.2e-4, skin=0.2,
                              threads=a.threads)
            t.run(1)  # list build and set-up outside the timing
            t0 = time.perf_counter()
            t.run(a.steps)
            rate[mu] = max(rate[mu], t.n * a.steps / (time.perf_counter() - t0))
            cs[mu].append(t.diagnostics()["contacts"] / t.n)
    for mu in (0.5, 0.0):
        c = np.mean(cs[mu])
        print(f"mu = {mu}: {rate[mu]:.3e} particle-steps/s, {c:.2f} contacts/particle")
    print(f"frictionless / frictional: {rate[0.0] / rate[0.5]:.2f}")


if __name__ == "__main__":
    main()
