"""Thread scaling of the kernel: particle-steps per second at 1-16 threads on the dense flowing
channel and on a dilute gas, 1e5 to 1e6 particles, and whether the thread count changes a bit.

    python benchmarks/thread_scaling.py prepare
    python benchmarks/thread_scaling.py run [--threads 1 2 4 8 12 16] [--sizes 1e5 3e5 1e6]
        [--budget 1e8] [--out benchmarks/out/thread_scaling.json]

``prepare`` writes the two small states to benchmarks/out/ (git-ignored; a device run carries
that folder):
- the flowing channel of compare_lammps.py (W = 20, H = 30, B = 10 d, 6754 particles, kn = 1e6,
  e_n = 0.82, mu = 0.5, dt = 1.2e-4, skin 0.2, flowed 70 000 steps), with its law;
- a :class:`granflow.scenes.PeriodicGas` at phi = 0.1 (its own material: kn = 1e5, e_n = 0.8,
  diameters in [0.9, 1.1], the kernel's dt), temperature 1, about 1e5 spheres, run 500 steps
  past the insertion, with its resolved law, dt and skin.
``run`` imports numpy and granflow's kernel alone (no polars), tiles each state along its
periodic axes to each size (benchmarks/tiling.py: the tiled state has the small one's contacts
and neighbours per particle) and times ``budget / N`` steps (50 to 2000) at each thread count,
twice: thread counts rising, then falling (an interleaved A/B, so a drift of the machine shows
as a difference between the two rounds). Then, on the smallest size of each state, 200 steps
from the same start at 1 thread and at the largest count: their positions, velocities and
angular velocities must agree to the bit.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
from state_sim import simulation  # noqa: E402
from tiling import pair_counts, tile  # noqa: E402

OUT = HERE / "out"
STATES = {"channel": OUT / "thread_scaling_channel.npz", "gas": OUT / "thread_scaling_gas.npz"}
GAS_PHI = 0.1
GAS_N = 1.0e5
GAS_SETTLE_STEPS = 500
SAME_BITS_STEPS = 200


def prepare() -> None:
    """Write the two small states (needs the full granflow: the scenes and compare_lammps)."""
    import math

    import compare_lammps as cl
    from granflow.material import kernel_default_skin
    from granflow.scenes import PeriodicGas

    OUT.mkdir(exist_ok=True)
    st = cl.channel_state()
    law = {"kn": cl.KN, "e_n": cl.E_N, "mu": cl.MU, "kt": cl.KT, "xi_t_ratio": 0.5}
    np.savez(STATES["channel"], x=st["x"], v=st["v"], omega=st["omega"], d=st["d"],
             hi=st["hi"], periodic=st["periodic"], walls=np.asarray(st["walls"], float),
             law=json.dumps(law), dt=cl.DT, skin=cl.SKIN, density=cl.DENSITY,
             gravity=cl.G)  # fmt: skip
    mean_volume = math.pi / 6.0  # diameters uniform in [0.9, 1.1]: <d^3> = 1.01
    side = (GAS_N * 1.01 * mean_volume / GAS_PHI) ** (1.0 / 3.0)
    gas = PeriodicGas(L=side, phi=GAS_PHI, temperature=1.0, seed=1, sample_every=10**6)
    gas.prepare(progress=False)
    core = gas.core
    core.run(GAS_SETTLE_STEPS)
    resolved = gas.mat.law(core.diameters())
    law = {k: getattr(resolved, k) for k in ("kn", "kt", "e_n", "xi_n", "xi_t_ratio", "mu")}
    skin = gas.mat.skin if gas.mat.skin is not None else kernel_default_skin()
    np.savez(STATES["gas"], x=core.positions(), v=core.velocities(),
             omega=core.angular_velocities(), d=core.diameters(), hi=np.full(3, side),
             periodic=(True, True, True), walls=np.zeros((0, 2)), law=json.dumps(law),
             dt=core.dt, skin=skin, density=gas.mat.density, gravity=0.0)  # fmt: skip
    for name, f in STATES.items():
        z = np.load(f)
        print(f"{name}: N = {len(z['d'])}, box {z['hi']}, dt = {float(z['dt']):.3g} -> {f}")


def load(name: str) -> dict[str, Any]:
    z = np.load(STATES[name])
    if "walls" not in z.files:
        raise SystemExit(f"{STATES[name]} predates the stored geometry: run `prepare` again")
    return {k: z[k] for k in ("x", "v", "omega", "d", "hi")} | {
        "periodic": tuple(bool(b) for b in z["periodic"]),
        "walls": [(float(p), float(s)) for p, s in z["walls"]],
        "law": json.loads(str(z["law"])), "dt": float(z["dt"]), "density": float(z["density"]),
        "skin": float(z["skin"]), "gravity": float(z["gravity"]),
    }  # fmt: skip


def build(st: dict[str, Any], threads: int) -> Any:
    """The granflow simulation of a (tiled) state, with the geometry, law and gravity it was
    prepared with (the channel: two walls and gravity along -y; the gas: fully periodic)."""
    import granflow as gf

    return simulation(st, gf.ContactLaw(**st["law"]), density=st["density"],
                      dt=st["dt"], skin=st["skin"], gravity=st["gravity"] or None,
                      threads=threads)  # fmt: skip


def digest(sim: Any) -> str:
    core = sim.core
    h = hashlib.sha256()
    for a in (core.positions(), core.velocities(), core.angular_velocities()):
        h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    return h.hexdigest()[:16]


def time_size(name: str, base: dict[str, Any], n_target: float, threads: list[int],
              budget: float) -> dict[str, Any]:
    counts = (1, *pair_counts(n_target, len(base["d"])))
    st = tile(base, counts)
    n = len(st["d"])
    t0 = time.perf_counter()
    sim = build(st, max(threads))
    sim.core.run(20)  # first rebuilds and history allocations
    build_s = time.perf_counter() - t0
    steps = int(min(2000, max(50, budget / n)))
    rates: dict[int, list[float]] = {t: [] for t in threads}
    for order in (threads, threads[::-1]):
        for t in order:
            sim.set_threads(t)
            sim.core.run(10)
            t0 = time.perf_counter()
            sim.core.run(steps)
            rates[t].append(n * steps / (time.perf_counter() - t0))
    return {
        "state": name, "n_target": n_target, "n": n, "copies": list(counts), "steps": steps,
        "build_seconds": build_s, "particle_steps_per_s": {str(t): r for t, r in rates.items()},
        "contacts_per_particle": sim.diagnostics()["contacts"] / n,
    }  # fmt: skip


def same_bits(name: str, base: dict[str, Any], n_target: float, most: int) -> dict[str, Any]:
    st = tile(base, (1, *pair_counts(n_target, len(base["d"]))))
    out = {}
    for t in (1, most):
        sim = build(st, t)
        sim.core.run(SAME_BITS_STEPS)
        out[str(t)] = digest(sim)
    return {"state": name, "n": len(st["d"]), "steps": SAME_BITS_STEPS, "digests": out,
            "equal": len(set(out.values())) == 1}  # fmt: skip


def run(a: argparse.Namespace) -> None:
    threads = sorted(set(a.threads))
    head = " ".join(f"{t:>7}" for t in threads)
    print(f"host: {platform.processor() or platform.machine()}, os.cpu_count() = "
          f"{os.cpu_count()}; particle-steps/s (1e6), mean of a rising and a falling round")
    print(f"{'state':>8} {'N':>9} {'steps':>5} {'build s':>7} {'c/p':>5} {head}   speed-up at "
          f"{threads[-1]} / efficiency")  # fmt: skip
    rows, checks = [], []
    for name in ("channel", "gas"):
        base = load(name)
        for n_target in a.sizes:
            r = time_size(name, base, n_target, threads, a.budget)
            rows.append(r)
            mean = {t: float(np.mean(r["particle_steps_per_s"][str(t)])) for t in threads}
            cols = " ".join(f"{mean[t] / 1e6:>7.1f}" for t in threads)
            sp = mean[threads[-1]] / mean[threads[0]]
            print(f"{name:>8} {r['n']:>9} {r['steps']:>5} {r['build_seconds']:>7.1f} "
                  f"{r['contacts_per_particle']:>5.2f} {cols}   {sp:.2f} / "
                  f"{sp / (threads[-1] / threads[0]):.2f}", flush=True)  # fmt: skip
        checks.append(same_bits(name, base, min(a.sizes), threads[-1]))
        c = checks[-1]
        print(f"{name}: {c['steps']} steps, N = {c['n']}: threads 1 and {threads[-1]} "
              f"{'agree to the bit' if c['equal'] else 'DIFFER'} {c['digests']}", flush=True)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"cpu_count": os.cpu_count(), "rows": rows, "same_bits": checks},
                              indent=1))  # fmt: skip
    print(f"wrote {out}")
    if not all(c["equal"] for c in checks):
        raise SystemExit("the thread count changed the numbers")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=["prepare", "run"])
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2, 4, 8, 12, 16])
    ap.add_argument("--sizes", type=float, nargs="+", default=[1e5, 3e5, 1e6])
    ap.add_argument("--budget", type=float, default=1e8,
                    help="particle-steps per timing (steps = budget/N within [50, 2000])")
    ap.add_argument("--out", default=str(OUT / "thread_scaling.json"))
    a = ap.parse_args(argv)
    if a.what == "prepare":
        prepare()
    else:
        run(a)


if __name__ == "__main__":
    main()
