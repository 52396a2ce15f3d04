"""Write a flowing channel state for the Rust step benchmark (`cargo bench --bench step`).

    python benchmarks/kernel_state.py OUT.bin [--tile A B]

Uses the flowing channel state cached by compare_lammps.py (W = 20, H = 30, B = 10 d, 6754
particles, kn = 1e6, flowed 70 000 steps; built on first use), optionally tiled A x B times along
the periodic axes (y, z). File layout (f64 little-endian): kind (1 = channel), N, Lx, Ly, Lz, dt,
then x y z vx vy vz wx wy wz d per particle.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from tiling import tile  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--tile", type=int, nargs=2, default=(1, 1), metavar=("A", "B"))
    a = ap.parse_args()
    import compare_lammps as cl  # the cached flowing state lives there

    st = cl.channel_state()
    lx = float(st["hi"][0] - st["lo"][0])
    st = tile({**st, "hi": st["hi"] - st["lo"]}, (1, *a.tile))
    x, v, w, d = (np.asarray(st[k], dtype=float) for k in ("x", "v", "omega", "d"))
    _, ly, lz = (float(c) for c in st["hi"])
    hdr = np.array([1, len(d), lx, ly, lz, cl.DT], dtype="<f8")
    with open(a.out, "wb") as f:
        f.write(hdr.tobytes())
        f.write(np.column_stack([x, v, w, d]).astype("<f8").tobytes())
    print(f"wrote {a.out}: N = {len(d)}")


if __name__ == "__main__":
    main()
