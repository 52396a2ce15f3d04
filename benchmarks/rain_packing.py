"""How densely 000's rain packs a channel's bed (docs/channel.md, "Preparation"): rain one
channel (granflow.scenes.channel.Channel, preparation "rain"), stop at the release, and print one
JSON line: the bed's top and level, its fraction to the top and in its core, the core's middle
(4 d from each wall), the settle time, the wall seconds, and phi(x) (0.5 d bins, the core's
height) and phi(y) (1 d bins, the whole width) from exact sphere-slab volumes.

    python benchmarks/rain_packing.py W H B PHI_BAR RAIN_PHI SEED [KN [RAIN_KN|none [TILES]]]

e.g. ``python benchmarks/rain_packing.py 20 40 10 0.5 0.05 1`` (~3 min on one core).
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any

import numpy as np
from granflow.scenes.channel import Channel


class _Released(Exception):
    """Raised in place of the release: the prepared bed is what is measured."""


def slab_volume(x: np.ndarray, d: np.ndarray, lo: float, hi: float, axis: int) -> float:
    """The solid volume of the spheres (centres ``x``, diameters ``d``) between two planes
    normal to ``axis``."""
    c, r = x[:, axis], d / 2
    a, b = np.clip(lo - c, -r, r), np.clip(hi - c, -r, r)
    return float(np.sum(np.pi * (r**2 * (b - a) - (b**3 - a**3) / 3)))


def main() -> None:
    a = sys.argv[1:]
    if len(a) < 6:
        sys.exit(__doc__)
    w, h, b, phi_bar, rain_phi = (float(v) for v in a[:5])
    seed = int(a[5])
    kn = float(a[6]) if len(a) > 6 else 1e5
    rain_kn = float(a[7]) if len(a) > 7 and a[7] != "none" else None
    tiles = int(a[8]) if len(a) > 8 else 1
    got: dict[str, Any] = {}

    def grab(self: Channel, x: np.ndarray, d: np.ndarray, info: dict[str, Any]) -> None:
        got.update(x=x.copy(), d=d.copy(), info=info)
        raise _Released

    Channel._release = grab  # type: ignore[method-assign, assignment]
    c = Channel(W=w, H=h, B=b, kn=kn, phi_bar=phi_bar, seed=seed, rain_phi=rain_phi,
                rain_kn=rain_kn, rain_tiles=tiles, sample_every=None, threads=1)
    t0 = time.time()
    try:
        c.prepare(progress=False)
    except _Released:
        pass
    x, d, info = got["x"], got["d"], got["info"]
    top = info["bed_top"]
    core = (x[:, 1] > 3) & (x[:, 1] < top - 4)
    hcore = top - 7
    xb = np.arange(0, w + 1e-9, 0.5)
    px = [slab_volume(x[core], d[core], xb[i], xb[i + 1], 0) / (0.5 * b * hcore)
          for i in range(len(xb) - 1)]
    yb = np.arange(0, np.ceil(top) + 1e-9, 1.0)
    py = [slab_volume(x, d, yb[i], yb[i + 1], 1) / (b * w) for i in range(len(yb) - 1)]
    mid = core & (x[:, 0] > 4) & (x[:, 0] < w - 4)
    print(json.dumps({
        "W": w, "H": h, "B": b, "phi_bar": phi_bar, "rain_phi": rain_phi, "seed": seed,
        "kn": kn, "rain_kn": rain_kn, "tiles": tiles, "n": len(d), "top": top,
        "level": info["bed_level"], "phi_bed": info["phi_bed"],
        "phi_core": info["phi_bed_core"],
        "phi_mid": (slab_volume(x[mid], d[mid], 4, w - 4, 0) / ((w - 8) * b * hcore)
                    if w > 8 else None),
        "settle_time": info["settle_time"], "wall_s": time.time() - t0,
        "px": [round(v, 3) for v in px], "py": [round(v, 3) for v in py]}))


if __name__ == "__main__":
    main()
