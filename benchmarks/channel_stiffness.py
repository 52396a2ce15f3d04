"""Channel profiles against particle stiffness (issue #5; paper 000 §3.2, figure 10).

000 (text of fig. 10): "In all cases, phi and u_y ... are independent of k_n for k_n >= 1e5,
except for one case corresponding to variation of phi with x/d_p for k_n = 1e5 and
phi_bar = 0.59" (W = 100 d, phi_bar = 0.59 and 0.61, k_n = 1e5 ... 1e8). du_y/dx and T depend
on k_n in the dense shearing and plug zones, so they are not compared here.

One small channel is poured and released once (:meth:`Channel.prepare_from`) and run from the
same packing at each k_n with dt = 1.2e-4 sqrt(1e6/k_n) (000's dt at k_n = 1e6, ~t_c/11, scaled
as t_c ~ k_n^-1/2) and the same sampling interval in time. After ``--discard`` the folded half
profiles phi(xi) and u(xi) (granflow.analysis.channel_profiles.profiles, block-jackknife SE) are
compared bin by bin for each pair of k_n: z = (a - b)/sqrt(se_a^2 + se_b^2), chi^2 = sum z^2
over the bins (neighbouring bins are correlated, so chi^2/n is indicative, not a test), the
fraction of bins with |z| < 2 and < 3, and the same z for u_slip and u_max.

Control (``--control``): the softest k_n again with dt x 0.9, the same physics on a different
(chaotic) trajectory. Its pair with the softest run is the null comparison: if it disagrees as
much as the k_n pairs, the block SE underestimates the run-to-run scatter (slow wandering of the
plug) and the k_n comparison cannot resolve a stiffness effect of that size. The comparison is
made with the automatic number of blocks and with ``--n-blocks`` (default 10, the fewest the
jackknife gives an SE from: granflow.analysis.stats.MIN_SE_BLOCKS) long blocks.

    python benchmarks/channel_stiffness.py [--kn 1e5 1e6 1e7] [--T 400] [--discard 60]
        [--W 16 --H 10 --B 6 --phi 0.59] [--control] [--n-blocks 10] [--out benchmarks/out]
        [--force]

Each k_n's tables go to ``OUT/channel_stiffness_kn_<kn>_{bins,series}.parquet`` and are reused
on the next call (``--force`` reruns); the comparison goes to ``OUT/channel_stiffness.json`` and
a table to stdout. One thread. Cost: ~5 s of wall time per unit of sqrt(d/g) for the three k_n
together at the default size (1063 particles).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
from granflow.analysis import channel as ach
from granflow.analysis.compare import difference_z
from granflow.analysis.stats import MIN_SE_BLOCKS, steady_state_start
from granflow.scenes.channel import Channel

DT_1E6 = 1.2e-4  # 000 §2: dt = 1.2e-4 sqrt(d/g) at k_n = 1e6


def dt_for(kn: float) -> float:
    """000's dt scaled with the contact time t_c ~ k_n^-1/2 (the scene's default at 1e6)."""
    return DT_1E6 * math.sqrt(1e6 / kn)


def tag(kn: float, dt_scale: float = 1.0) -> str:
    t = f"{kn:.0e}".replace("+", "")
    return t if dt_scale == 1.0 else f"{t}_dt{dt_scale:g}"


def run_one(src: Channel, kn: float, a: argparse.Namespace, out: Path,
            dt_scale: float = 1.0) -> dict[str, Any]:
    """Run the prepared packing ``src`` at ``kn`` (dt x ``dt_scale``) for ``a.T``; write its
    tables."""
    dt = dt_for(kn) * dt_scale
    label = tag(kn, dt_scale)
    ch = Channel(W=a.W, H=a.H, B=a.B, phi_bar=a.phi, kn=kn, dt=dt, seed=a.seed, threads=1,
                 sample_every=max(1, round(a.sample_dt / dt)), window=a.window,
                 bin_width=a.bin_width)
    ch.prepare_from(src)
    steps = round(a.T / dt)
    chunk = round(a.chunk / dt)
    t0, c0 = time.perf_counter(), time.process_time()
    done = 0
    while done < steps:
        c = min(chunk, steps - done)
        ch.run(c, progress=False)
        done += c
        last = ch._tables.last("series")  # the last sample (not the whole table every chunk)
        vy = last["vcm_y"] if last else float("nan")
        print(f"  kn = {kn:.0e}  t = {ch.core.time:6.1f}  vcm_y = {vy:8.4f}  "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    tabs = ch.tables()
    for name in ("bins", "series"):
        pl.from_arrow(tabs[name]).write_parquet(
            out / f"channel_stiffness_kn_{label}_{name}.parquet")
    meta = {"label": label, "kn": kn, "dt": dt, "steps": steps, "wall_seconds": wall,
            "cpu_seconds": cpu, "n": ch.prep_info["n"],
            "phi_bar_achieved": ch.prep_info["phi_bar_achieved"],
            "sample_every": ch.sample_every,
            "particle_steps_per_s": steps * ch.prep_info["n"] / wall}
    (out / f"channel_stiffness_kn_{label}_meta.json").write_text(json.dumps(meta, indent=1))
    return meta


def analyse(label: str, out: Path, discard: float, n_blocks: int | None) -> dict[str, Any]:
    """Folded steady profiles and 3.1 numbers of one run (from its tables)."""
    bins = pl.read_parquet(out / f"channel_stiffness_kn_{label}_bins.parquet")
    series = pl.read_parquet(out / f"channel_stiffness_kn_{label}_series.parquet")
    meta = json.loads((out / f"channel_stiffness_kn_{label}_meta.json").read_text())
    meta.setdefault("label", label)
    s = ach.summary(bins, series, start_time=discard, n_blocks=n_blocks)
    prof = s["profile"]
    # MSER start of |vcm_y|: the discard must not be earlier, else the transient biases
    ss = steady_state_start(series["t"].to_numpy(), np.abs(series["vcm_y"].to_numpy()))
    return {
        **meta,
        "flow_state": s["flow_state"]["state"],
        "t_start": s["steady"]["t_start"],
        "t_end": float(series["t"].max()),
        "mser_start": float(ss.t_start),
        "n_blocks": s["steady"]["n_blocks"],
        "u_slip": s["u_slip"]._asdict(), "u_max": s["u_max"]._asdict(),
        "u_max_over_u_slip": s["u_max_over_u_slip"]._asdict(),
        "xi": prof["xi"].to_list(),
        "phi": prof["phi"].to_list(), "phi_se": prof["phi_se"].to_list(),
        "u": prof["u"].to_list(), "u_se": prof["u_se"].to_list(),
        "T": prof["T"].to_list(), "T_se": prof["T_se"].to_list(),
    }


def z_scores(a: list[float], sa: list[float], b: list[float], sb: list[float]) -> np.ndarray:
    """(a - b)/sqrt(se_a^2 + se_b^2) per bin."""
    a_, b_ = np.asarray(a), np.asarray(b)
    s = np.sqrt(np.asarray(sa) ** 2 + np.asarray(sb) ** 2)
    return (a_ - b_) / s


def compare(r1: dict[str, Any], r2: dict[str, Any], phi_claimed: bool) -> dict[str, Any]:
    """Bin-by-bin and scalar agreement of two k_n runs."""
    out: dict[str, Any] = {"a": r1["label"], "b": r2["label"], "kn_a": r1["kn"],
                           "kn_b": r2["kn"]}
    for q in ("phi", "u"):
        z = z_scores(r1[q], r1[f"{q}_se"], r2[q], r2[f"{q}_se"])
        ok = np.isfinite(z)
        za = np.abs(z[ok])
        out[q] = {
            "n_bins": int(ok.sum()),
            "frac_2sigma": float(np.mean(za < 2)), "frac_3sigma": float(np.mean(za < 3)),
            "max_abs_z": float(za.max()), "chi2": float(np.sum(za**2)),
            "chi2_per_bin": float(np.mean(za**2)),
            "max_abs_diff": float(np.max(np.abs(np.asarray(r1[q]) - np.asarray(r2[q])))),
            "z": [float(v) for v in z],
            # 000 fig. 10: u_y independent of k_n >= 1e5; phi too except k_n = 1e5 at 0.59
            "paper_claims_equal": True if q == "u" else phi_claimed,
        }
    for q in ("u_slip", "u_max", "u_max_over_u_slip"):
        a, b = r1[q], r2[q]
        diff, s, z = difference_z(a["value"], a["se"], b["value"], b["se"])
        out[q] = {"a": a["value"], "b": b["value"], "diff": diff, "se": s, "z": z}
    return out


def table(runs: list[dict[str, Any]], pairs: list[dict[str, Any]]) -> str:
    lines = ["per k_n (steady part; SE from block jackknife)",
             f"{'run':>10} {'dt':>9} {'steps':>9} {'wall[s]':>7} {'cpu[s]':>6} {'state':>12} "
             f"{'t_start':>7} "
             f"{'mser':>6} {'u_slip':>16} {'u_max':>16} {'u_max/u_slip':>16}"]
    for r in runs:
        def pm(e: dict[str, float]) -> str:
            return f"{e['value']:.4g}±{e['se']:.2g}"

        cpu = f"{r['cpu_seconds']:6.0f}" if "cpu_seconds" in r else f"{'-':>6}"
        lines.append(f"{r['label']:>10} {r['dt']:9.2e} {r['steps']:9d} "
                     f"{r['wall_seconds']:7.0f} {cpu} "
                     f"{r['flow_state']:>12} {r['t_start']:7.1f} {r['mser_start']:6.1f} "
                     f"{pm(r['u_slip']):>16} {pm(r['u_max']):>16} "
                     f"{pm(r['u_max_over_u_slip']):>16}")
    lines += ["", "pairs: per-bin z = diff/sqrt(se1^2+se2^2) over the folded half profile",
              f"{'pair':>21} {'q':>4} {'bins':>4} {'<2sig':>6} {'<3sig':>6} {'max|z|':>7} "
              f"{'chi2/bin':>8} {'max|diff|':>9} {'paper':>6}   z(u_slip) z(u_max)"]
    for p in pairs:
        for q in ("phi", "u"):
            c = p[q]
            lines.append(
                f"{p['a'] + '-' + p['b']:>21} {q:>4} {c['n_bins']:4d} "
                f"{c['frac_2sigma']:6.2f} {c['frac_3sigma']:6.2f} {c['max_abs_z']:7.2f} "
                f"{c['chi2_per_bin']:8.2f} {c['max_abs_diff']:9.3g} "
                f"{'equal' if c['paper_claims_equal'] else 'differ':>6}"
                + (f"   {p['u_slip']['z']:9.2f} {p['u_max']['z']:8.2f}" if q == "u" else ""))
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kn", type=float, nargs="+", default=[1e5, 1e6, 1e7])
    ap.add_argument("--W", type=float, default=16.0)
    ap.add_argument("--H", type=float, default=10.0)
    ap.add_argument("--B", type=float, default=6.0)
    ap.add_argument("--phi", type=float, default=0.59, help="phi_bar (000 fig. 10: 0.59, 0.61)")
    ap.add_argument("--T", type=float, default=400.0, help="run time per k_n, sqrt(d/g)")
    ap.add_argument("--discard", type=float, default=60.0, help="start of the averages")
    ap.add_argument("--sample-dt", type=float, default=0.1, help="sampling interval, sqrt(d/g)")
    ap.add_argument("--window", type=int, default=20, help="samples per window")
    ap.add_argument("--bin-width", type=float, default=0.5)
    ap.add_argument("--chunk", type=float, default=20.0, help="progress line every, sqrt(d/g)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=str(Path(__file__).parent / "out"))
    ap.add_argument("--force", action="store_true", help="rerun k_n whose tables exist")
    ap.add_argument("--control", action="store_true",
                    help="also the softest k_n with dt x 0.9 (null comparison)")
    ap.add_argument("--n-blocks", type=int, default=MIN_SE_BLOCKS,
                    help="long blocks for the second SE (fewer than "
                    f"{MIN_SE_BLOCKS}: no SE)")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    kns = sorted(a.kn)
    wanted = [(k, 1.0) for k in kns] + ([(kns[0], 0.9)] if a.control else [])
    todo = [(k, f) for k, f in wanted
            if a.force or not (out / f"channel_stiffness_kn_{tag(k, f)}_meta.json").exists()]
    if todo:
        # one packing for every k_n: poured at the softest prep stiffness, released at rest
        src = Channel(W=a.W, H=a.H, B=a.B, phi_bar=a.phi, kn=max(kns), dt=dt_for(max(kns)),
                      seed=a.seed, threads=1, preparation="pour")  # the recorded packing
        src.prepare()
        print(f"prepared: {src.prep_info}", flush=True)
        for kn, f in todo:
            run_one(src, kn, a, out, f)
    res: dict[str, Any] = {"params": {k: v for k, v in vars(a).items()
                                      if k not in ("force", "out")}}
    for name, nb in (("auto_blocks", None), (f"{a.n_blocks}_blocks", a.n_blocks)):
        runs = [analyse(tag(k, f), out, a.discard, nb) for k, f in wanted]
        main_runs = runs[:len(kns)]
        pairs = [compare(r1, r2, phi_claimed=min(r1["kn"], r2["kn"]) >= 1e6 or a.phi != 0.59)
                 for r1, r2 in itertools.combinations(main_runs, 2)]
        if a.control:
            pairs.append(compare(runs[0], runs[-1], phi_claimed=True))  # null pair
        res[name] = {"runs": runs, "pairs": pairs}
        print(f"\n== SE with {name.replace('_', ' ')} ==")
        print(table(runs, pairs))
    metas = res["auto_blocks"]["runs"]
    res["total_wall_seconds"] = float(sum(r["wall_seconds"] for r in metas))
    # runs written before CPU time was recorded count with their wall time (an upper bound)
    res["total_cpu_seconds_at_most"] = float(
        sum(r.get("cpu_seconds", r["wall_seconds"]) for r in metas))
    (out / "channel_stiffness.json").write_text(json.dumps(res, indent=1))
    print(f"\ntotal run time {res['total_wall_seconds']:.0f} s wall, <= "
          f"{res['total_cpu_seconds_at_most']:.0f} s CPU (1 thread); "
          f"wrote {out / 'channel_stiffness.json'}")


if __name__ == "__main__":
    main()
