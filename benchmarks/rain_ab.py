"""Interleaved A/B wall time of the rain's speed options (granflow.scenes.channel.Channel,
preparation = "rain"), each preparation in its own process on one thread.

    python benchmarks/rain_ab.py [--rounds 3] [--W 10 --H 12 --B 16 --phi 0.58 --kn 1e5]
           [--pairs skin tiles]

- skin: the rain's neighbour-list skin RAIN_SKIN (1 d) against the material's default skin;
- tiles: one slab of depth B/2 rained and repeated (``rain_tiles = 2``) against the whole depth.

Per round each pair runs A then B, the order swapped every other round, so slow drifts of the
machine (the other core busy) fall on both alike. Reported per pair: the wall seconds of each
run and the median of the paired ratios B/A (the single-run figures in docs/channel.md are
indications; these are the measurement). Appended to benchmarks/out/rain_ab.jsonl.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

WORKER = r"""
import json, sys, time
import granflow.scenes.channel as ch
spec, variant = json.loads(sys.argv[1]), sys.argv[2]
if variant == "default-skin":
    ch.RAIN_SKIN = 0.0  # the material's skin (the rain's is max(skin, RAIN_SKIN))
if variant == "tiles2":
    spec["rain_tiles"] = 2
c = ch.Channel(**spec)
t0 = time.perf_counter()
c.prepare(progress=False)
print(json.dumps({"wall": time.perf_counter() - t0, "rain_seconds": c.prep_info["rain_seconds"],
                  "phi_bed_core": c.prep_info["phi_bed_core"], "n": c.prep_info["n"]}))
"""

#: pair name -> (A variant, B variant)
PAIRS = {"skin": ("rain-skin", "default-skin"), "tiles": ("tiles1", "tiles2")}


def one(spec: dict[str, object], variant: str) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", WORKER, json.dumps(spec), variant],
                         check=True, capture_output=True, text=True).stdout
    return dict(json.loads(out.strip().splitlines()[-1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--W", type=float, default=10.0)
    ap.add_argument("--H", type=float, default=12.0)
    ap.add_argument("--B", type=float, default=16.0)
    ap.add_argument("--phi", type=float, default=0.58)
    ap.add_argument("--kn", type=float, default=1e5)
    ap.add_argument("--rain-phi", type=float, default=0.05)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--pairs", nargs="+", choices=sorted(PAIRS), default=sorted(PAIRS))
    a = ap.parse_args()
    spec = {"W": a.W, "H": a.H, "B": a.B, "phi_bar": a.phi, "kn": a.kn, "seed": a.seed,
            "threads": 1, "sample_every": None, "preparation": "rain", "rain_phi": a.rain_phi}
    log = HERE / "out" / "rain_ab.jsonl"
    log.parent.mkdir(parents=True, exist_ok=True)
    for name in a.pairs:
        va, vb = PAIRS[name]
        walls: dict[str, list[float]] = {va: [], vb: []}
        ratios = []
        for r in range(a.rounds):
            order = (va, vb) if r % 2 == 0 else (vb, va)
            got = {v: one(spec, v) for v in order}
            for v in order:
                walls[v].append(got[v]["wall"])
            ratios.append(got[vb]["wall"] / got[va]["wall"])
            print(f"{name} round {r + 1}: " + ", ".join(
                f"{v} {got[v]['wall']:.1f} s (core phi {got[v]['phi_bed_core']:.4f})"
                for v in order), flush=True)
        rec = {"pair": name, "spec": spec, "A": va, "B": vb, "wall_A": walls[va],
               "wall_B": walls[vb], "median_ratio_B_over_A": statistics.median(ratios)}
        print(f"{name}: {vb} / {va} wall, median of {a.rounds} paired ratios: "
              f"{rec['median_ratio_B_over_A']:.3f}", flush=True)
        with log.open("a") as f:
            f.write(json.dumps(rec) + "\n")


if __name__ == "__main__":
    main()
