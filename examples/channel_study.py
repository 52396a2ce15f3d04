"""Vertical channel (000) in resumable chunks: after each chunk, the flow state (steady,
fluctuating, arrested, accelerating) and the key figures with standard errors; Parquet files,
plots and a text summary in the output directory. Run again to continue where it stopped.

    python examples/channel_study.py OUT [--phi 0.60] [--W 20] [--H 30] [--B 10] [--kn 1e5]
           [--chunk-time 20] [--max-time 600] [--threads 2]

The paper needs t ~ 2e3 sqrt(d/g) to reach steady flow at W >= 60 d; this example uses smaller
channels and a softer kn = 1e5 (the paper's fig. 10: phi and u_y do not depend on kn >= 1e5
outside the plug).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from granflow.material import MATERIAL_000
from granflow.runner import execute


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--phi", type=float, default=0.60)
    ap.add_argument("--W", type=float, default=20.0)
    ap.add_argument("--H", type=float, default=30.0)
    ap.add_argument("--B", type=float, default=10.0)
    ap.add_argument("--kn", type=float, default=1e5)
    ap.add_argument("--chunk-time", type=float, default=20.0, help="sqrt(d/g) per chunk")
    ap.add_argument("--max-time", type=float, default=600.0, help="stop after this time")
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    # the soft pour by default: 000's rain packs only ~0.59 up to its top at H = 30
    # (docs/channel.md, "Preparation"); --preparation rain with a phi_bar it can pack
    ap.add_argument("--preparation", choices=["rain", "pour"], default="pour")
    a = ap.parse_args()
    dt = MATERIAL_000.with_(kn=a.kn).dt()  # 000's rule: 1.2e-4 at kn = 1e6, scaled with t_c
    assert dt is not None
    spec = {
        "scene": "channel",
        "seed": a.seed,
        "params": {"W": a.W, "H": a.H, "B": a.B, "phi_bar": a.phi, "kn": a.kn,
                   "sample_every": 200, "window": 25, "preparation": a.preparation},
        "run": {"steps": 0, "checkpoint_every": int(round(a.chunk_time / dt))},
        "output": {},
    }
    out = Path(a.out)
    chunk = int(round(a.chunk_time / dt))
    steps = 0
    man = out / "manifest.json"
    if man.exists():
        steps = json.loads(man.read_text()).get("steps_done", 0)
    prev_u = 0.0
    while steps * dt < a.max_time:
        steps += chunk
        spec["run"]["steps"] = steps
        t0 = time.perf_counter()
        r = execute(spec, out, progress=False, threads=a.threads)
        s = r.summary
        print(f"t = {steps * dt:7.1f} sqrt(d/g)  state = {s.get('state')}  "
              f"u_slip = {s.get('u_slip', float('nan')):.4g} ± {s.get('u_slip_se') or 0:.2g}  "
              f"u_max = {s.get('u_max', float('nan')):.4g} ± {s.get('u_max_se') or 0:.2g}  "
              f"u_max/u_slip = {s.get('u_max_over_u_slip', float('nan')):.4g}  "
              f"({time.perf_counter() - t0:.0f} s, total {r.wall_seconds:.0f} s)", flush=True)
        u = s.get("u_max", float("nan"))
        free_fall = s.get("state") == "accelerating" and u > 1.2 * prev_u > 0
        if steps * dt >= 3 * a.chunk_time and (s.get("state") == "arrested" or free_fall):
            print(f"flow {s['state']}: stopping")
            break
        prev_u = u
    try:
        from granflow.analysis.plots import plot_run

        for p in plot_run(out):
            print("wrote", p)
    except Exception as exc:  # plots are a convenience; the data are written already
        print(f"plots skipped: {type(exc).__name__}: {exc}")
    errs = out / "errors.txt"
    if errs.exists():
        print("\nstandard error against run time:\n" + errs.read_text())
    lines = [f"{k}: {v}" for k, v in sorted(r.summary.items())]
    (out / "summary.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
