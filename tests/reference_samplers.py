"""Reference samplers: the Python implementations the kernel's samplers replaced
(src/sampling/), kept only so that the tests can check the kernel's tables against them.

:class:`ChannelReference` is the channel's former per-sample binning (numpy, from the kernel's
positions, velocities, per-particle stats and contacts after a step with statistics);
:func:`cell_observe` the cell's former per-sample observables.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa
from granflow.scenes.cell import fabric

SIGMA = ["xx", "xy", "xz", "yx", "yy", "yz", "zx", "zy", "zz"]
AX = "xyz"


def cap_volume_below(z: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Volume of a sphere of radius r lying below a plane at signed height z above its centre."""
    zc = np.clip(z, -r, r)
    a = r + zc  # cap height
    return np.pi * a * a * (3 * r - a) / 3.0


class ChannelReference:
    """The former ``Channel._sample`` / ``_close_window``, driven from outside: call
    :meth:`sample` after every step taken with ``core.request_stats()`` at a sampling step."""

    def __init__(self, channel: Any) -> None:
        self.core = channel.core
        self.H, self.B, self.window = channel.H, channel.B, channel.window
        core = self.core
        self._d = core.diameters()
        self._m = core.masses()
        self._inertia = self._m * self._d**2 / 10
        self._edges = channel.bin_edges()
        self._vbin = np.diff(self._edges) * self.H * self.B
        self._bins: list[pa.Table] = []
        self._series: list[dict[str, float]] = []
        self._win: dict[str, Any] | None = None
        self._window_index = 0

    def tables(self) -> dict[str, pa.Table]:
        out = {}
        if self._bins:
            out["bins"] = pa.concat_tables(self._bins)
        if self._series:
            out["series"] = pa.Table.from_pylist(self._series)
        return out

    def sample(self) -> None:
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


def cell_observe(cell: Any) -> dict[str, float]:
    """The former ``ShearCell.observe()``: every cell observable of the current state."""
    self = cell
    core = self.core
    h = np.asarray(core.cell()[0])
    obs = dict(core.domain_observables())
    L = np.array([[obs[f"L_{a}{b}"] for b in AX] for a in AX])
    sc = np.array([[obs[f"sigma_c_{a}{b}"] for b in AX] for a in AX])
    sk = np.array([[obs[f"sigma_k_{a}{b}"] for b in AX] for a in AX])
    sig = sc + sk
    V = float(np.linalg.det(h))
    F = h @ np.linalg.inv(self._h0)
    # 002's convention: strain rate compressive-positive (D = -sym L, W = -skew L), with the
    # compressive-positive stress; (4.1)-(5.4) then hold as printed (mu1 > 0, mu2 = -N0/p)
    D = -0.5 * (L + L.T)
    W = -0.5 * (L - L.T)
    gd = float(np.sqrt(0.5 * np.sum(D * D)))
    p = float(np.trace(sig) / 3)
    sp = 0.5 * (sig + sig.T)
    ev, evec = np.linalg.eigh(D)
    order = np.argsort(ev)[::-1]
    ev, evec = ev[order], evec[:, order]
    d1h, d3h = evec[:, 0], evec[:, 2]
    G = np.outer(d3h, d1h) - np.outer(d1h, d3h)
    tiny = 1e-300
    beta = abs(float(np.sum(W * G)) / (gd * float(np.sum(G * G)))) if gd > tiny else 0.0
    sD = float(np.sum((sp - p * np.eye(3)) * D))  # deviatoric projection (cell_obs.rs)
    Dv = D - np.trace(D) / 3 * np.eye(3)  # (2.4)'s tensors from D's deviatoric part
    D2 = Dv @ Dv - np.trace(Dv @ Dv) / 3 * np.eye(3)
    DW = D @ W - W @ D
    ok = gd > tiny and p > tiny and abs(sD) > tiny
    mu1 = sD / (2 * gd * p) if ok else 0.0
    mu2 = 1.5 * float(np.sum(sp * D2)) / (gd * gd * p) if ok else 0.0
    mu3 = float(np.sum(sp * DW)) / (8 * gd * gd * p) if ok else 0.0
    n0 = -3 * float(np.sum(sp * D2)) / (gd * sD) if ok else 0.0
    n1 = float(np.sum(sp * DW)) / (gd * sD) if ok else 0.0
    I = gd * self.a / np.sqrt(p / self.mat.density) if p > tiny else 0.0  # noqa: E741
    # fabric (5.1): <n n> = I/3 + (2/15) A over contacts
    ids, dvec, _ = core.contacts()
    nc = len(ids)
    A = np.zeros((3, 3))
    z2 = 0.0
    theta = 0.0
    if nc:
        n = dvec / np.linalg.norm(dvec, axis=1)[:, None]
        A = fabric(n)
        z = np.bincount(ids.ravel(), minlength=core.n)
        keep = np.ones(core.n, bool)
        act = np.ones(nc, bool)
        while True:  # remove rattlers (< 2 contacts) iteratively
            bad = keep & (z < 2)
            if not bad.any():
                break
            keep &= ~bad
            act &= keep[ids[:, 0]] & keep[ids[:, 1]]
            z = np.bincount(ids[act].ravel(), minlength=core.n)
        z2 = 2 * act.sum() / keep.sum() if keep.sum() else 0.0
        # misalignment in the flow plane: compressive directions of D and of A (xy)
        def angle(m: np.ndarray, largest: bool) -> float:
            w, v = np.linalg.eigh(m[:2, :2])
            e = v[:, -1] if largest else v[:, 0]
            return float(np.degrees(np.arctan2(e[1], e[0])) % 180.0)

        if gd > tiny:
            diff = angle(A, True) - angle(D, True)
            theta = float((diff + 90.0) % 180.0 - 90.0)
    row: dict[str, float] = {"step": core.step, "t": core.time}
    for a, b in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):
        row[f"H_{AX[a]}{AX[b]}"] = h[a, b]
    for a in range(3):
        for b in range(3):
            row[f"F_{AX[a]}{AX[b]}"] = F[a, b]
    for a in range(3):
        for b in range(3):
            row[f"L_{AX[a]}{AX[b]}"] = L[a, b]
    for a, b in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):
        row[f"D_{AX[a]}{AX[b]}"] = D[a, b]
    row.update(W_xy=W[0, 1], W_xz=W[0, 2], W_yz=W[1, 2], shear_rate=gd,
               d1=ev[0], d2=ev[1], d3=ev[2], beta=beta, phi=self._vs / V, p=p)
    for name, m in (("sigma", sig), ("sigma_c", sc), ("sigma_k", sk)):
        for a in range(3):
            for b in range(3):
                row[f"{name}_{AX[a]}{AX[b]}"] = m[a, b]
    row.update(mu1=mu1, mu2=mu2, mu3=mu3, I=I, N0_tau=n0, N1_tau=n1)
    for a, b in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):
        row[f"A_{AX[a]}{AX[b]}"] = A[a, b]
    dg = core.diagnostics()
    row.update(Z2=z2, theta_c=theta, n_contacts=float(nc), max_overlap=dg["max_overlap"],
               tilt_flips=obs["tilt_flips"])
    for k, v in row.items():
        if not np.isfinite(v):
            raise FloatingPointError(f"non-finite cell observable {k}")
    return row
