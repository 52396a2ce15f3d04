"""Time the channel's fill and release (granflow.scenes.channel.Channel.prepare) at a given size:
the stages as the preparation prints them, and the wall and CPU seconds.

    python benchmarks/channel_prep.py [--W 100 --B 40 --H 60 --phi 0.6 --kn 1e6 --threads 2]
           [--preparation rain|pour] [--rain-phi 0.05] [--rain-kn 1e4] [--rain-tiles 4]

Issue 22 asks for a paper-size channel (W = 100, B = 40, H = 60: ~2.7e5 spheres) prepared and
released in minutes; issue 36 in at most 5 minutes on 2 cores with 000's rain (a soft rain,
``--rain-kn``, and one slab repeated along z, ``--rain-tiles``, are the ways there; what they
change in the packing: docs/channel.md, "Preparation"). A phi_bar the rain cannot pack is
refused after the rain; the record then says so, with the rain's time. Results are appended to
benchmarks/out/channel_prep.jsonl.
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

from granflow.errors import ParameterError
from granflow.scenes.channel import Channel


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--W", type=float, default=100.0)
    ap.add_argument("--B", type=float, default=40.0)
    ap.add_argument("--H", type=float, default=60.0)
    ap.add_argument("--phi", type=float, default=0.6)
    ap.add_argument("--kn", type=float, default=1e6)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--preparation", choices=["rain", "pour"], default="rain",
                    help="000's rain (the default) or the soft pour (timed on 2026-11-26)")
    ap.add_argument("--rain-phi", type=float, default=None,
                    help="the rain column's volume fraction (None: Channel's default)")
    ap.add_argument("--rain-kn", type=float, default=None,
                    help="the rain's stiffness (None: the run's kn)")
    ap.add_argument("--rain-tiles", type=int, default=1,
                    help="rain one slab of depth B/N and repeat it N times along z")
    a = ap.parse_args()
    # dt: the material's rule, 000's 1.2e-4 sqrt(1e6/kn)
    extra: dict[str, object] = {} if a.rain_phi is None else {"rain_phi": a.rain_phi}
    if a.preparation == "rain":
        extra.update(rain_kn=a.rain_kn, rain_tiles=a.rain_tiles)
    ch = Channel(W=a.W, B=a.B, H=a.H, phi_bar=a.phi, kn=a.kn, seed=a.seed, threads=a.threads,
                 sample_every=None, preparation=a.preparation, **extra)
    cpu0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.perf_counter()
    refused = None
    try:
        ch.prepare(progress=True)
    except ParameterError as err:  # a phi_bar the rain cannot pack: refused after the rain
        refused = str(err)
    wall = time.perf_counter() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    rec = {"W": a.W, "B": a.B, "H": a.H, "phi_bar": a.phi, "kn": a.kn, "threads": a.threads,
           "seed": a.seed, "wall_seconds": wall, "cpu_seconds": cpu,
           "date": time.strftime("%Y-%m-%d %H:%M"), "rain_kn_arg": a.rain_kn,
           "rain_tiles": a.rain_tiles, "refused": refused, **ch.prep_info}
    print(json.dumps(rec))
    out = Path(__file__).parent / "out"
    out.mkdir(exist_ok=True)
    with open(out / "channel_prep.jsonl", "a") as f:
        f.write(json.dumps(rec) + "\n")


if __name__ == "__main__":
    main()
