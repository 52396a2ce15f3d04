"""The vertical channel of 000_260a8780d7c638a6 (Debnath, Kesava Rao & Kumaran 2022).

Polydisperse frictional spheres between two flat frictional walls at x = 0 and x = W, periodic
in y (vertical; gravity along -y) and z. Units: d (mean diameter), rho_p, sqrt(d/g).

Preparation (paper fig. 2, "fill and release"): spheres are placed at random in a tall region
above a floor, poured under gravity and settled; then the floor is removed and y made periodic
with period H. Protocol details that the paper leaves open, and our choices:

* pouring is frictionless and uses min(kn, prep_kn = 1e4), e_n = 0.3, dt = t_c/20 for speed; the
  bed is settled when the kinetic energy per particle is below ``settle_ke`` m g d; friction and
  the run's stiffness, restitution and dt apply from the release on (all tangential histories
  start at zero at the release);
* a frictionless pour packs to ~0.64, so every phi_bar up to random close packing can be made;
  the soft pour's overlaps are then relaxed at the run's kn (1000 damped steps, velocities
  quenched) so that a stiff run does not start with stored elastic energy;
  if the settled bed is taller than H (phi_bar close to the packing fraction) it is compressed
  affinely into [0, H) and relaxed without gravity before the release;
* the achieved phi_bar is exact: (total particle volume) / (W H B) with whole particles.

Statistics (000 eqs 2.1–2.5), sampled every ``sample_every`` steps and averaged over windows of
``window`` samples; each window is one row per bin of the ``bins`` table (docs/columns.md):

* bins across x: the two wall bins are ``wall_bin`` wide, the interior is tiled by
  ``n = round((W - 2 wall_bin)/bin_width)`` equal bins (width adjusted to tile exactly);
* particle quantities (count, velocity, spin, temperature, kinetic stress, power) go to the bin
  holding the particle's centre, as the paper does;
* the contact stress (2.4) shares each contact's r_ij (x) f_ij among the bins its branch vector
  crosses in proportion to the length inside each (the paper assigns half to each particle's
  bin; the length rule makes each bin's stress divergence balance its forces, which the
  centre rule does not at the scale of one bin); a wall contact's r (x) f, with r from the
  contact point to the centre, lies in the wall bin, so wall contacts count where they act;
* the volume fraction uses the exact sphere–slab intersection volumes (not centres);
* the temperature (2.3) and the kinetic stress use fluctuations about the window's bin means;
* Gamma (2.5) is -(1/V) sum_i P_i averaged over the samples, P_i = sum_j f_ij . v_ij / 2 (each
  contact's power split between its two particles; walls in full).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar

import numpy as np
import pyarrow as pa

from granflow import _core
from granflow.errors import ConfigurationError, ParameterError
from granflow.simulation import Box, ContactLaw, Simulation, Wall, contact_time
from granflow.sizes import SizeDist, discrete

from ._base import check_keys, register, run_with_checkpoints

RCP = 0.64
SIGMA = ["xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz"]


def _law(kn: float, e_n: float, mu: float, kt: float | None, ratio: float, form: str) -> ContactLaw:
    return ContactLaw(kn=kn, e_n=e_n, mu=mu, kt=kt, xi_t_ratio=ratio, form=form)


def cap_volume_below(z: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Volume of a sphere of radius r lying below a plane at signed height z above its centre."""
    zc = np.clip(z, -r, r)
    a = r + zc  # cap height
    return np.pi * a * a * (3 * r - a) / 3.0


@register("channel")
@dataclass
class Channel:
    """Vertical channel scene; every parameter has the paper's default (000 §2, App. A)."""

    W: float = 20.0
    H: float = 30.0
    B: float = 40.0
    phi_bar: float = 0.60
    sizes: dict[float, float] = field(default_factory=lambda: {0.9: 0.3, 1.0: 0.4, 1.1: 0.3})
    density: float = 1.0
    kn: float = 1e6
    kt: float | None = None
    e_n: float = 0.82
    xi_t_ratio: float = 0.5
    mu: float = 0.5
    wall_kn: float | None = None
    wall_e_n: float | None = None
    wall_mu: float | None = None
    form: str = "hooke"
    dt: float = 1.2e-4
    skin: float = 0.3
    bin_width: float = 1.0
    wall_bin: float = 1.5
    sample_every: int = 100
    window: int = 50
    settle_ke: float = 1e-4
    prep_kn: float = 1e4
    seed: int = 0
    threads: int | None = None

    scene_name: ClassVar[str]

    def __post_init__(self) -> None:
        self._validate()
        self.sim: Simulation | None = None
        self.prep_info: dict[str, Any] = {}
        self._bins: list[pa.Table] = []
        self._series: list[dict[str, float]] = []
        self._win: dict[str, Any] | None = None
        self._window_index = 0
        self.pbc = (False, True, True)

    # -- parameters ------------------------------------------------------------------------
    def _validate(self) -> None:
        def need(cond: bool, name: str, value: Any, allowed: str) -> None:
            if not cond:
                raise ParameterError(f"invalid {name} = {value!r}: allowed {allowed}")

        sd = self.size_dist()
        dmax = sd.max
        need(all(d > 0 for d in self.sizes) and all(f >= 0 for f in self.sizes.values())
             and abs(sum(self.sizes.values()) - 1) < 1e-6,
             "sizes", self.sizes, "positive diameters with number fractions summing to 1")
        need(np.isfinite(self.W) and self.W >= 5 * dmax, "W", self.W,
             f">= 5 d_max = {5 * dmax:g} (a channel a few diameters wide)")
        need(np.isfinite(self.H) and self.H >= 5 * dmax, "H", self.H, f">= {5 * dmax:g}")
        need(np.isfinite(self.B) and self.B >= 2 * (dmax + self.skin) + 0.5, "B", self.B,
             f">= {2 * (dmax + self.skin) + 0.5:g} (two interaction ranges)")
        need(0 < self.phi_bar <= RCP, "phi_bar", self.phi_bar,
             f"0 < phi_bar <= {RCP} (above random close packing the spheres cannot be packed)")
        need(self.dt > 0, "dt", self.dt, "> 0")
        need(self.bin_width > 0 and self.wall_bin > 0 and self.W - 2 * self.wall_bin >= 0,
             "bin_width/wall_bin", (self.bin_width, self.wall_bin),
             "positive widths with 2 wall_bin <= W")
        need(isinstance(self.sample_every, int) and self.sample_every >= 1, "sample_every",
             self.sample_every, "an integer >= 1")
        need(isinstance(self.window, int) and self.window >= 1, "window", self.window,
             "an integer >= 1")
        need(self.form in ("hooke", "hertz"), "form", self.form, "'hooke' or 'hertz'")

    def size_dist(self) -> SizeDist:
        return discrete({float(k): float(v) for k, v in self.sizes.items()})

    @classmethod
    def from_spec(cls, params: Mapping[str, Any], seed: int = 0,
                  threads: int | None = None) -> Channel:
        check_keys("params", params, {f.name for f in fields(cls)} - {"seed", "threads"})
        p = dict(params)
        if "sizes" in p:
            p["sizes"] = {float(k): float(v) for k, v in dict(p["sizes"]).items()}
        return cls(**p, seed=seed, threads=threads)

    def parameters(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "threads"}
        out["sizes"] = {str(k): v for k, v in self.sizes.items()}
        out.update({f"prep_{k}": v for k, v in self.prep_info.items()})
        return out

    @property
    def law(self) -> ContactLaw:
        return _law(self.kn, self.e_n, self.mu, self.kt, self.xi_t_ratio, self.form)

    @property
    def wall_law(self) -> ContactLaw:
        return _law(self.wall_kn or self.kn, self.wall_e_n or self.e_n,
                    self.mu if self.wall_mu is None else self.wall_mu,
                    None,  # kt: the kernel's default, 2/7 of the wall's kn (LawSpec)
                    self.xi_t_ratio, self.form)

    def bin_edges(self) -> np.ndarray:
        interior = self.W - 2 * self.wall_bin
        n = max(int(round(interior / self.bin_width)), 0)
        inner = np.linspace(self.wall_bin, self.W - self.wall_bin, n + 1) if n else np.array(
            [self.wall_bin])
        return np.concatenate([[0.0], inner, [self.W]]) if n else np.array(
            [0.0, self.wall_bin, self.W])

    # -- preparation -----------------------------------------------------------------------
    def prepare(self, progress: bool | None = None) -> None:
        """Fill and release (see the module docstring); does nothing if the channel is prepared
        already (or restored from a checkpoint)."""
        if self.sim is not None:
            return
        vol_target = self.phi_bar * self.W * self.H * self.B
        d = self.size_dist().diameters_for_volume(vol_target, self.seed)
        vs = float(np.sum(np.pi * d**3 / 6))
        phi_ins = 0.3
        h_fill = vs / (self.W * self.B * phi_ins) + 2 * d.max()
        x = np.asarray(_core.insert_spheres(
            d, (0.0, 0.0, 0.0), (self.W, h_fill, self.B), (False, False, True), self.seed))
        prep_law = _law(min(self.kn, self.prep_kn), 0.3, 0.0, None, self.xi_t_ratio, "hooke")
        box = Box(length=(self.W, h_fill, self.B), periodic=(False, False, True))
        walls = [Wall(0, 0.0, 1.0), Wall(0, self.W, -1.0), Wall(1, 0.0, 1.0)]
        dt = contact_time(prep_law, d, self.density) / 20
        sim = Simulation(x, d, box, prep_law, walls=walls, gravity=(0.0, -1.0, 0.0), dt=dt,
                         threads=self.threads, density=self.density, skin=self.skin)
        m = sim.core.masses()
        t_max = 40.0 + 4 * np.sqrt(2 * h_fill)
        check = max(int(0.5 / dt), 1)
        ke = np.inf
        while sim.time < t_max:
            sim.run(check, progress=progress)
            ke = sim.energies()["kinetic_translational"] / len(d) / float(np.mean(m))
            if ke < self.settle_ke and sim.time > np.sqrt(2 * h_fill):
                break
        else:
            raise ParameterError(
                f"invalid settle_ke = {self.settle_ke}: the bed did not settle within "
                f"t = {t_max:.0f} sqrt(d/g) (kinetic energy per particle {ke:.2e} m g d); "
                "allowed a larger value"
            )
        x = sim.get_positions()
        r = d / 2
        top = float(np.max(x[:, 1] + r))
        compressed = top > self.H
        if compressed:
            # squeeze the bed affinely into [0, H) and relax without gravity
            ymax = self.H - 0.5 * d.max()
            x[:, 1] = r + (x[:, 1] - r) * (ymax - r.max()) / (np.max(x[:, 1]) - r.max())
            box = Box(length=(self.W, self.H, self.B), periodic=(False, True, True))
            rel = Simulation(x, d, box, prep_law, walls=walls[:2], dt=dt, threads=self.threads,
                             density=self.density, skin=self.skin)
            for _ in range(20):
                rel.run(200, progress=False)
                rel.set_velocities(np.zeros_like(x))
                if rel.diagnostics()["max_overlap"] < 0.01:
                    break
            x = rel.get_positions()
        if self.kn > self.prep_kn and not compressed:
            # the soft pour leaves overlaps ~ load/prep_kn; relax them at the run's stiffness
            # (frictionless, damped, same geometry and load) so the release does not start with
            # a burst of stored elastic energy at large kn
            # (a bed squeezed into H was already relaxed without gravity above)
            stiff = _law(self.kn, 0.3, 0.0, None, self.xi_t_ratio, "hooke")
            g = (0.0, -1.0, 0.0)
            walls_now = walls
            rel_box = Box(length=(self.W, h_fill, self.B), periodic=(False, False, True))
            stiff_sim = Simulation(x, d, rel_box, stiff, walls=walls_now, gravity=g,
                                   dt=contact_time(stiff, d, self.density) / 20,
                                   threads=self.threads,
                                   density=self.density, skin=self.skin)
            for _ in range(10):
                stiff_sim.run(100, progress=False)
                stiff_sim.set_velocities(np.zeros_like(x))
                stiff_sim.set_angular_velocities(np.zeros_like(x))
            x = stiff_sim.get_positions()
        self._release(x, d, {
            "n": int(len(d)),
            "phi_bar_achieved": vs / (self.W * self.H * self.B),
            "bed_top": top,
            "compressed": bool(compressed),
            "settle_time": float(sim.time),
            "settle_ke": float(ke),
        })

    def _release(self, x: np.ndarray, d: np.ndarray, prep_info: dict[str, Any]) -> None:
        """The release: the run's simulation (periodic in y, walls, the run's law and dt) from
        prepared positions ``x``, at rest."""
        self.sim = Simulation(
            x, d, Box(length=(self.W, self.H, self.B), periodic=(False, True, True)), self.law,
            density=self.density, walls=[Wall(0, 0.0, 1.0), Wall(0, self.W, -1.0)],
            wall_law=self.wall_law, gravity=(0.0, -1.0, 0.0), dt=self.dt, skin=self.skin,
            threads=self.threads,
        )
        self.prep_info = dict(prep_info)
        self._cache_static()

    def prepare_from(self, other: Channel) -> None:
        """Start from the prepared (released, at rest) packing of ``other`` instead of pouring
        a new one: the same particles in the same place, with this channel's law, dt and
        sampling (e.g. one packing run at several kn). ``other`` must be prepared and not yet
        run, with the same geometry."""
        other.prepare()
        core = other.core
        for name in ("W", "H", "B", "density"):
            if getattr(self, name) != getattr(other, name):
                raise ParameterError(
                    f"invalid {name} = {getattr(self, name)!r}: allowed {getattr(other, name)!r} "
                    "(the packing's value)")
        if core.step != 0:
            raise ParameterError(
                f"invalid source channel at step {core.step}: allowed a freshly prepared one "
                "(step 0, at rest)")
        self._release(np.array(core.positions()), np.array(core.diameters()),
                      {**other.prep_info, "prepared_with_kn": other.kn})

    def _cache_static(self) -> None:
        core = self.core
        self._d = core.diameters()
        self._m = core.masses()
        self._inertia = self._m * self._d**2 / 10
        self._edges = self.bin_edges()
        self._vbin = np.diff(self._edges) * self.H * self.B

    def _simulation(self) -> Simulation:
        if self.sim is None:
            raise ConfigurationError(
                "channel not prepared: call prepare() (or run(), or restore()) first")
        return self.sim

    @property
    def core(self) -> _core.Sim:
        """The kernel simulation of the prepared channel (after :meth:`prepare`, :meth:`run`
        or :meth:`restore`; before, a :class:`granflow.ConfigurationError`)."""
        return self._simulation().core

    @property
    def achieved_phi_bar(self) -> float:
        """(total particle volume) / (W H B) of the prepared packing (prepares if needed)."""
        self.prepare()
        return float(self.prep_info["phi_bar_achieved"])

    # -- sampling ----------------------------------------------------------------------------
    def _sample(self) -> None:
        core = self.core
        x, v, w = core.positions(), core.velocities(), core.angular_velocities()
        s_c, power = core.particle_stats()
        m, inertia, r = self._m, self._inertia, self._d / 2
        edges = self._edges
        nb = len(edges) - 1
        b = np.clip(np.searchsorted(edges, x[:, 0], side="right") - 1, 0, nb - 1)

        def bsum(vals: np.ndarray) -> np.ndarray:
            if vals.ndim == 1:
                return np.bincount(b, weights=vals, minlength=nb)
            return np.stack([np.bincount(b, weights=vals[:, k], minlength=nb)
                             for k in range(vals.shape[1])], axis=1)

        below = cap_volume_below(edges[None, :] - x[:, :1], r[:, None])
        vol = (below[:, 1:] - below[:, :-1]).sum(axis=0)
        mv = m[:, None] * v
        vv = (mv[:, :, None] * v[:, None, :]).reshape(-1, 9)
        sc_bins = self._contact_stress_bins(core, x, s_c, edges)
        acc = {
            "count": np.bincount(b, minlength=nb).astype(float),
            "vol": vol,
            "m": bsum(m),
            "mv": bsum(mv),
            "mvv": bsum(vv),
            "I": bsum(inertia),
            "Iw": bsum(inertia[:, None] * w),
            "Iww": bsum(inertia * np.einsum("ij,ij->i", w, w)),
            "sc": sc_bins,
            "P": bsum(power),
        }
        if self._win is None:
            self._win = {"t0": core.time, "n": 0, **{k: np.zeros_like(a) for k, a in acc.items()}}
        win = self._win
        for k, a in acc.items():
            win[k] += a
        win["n"] += 1
        # time series
        mt = float(m.sum())
        e = core.energies()
        wf = np.asarray(core.wall_forces())
        wi = np.asarray(core.wall_impulse())
        area = self.H * self.B
        dg = core.diagnostics()
        mv_tot = (m[:, None] * v).sum(axis=0)
        vcm = mv_tot / mt
        self._series.append({
            "step": core.step, "t": core.time, "vcm_x": vcm[0], "vcm_y": vcm[1], "vcm_z": vcm[2],
            "ke_trans": e[0], "ke_rot": e[1],
            "wall0_sigma_xx": wf[0, 0] / area, "wall0_sigma_xy": wf[0, 1] / area,
            "wall0_sigma_xz": wf[0, 2] / area, "wall1_sigma_xx": wf[1, 0] / area,
            "wall1_sigma_xy": wf[1, 1] / area, "wall1_sigma_xz": wf[1, 2] / area,
            "n_contacts": float(dg["contacts"]), "max_overlap": dg["max_overlap"],
            "px": float(mv_tot[0]), "py": float(mv_tot[1]), "pz": float(mv_tot[2]),
            "wall_impulse_x": float(wi[:, 0].sum()), "wall_impulse_y": float(wi[:, 1].sum()),
            "wall_impulse_z": float(wi[:, 2].sum()),
        })
        if win["n"] >= self.window:
            self._win = None
            self._close_window(win, core.time)

    @staticmethod
    def _contact_stress_bins(core: Any, x: np.ndarray, s_c: np.ndarray,
                             edges: np.ndarray) -> np.ndarray:
        """Contact stress sums per bin: each pair contact's r_ij (x) f_ij is shared among the
        bins its branch vector crosses, in proportion to the length inside each (so the bins'
        stress divergence balances their forces exactly, as in the method of planes); wall
        contacts (branch vector inside the wall bin) go to the particle's bin."""
        nb = len(edges) - 1
        ids, d, f = core.contacts()
        full = (d[:, :, None] * f[:, None, :]).reshape(-1, 9)
        n = len(x)
        pair_share = np.zeros((n, 9))
        for col in (0, 1):
            for k in range(9):
                pair_share[:, k] += np.bincount(ids[:, col], weights=0.5 * full[:, k],
                                                minlength=n)
        wall_part = s_c - pair_share
        b = np.clip(np.searchsorted(edges, x[:, 0], side="right") - 1, 0, nb - 1)
        out = np.stack([np.bincount(b, weights=wall_part[:, k], minlength=nb)
                        for k in range(9)], axis=1)
        xi = x[ids[:, 0], 0]
        xj = xi - d[:, 0]
        lo, hi = np.minimum(xi, xj), np.maximum(xi, xj)
        span = hi - lo
        k0 = np.clip(np.searchsorted(edges, lo, side="right") - 1, 0, nb - 1)
        k1 = np.clip(np.searchsorted(edges, hi, side="right") - 1, 0, nb - 1)
        flat = span < 1e-12
        for o in range(int((k1 - k0).max(initial=0)) + 1):
            k = np.minimum(k0 + o, nb - 1)
            ov = np.minimum(hi, edges[k + 1]) - np.maximum(lo, edges[k])
            w = np.where(flat, (o == 0) * 1.0, np.clip(ov, 0, None) / np.where(flat, 1, span))
            w = np.where(k0 + o <= k1, w, 0.0)
            for c in range(9):
                out[:, c] += np.bincount(k, weights=w * full[:, c], minlength=nb)
        return out

    def _close_window(self, a: dict[str, Any], t1: float) -> None:
        """Append the bins rows of the window of sums ``a`` closed at time ``t1``."""
        ns = a["n"]
        edges = self._edges
        nb = len(edges) - 1
        vb = self._vbin * ns
        msum = a["m"]
        safe = np.where(msum > 0, msum, 1.0)
        u = a["mv"] / safe[:, None]
        isafe = np.where(a["I"] > 0, a["I"], 1.0)
        om = a["Iw"] / isafe[:, None]
        cnt = a["count"]
        fluct_t = a["mvv"][:, [0, 4, 8]].sum(axis=1) - np.einsum("bk,bk->b", a["mv"], u)
        fluct_r = a["Iww"] - np.einsum("bk,bk->b", a["Iw"], om)
        T = np.where(cnt > 0, (fluct_t + fluct_r) / (6 * np.where(cnt > 0, cnt, 1)), 0.0)
        sk = (a["mvv"] - (a["mv"][:, :, None] * u[:, None, :]).reshape(nb, 9)) / vb[:, None]
        sc = a["sc"] / vb[:, None]
        st = sk + sc
        xc = 0.5 * (edges[1:] + edges[:-1])
        uy = np.where(msum > 0, u[:, 1], 0.0)
        dudx = np.gradient(uy, xc) if nb > 1 else np.zeros(nb)
        cols: dict[str, Any] = {
            "window": np.full(nb, self._window_index, dtype=np.int64),
            "t0": np.full(nb, a["t0"]), "t1": np.full(nb, t1),
            "n_samples": np.full(nb, ns, dtype=np.int64),
            "bin": np.arange(nb, dtype=np.int64),
            "x_lo": edges[:-1], "x_hi": edges[1:], "x": xc,
            "count": cnt / ns, "phi": a["vol"] / vb,
            "u_x": u[:, 0], "u_y": u[:, 1], "u_z": u[:, 2],
            "w_x": om[:, 0], "w_y": om[:, 1], "w_z": om[:, 2], "T": T,
        }
        for k, c in enumerate(SIGMA):
            cols[f"sigma_{c}"] = st[:, k]
        for k, c in enumerate(SIGMA):
            cols[f"sigma_c_{c}"] = sc[:, k]
        for k, c in enumerate(SIGMA):
            cols[f"sigma_k_{c}"] = sk[:, k]
        cols["Gamma"] = -a["P"] / vb
        cols["shear_production"] = st[:, 1] * dudx
        tab = pa.table(cols)
        for name in tab.column_names:
            col = tab[name].to_numpy()
            if col.dtype.kind == "f" and not np.isfinite(col).all():
                raise FloatingPointError(f"non-finite value in bins column {name}")
        self._bins.append(tab)
        self._window_index += 1

    # -- protocol ----------------------------------------------------------------------------
    def run(self, steps: int, progress: bool | None = None,
            checkpoint: str | os.PathLike[str] | None = None,
            checkpoint_every: int | None = None) -> None:
        """Advance ``steps`` steps (preparing first if needed), sampling every
        ``sample_every`` steps; ``checkpoint`` and ``checkpoint_every`` as
        :class:`granflow.scenes.Scene` says."""
        self.prepare(progress=progress)
        sim = self._simulation()
        core = sim.core

        def advance(steps: int) -> None:
            target = core.step + int(steps)
            while core.step < target:
                to_sample = self.sample_every - core.step % self.sample_every
                c = min(to_sample, target - core.step)
                if c > 1:
                    sim.run(c - 1, progress=progress)
                if core.step % self.sample_every == self.sample_every - 1:
                    core.request_stats()
                    sim.run(1, progress=False)
                    self._sample()
                elif core.step < target:
                    sim.run(1, progress=False)

        run_with_checkpoints(self, steps, advance, checkpoint, checkpoint_every)

    def tables(self) -> dict[str, pa.Table]:
        out = {}
        if self._bins:
            out["bins"] = pa.concat_tables(self._bins)
        if self._series:
            out["series"] = pa.Table.from_pylist(self._series)
        return out

    def load_tables(self, tables: Mapping[str, pa.Table]) -> None:
        if "bins" in tables:
            self._bins = [tables["bins"]]
            self._window_index = int(tables["bins"]["window"].to_numpy().max()) + 1
        if "series" in tables:
            self._series = tables["series"].to_pylist()

    def summary(self) -> dict[str, Any]:
        """The paper's analysis (granflow.analysis.channel.summary) flattened to scalars."""
        from granflow.analysis import channel as ach
        from granflow.analysis.channel_profiles import flow_state

        t = self.tables()
        out: dict[str, Any] = {"n": self.prep_info.get("n"),
                               "phi_bar_achieved": self.prep_info.get("phi_bar_achieved")}
        if "series" in t:
            fs = flow_state(t["series"])
            out["flow_state"] = fs.state
        if "bins" not in t or t["bins"].num_rows == 0:
            return out
        try:
            s = ach.summary(t["bins"], t.get("series"))
        except Exception as exc:  # too little data for the analysis: say so, keep the rest
            out["analysis_error"] = f"{type(exc).__name__}: {exc}"
            return out
        for k, v in s.items():
            if isinstance(v, dict) and "value" in v:
                out[k] = v["value"]
                out[k + "_se"] = v.get("se")
            elif isinstance(v, (int, float, str, bool)):
                out[k] = v
        return out

    def save_checkpoint(self, path: str | os.PathLike[str]) -> None:
        from granflow.io import atomic_path

        self.prepare()
        # the preparation record rides beside the kernel checkpoint (written first: a
        # checkpoint never exists without it)
        with atomic_path(f"{os.fspath(path)}.prep.json") as tmp:
            tmp.write_text(json.dumps(self.prep_info))
        self._simulation().save_checkpoint(path)

    def restore(self, path: str | os.PathLike[str]) -> None:
        self.sim = Simulation.from_checkpoint(path, threads=self.threads)
        prep = f"{os.fspath(path)}.prep.json"
        if os.path.exists(prep):
            with open(prep) as f:
                self.prep_info = json.load(f)
        self._cache_static()
        self._win = None
