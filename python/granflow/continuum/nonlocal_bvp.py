"""The nonlocal granular fluidity model of the channel (Henann & Kamrin, PNAS 110, 6730, 2013):
a boundary-value problem solved by collocation, with continuation in the amplitude A."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.integrate import solve_bvp

from granflow.errors import GranflowError

from ._checks import FloatArray, bad, finite
from .laws import LocalLaw
from .local import _g_loc, _local_profile, _quantities, _stress_ratio_error
from .problem import ChannelProblem, Profile


class _Nonlocal:
    """Right-hand side and Jacobian of the nonlocal system in ``y = [S, g, q]`` (in ``x``):

    ``S' = -rho_p g phi(I)``, ``I = mu g d / sqrt(sigma_xx/rho_p)``, ``mu = S/sigma_xx``;
    ``g' = q / (A d)``; ``q' = |mu - mu_s| (g - g_loc(mu)) / (A d)``.  That is Henann &
    Kamrin's ``g = g_loc + xi^2 g''``, ``xi = A d / sqrt(|mu - mu_s|)``, multiplied through by
    ``|mu - mu_s|`` so that ``mu = mu_s`` is not singular, with ``q = A d g'`` in place of
    ``h = g'``: written with ``h``, ``h' = (A d)^-2 ...`` amplifies the collocation error of
    ``g`` by ``(A d)^-2`` in the residual solve_bvp controls, and for small ``A`` it refines
    the mesh far beyond what the solution needs; with ``q`` both equations carry ``(A d)^-1``.
    ``u' = mu g`` does not feed back and is integrated afterwards (:meth:`_Form.solution`).

    Limitation: where ``g`` is close to 0 (deep in a plug at small ``A``, or a tiny
    ``g_wall``) and ``a_phi`` is small (below ~0.6), ``phi(I) ~ I^a_phi`` is so steep at
    ``I = 0`` that the collocation error of ``g`` (~1e-13) shows in the residual of ``S'``;
    solve_bvp then needs many nodes, or the tolerance is relaxed (see :func:`solve_nonlocal`).
    """

    def __init__(self, law: LocalLaw, A: float, prob: ChannelProblem) -> None:
        self.law, self.prob = law, prob
        self.rg = prob.rho_p * prob.g
        self.sxx = prob.sigma_xx
        self.c = prob.shear_rate_scale
        self.k = 1.0 / (A * prob.d)

    def g_loc(self, mu: FloatArray) -> FloatArray:
        return _g_loc(self.law, mu, self.c)

    def f(self, y: FloatArray) -> FloatArray:
        law = self.law
        s, g, q = y[0], y[1], y[2]
        mu = s / self.sxx
        return np.vstack(
            (
                -self.rg * law.phi(mu * g / self.c),
                self.k * q,
                self.k * np.abs(mu - law.mu_s) * (g - self.g_loc(mu)),
            )
        )

    def jac(self, y: FloatArray) -> FloatArray:
        law = self.law
        s, g = y[0], y[1]
        mu = s / self.sxx
        i = mu * g / self.c
        m = mu - law.mu_s
        # dphi/dI, 0 where phi(I) is clipped; I bounded away from 0 where a_phi < 1
        inside = (i > 0) & (i < law.I_max)
        i_safe = np.clip(i, 1e-12 * law.I_max, law.I_max)
        dphi = np.where(inside, law.dphi_dI(i_safe), 0.0)
        gl = self.g_loc(mu)
        # |mu - mu_s| d g_loc/dmu, written without the (mu - mu_s)^(1/a_mu - 1) singularity
        i_loc = law.I_of_mu(mu)
        mu_safe = np.where(i_loc > 0, mu, 1.0)
        m_dgl = np.where(
            i_loc > 0,
            self.c * (law.excess_dI_dmu(mu) / mu_safe - m * i_loc / mu_safe**2),
            0.0,
        )
        J = np.zeros((3, 3, y.shape[1]))
        J[0, 0] = -self.rg * dphi * g / (self.c * self.sxx)
        J[0, 1] = -self.rg * dphi * mu / self.c
        J[1, 2] = self.k
        J[2, 0] = self.k * (np.sign(m) * (g - gl) - m_dgl) / self.sxx
        J[2, 1] = self.k * np.abs(m)
        return J


class _RoundOff(Exception):
    """solve_bvp refined the mesh to where round-off dominates the residual."""


_GAUSS_T, _GAUSS_W = np.polynomial.legendre.leggauss(4)


class _Form:
    """The nonlocal BVP in a mapped variable ``t in [0, 1]``, in one of two forms.

    ``single``: ``y = [S, g, q]`` on ``[x0, W/2]``; ``g(x0) = g_wall``, ``S(W/2) = 0``,
    ``q(W/2) = 0``.  ``split`` (used when the wall yields, ``mu(x0) > mu_s``): two copies,
    on ``[x0, x_p]`` and ``[x_p, W/2]``, with the yield point ``x_p`` an unknown parameter
    fixed by ``S(x_p) = mu_s sigma_xx`` and ``S, g, q`` continuous there (7 conditions for
    6 equations and 1 parameter).  ``|mu - mu_s|`` has a kink at ``x_p``; with ``x_p`` inside
    an interval the collocation residual only falls like the spacing times ``(A d)^-1``, and
    for small ``A`` solve_bvp refines into round-off before reaching ``tol``.  The split puts
    the kink on the mesh end points.

    Each region ``[lo, hi]`` is mapped by ``x = lo + (hi - lo) (3 t^2 - 2 t^3)``, which
    compresses the mesh towards both ends, where the right-hand side has power-law
    singularities: ``phi(I)`` goes like ``(W/2 - x)^a_phi`` at the centre (``I ~ mu`` there)
    and like ``(x - x0 + delta)^a_phi`` at a wall with small ``g_wall`` (``I ~ g``),
    ``|mu - mu_s| g_loc`` like ``(x_p - x)^(1 + 1/a_mu)`` at the yield point.  The map turns
    ``|x - end|^q`` into ``t^(2q + 1)``, smooth enough for the collocation.
    """

    def __init__(self, sys: _Nonlocal, split: bool, tol: float, y_scale: float) -> None:
        self.sys, self.split = sys, split
        self.x0, self.xc = sys.prob.x0, sys.prob.half_width
        self.nr = 2 if split else 1
        # below this spacing the residual computed from differences of y is round-off
        self.h_floor = max(1e-13, 0.3 * np.finfo(float).eps * y_scale / tol)

    def bounds(self, p: FloatArray | None) -> list[tuple[float, float]]:
        if self.split:
            assert p is not None
            return [(self.x0, float(p[0])), (float(p[0]), self.xc)]
        return [(self.x0, self.xc)]

    @staticmethod
    def dxdt(lo: float, hi: float, t: FloatArray) -> FloatArray:
        return np.asarray(6.0 * (hi - lo) * t * (1.0 - t))

    @staticmethod
    def x_of_t(lo: float, hi: float, t: FloatArray) -> FloatArray:
        return np.asarray(lo + (hi - lo) * t * t * (3.0 - 2.0 * t))

    @staticmethod
    def t_of_x(lo: float, hi: float, x: FloatArray) -> FloatArray:
        """Inverse of :meth:`x_of_t` (closed form, then one Newton step for the ends)."""
        s = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
        t = 0.5 - np.sin(np.arcsin(1.0 - 2.0 * s) / 3.0)
        ds = 6.0 * t * (1.0 - t)
        step = np.divide(t * t * (3.0 - 2.0 * t) - s, ds, out=np.zeros_like(t), where=ds > 0)
        return np.asarray(np.clip(t - step, 0.0, 1.0))

    def fun(self, t: FloatArray, y: FloatArray, p: FloatArray | None = None) -> FloatArray:
        if t.size > 1:
            dt = np.diff(t)
            k = int(np.argmin(dt))
            if 0 < dt[k] < self.h_floor:
                raise _RoundOff(
                    f"mesh refined to spacing {dt[k]:.2g} (of the unit interval) at "
                    f"t = {t[k]:.8g}, where round-off exceeds the tolerance"
                )
        out = np.empty_like(y)
        for r, (lo, hi) in enumerate(self.bounds(p)):
            out[3 * r : 3 * r + 3] = self.dxdt(lo, hi, t) * self.sys.f(y[3 * r : 3 * r + 3])
        return out

    def jac(
        self, t: FloatArray, y: FloatArray, p: FloatArray | None = None
    ) -> FloatArray | tuple[FloatArray, FloatArray]:
        n = 3 * self.nr
        dfdy = np.zeros((n, n, t.size))
        dfdp = np.zeros((n, 1, t.size))
        for r, (lo, hi) in enumerate(self.bounds(p)):
            sl = slice(3 * r, 3 * r + 3)
            dfdy[sl, sl] = self.dxdt(lo, hi, t) * self.sys.jac(y[sl])
            if self.split:
                # d(dx/dt)/dx_p: +6 t (1 - t) on [x0, x_p], -6 t (1 - t) on [x_p, W/2]
                dfdp[sl, 0] = (6.0 if r == 0 else -6.0) * t * (1.0 - t) * self.sys.f(y[sl])
        return (dfdy, dfdp) if self.split else dfdy

    def bc(self, ya: FloatArray, yb: FloatArray, p: FloatArray | None = None) -> FloatArray:
        gw = self.sys.prob.g_wall
        assert gw is not None
        if not self.split:
            return np.array([ya[1] - gw, yb[0], yb[2]])
        return np.array(
            [
                ya[1] - gw,
                yb[3],
                yb[5],
                yb[0] - ya[3],
                yb[1] - ya[4],
                yb[2] - ya[5],
                yb[0] - self.sys.law.mu_s * self.sys.sxx,
            ]
        )

    def bc_jac(
        self, _ya: FloatArray, _yb: FloatArray, _p: FloatArray | None = None
    ) -> tuple[FloatArray, ...]:
        if not self.split:
            ja, jb = np.zeros((3, 3)), np.zeros((3, 3))
            ja[0, 1] = jb[1, 0] = jb[2, 2] = 1.0
            return ja, jb
        ja, jb = np.zeros((7, 6)), np.zeros((7, 6))
        ja[0, 1] = jb[1, 3] = jb[2, 5] = jb[6, 0] = 1.0
        for r in range(3):
            jb[3 + r, r] = 1.0
            ja[3 + r, 3 + r] = -1.0
        return ja, jb, np.zeros((7, 1))

    def start(
        self, guess: Callable[[FloatArray], FloatArray], mesh: FloatArray, xp: float
    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        p = np.array([xp]) if self.split else None
        ys = [guess(self.x_of_t(lo, hi, mesh)) for lo, hi in self.bounds(p)]
        return mesh, np.vstack(ys), p

    def valid(self, res: Any) -> bool:
        return not self.split or bool(self.x0 < float(res.p[0]) < self.xc)

    def solution(self, res: Any) -> Callable[[FloatArray], FloatArray]:
        """``x -> [S, g, q, u]`` from the collocation solution; ``u = u_wall + int mu g dx``
        by 4-point Gauss on each mesh interval, exact for the cubic interpolant."""
        p = res.p if self.split else None
        bounds = self.bounds(p)
        tm = res.x
        sxx, u_wall = self.sys.sxx, self.sys.prob.u_wall

        def du_dt(r: int, t: FloatArray) -> FloatArray:
            lo, hi = bounds[r]
            y = res.sol(t)[3 * r : 3 * r + 3]
            return np.asarray(self.dxdt(lo, hi, t) * (y[0] / sxx) * y[1])

        def gauss(r: int, a: FloatArray, b: FloatArray) -> FloatArray:
            half = 0.5 * (b - a)
            nodes = a[:, None] + half[:, None] * (_GAUSS_T[None, :] + 1.0)
            vals = du_dt(r, nodes.ravel()).reshape(nodes.shape)
            return np.asarray(half * (vals @ _GAUSS_W))

        cum: list[FloatArray] = []
        start = u_wall
        for r in range(self.nr):
            c = start + np.concatenate(([0.0], np.cumsum(gauss(r, tm[:-1], tm[1:]))))
            cum.append(c)
            start = float(c[-1])

        def y_at(x: FloatArray) -> FloatArray:
            x = np.asarray(x, dtype=np.float64)
            out = np.empty((4, x.size))
            region = (x >= bounds[1][0]).astype(int) if self.split else np.zeros(x.size, int)
            for r, (lo, hi) in enumerate(bounds):
                sel = region == r
                if not np.any(sel):
                    continue
                t = self.t_of_x(lo, hi, x[sel])
                out[:3, sel] = res.sol(t)[3 * r : 3 * r + 3]
                i = np.clip(np.searchsorted(tm, t, side="right") - 1, 0, tm.size - 2)
                out[3, sel] = cum[r][i] + gauss(r, tm[i], t)
            return out

        return y_at


def _decay(t: FloatArray) -> FloatArray:
    """``exp(-t)`` for ``t >= 0`` without underflow (0 past ``t = 600``)."""
    return np.asarray(np.where(t < 600.0, np.exp(-np.minimum(t, 600.0)), 0.0))


def _guess(
    A: float, prob: ChannelProblem, local: Profile
) -> tuple[Callable[[FloatArray], FloatArray], float]:
    """Initial guess ``[S, g, q = A d g'](x)`` for the BVP, and its wall-layer length ``l``:
    the local solution with ``g = max(g_loc, small)`` blended into ``g_wall`` over
    ``l = A d / sqrt(0.05)`` (the cooperativity length at ``|mu - mu_s| = 0.05``)."""
    assert prob.g_wall is not None and local.evaluate is not None
    evaluate = local.evaluate
    ell = A * prob.d / math.sqrt(0.05)
    small = 1e-6 * prob.g_wall
    dg = prob.g_wall - max(float(local.fluidity[0]), small)

    def y_of_x(x: FloatArray) -> FloatArray:
        q = evaluate(x)
        b = _decay((x - prob.x0) / ell)
        g = np.maximum(q["fluidity"], small) + dg * b
        return np.vstack((q["sigma_xy"], g, -A * prob.d * dg * b / ell))

    return y_of_x, ell


def _unit_mesh(ell_rel: float) -> FloatArray:
    """401 uniform points on [0, 1] plus points graded geometrically towards 0 over the
    relative wall-layer length ``ell_rel`` (no finer than 1e-5, far above round-off)."""
    lo = max(0.02 * ell_rel, 1e-5)
    graded = np.geomspace(lo, max(20.0 * ell_rel, 10.0 * lo), 60)
    return np.unique(np.concatenate((np.linspace(0.0, 1.0, 401), graded[graded < 1.0])))


def solve_nonlocal(
    law: LocalLaw,
    A: float,
    prob: ChannelProblem,
    n: int = 2001,
    tol: float = 1e-8,
    max_nodes: int = 200_000,
) -> Profile:
    """Nonlocal granular fluidity solution (Henann & Kamrin 2013) on ``n`` uniform points.

    Solves ``S' = -rho_p g phi(I)``, ``(A d)^2 g'' = |mu - mu_s| (g - g_loc(mu))`` (see
    :class:`_Nonlocal`) on ``[x0, W/2]`` with ``g(x0) = g_wall``, ``S(W/2) = 0`` and
    ``g'(W/2) = 0`` (symmetry) by collocation (scipy ``solve_bvp``, relative residual tolerance
    ``tol``, analytic Jacobian), then ``u = u_wall + int_{x0}^x mu g dx`` by quadrature of
    the collocation solution.  When the wall yields (``mu(x0) > mu_s``) the problem is split at
    the yield point (:class:`_Form`); otherwise, or if the split solve fails, it is solved on
    ``[x0, W/2]`` in one piece.  The initial guess is the local solution with ``g`` blended into
    ``g_wall`` near the wall; if a solve fails it is continued from a larger ``A`` (wider,
    smoother boundary layers) down to ``A``.

    ``info`` records ``max_residual`` (solve_bvp's largest relative residual), ``nodes``
    (mesh size; the split form carries both parts on one mesh), ``form`` ("split"/"single"),
    ``x_yield`` (the split point, or None), ``A_path`` (the amplitudes solved at),
    ``failed_forms``, ``tol`` (the tolerance reached), ``mu_wall``, ``I_wall`` and
    ``I_max_exceeded`` (``phi`` is held at ``phi(I_max)`` wherever ``I = mu g d /
    sqrt(sigma_xx/rho_p)`` exceeds ``I_max``, which a large ``g_wall`` can cause).

    The kink that this clipping puts in ``phi``, or ``phi ~ I^a_phi`` with a small ``a_phi``
    where ``g ~ 0`` (see :class:`_Nonlocal`), can keep the residual above a tight ``tol`` until
    the mesh spacing reaches round-off (detected, rather than refined to ``max_nodes``); the
    solve is then repeated at ``100 tol`` and ``10^4 tol`` (not above 1e-4), with a
    RuntimeWarning and ``info["tol"]`` saying so.

    Raises ParameterError for ``A <= 0``, ``g_wall`` missing, or a stress ratio above
    ``law.mu_max`` (``g_loc`` would be needed where the law was not calibrated);
    GranflowError when solve_bvp does not converge.
    """
    finite("A", A)
    if A <= 0:
        raise bad("A", A, "> 0")
    if prob.g_wall is None:
        raise bad("g_wall", None, "> 0 (the nonlocal model needs the wall fluidity)")
    if not (tol > 0 and math.isfinite(tol)):
        raise bad("tol", tol, "> 0")
    if int(n) != n or n < 3:
        raise bad("n", n, "an integer >= 3")
    rg = prob.rho_p * prob.g
    x0, xc = prob.x0, prob.half_width
    # phi >= phi(I_max) everywhere, so this is a lower bound on the wall stress ratio
    mu_wall_min = rg * float(law.phi(law.I_max)) * (xc - x0) / prob.sigma_xx
    if mu_wall_min > law.mu_max:
        raise _stress_ratio_error(law, mu_wall_min, prob)

    with np.errstate(under="ignore"):
        local = _local_profile(law, prob, 2001)
        x_edge = float(local.info["x_plug_edge"])
        # phi <= phi_0 = the local plug's phi, so the nonlocal sigma_xy(x0) is at most the local
        # one wherever g >= g_loc: a wall that does not yield in the local solution does not
        # yield here either, and only a yielding wall (mu_s > 0) needs the split form
        splits = [True, False] if (law.mu_s > 0 and x_edge > x0) else [False]
        # a kink or a steep power law in the right-hand side can hold the residual above a
        # tight tol down to round-off: then relax it, twice
        tols = [tol] + [t for t in (1e2 * tol, 1e4 * tol) if t <= 1e-4]
        failures: list[str] = []
        for tol_used in tols:
            for split in splits:
                try:
                    res, path, form = _solve_form(
                        law, A, prob, local, split, x_edge, tol_used, max_nodes
                    )
                    break
                except GranflowError as e:
                    failures.append(f"{'split' if split else 'single'} form, tol {tol_used:g}: {e}")
            else:
                continue
            break
        else:
            raise GranflowError(
                "nonlocal channel solution did not converge: "
                + "; ".join(failures)
                + f" (A = {A:g}, g_wall = {prob.g_wall:g}, W = {prob.W:g}, x0 = {x0:g}, "
                f"sigma_xx = {prob.sigma_xx:g}, {law})"
            )
        if tol_used > tol:
            warnings.warn(
                f"solve_nonlocal: tol = {tol:g} not reached (mesh refinement ran into round-off);"
                f" solved to tol = {tol_used:g}",
                RuntimeWarning,
                stacklevel=2,
            )
        y_at = form.solution(res)
        c = prob.shear_rate_scale

        def evaluate(xs: FloatArray) -> dict[str, FloatArray]:
            with np.errstate(under="ignore"):  # g underflows deep in a plug: harmless
                y = y_at(np.atleast_1d(np.asarray(xs, dtype=np.float64)))
                s, g = y[0], y[1]
                mu = s / prob.sigma_xx
                i = mu * g / c
                return _quantities(law, y[3], s, mu, i, mu * g, g)

        x = np.linspace(x0, xc, int(n))
        q = evaluate(x)

    mu_wall = float(q["mu"][0])
    if mu_wall > law.mu_max:
        raise _stress_ratio_error(law, mu_wall, prob)
    info = {
        "max_residual": float(np.max(res.rms_residuals)),
        "tol": tol_used,
        "nodes": int(res.x.size),
        "niter": int(res.niter),
        "form": "split" if form.split else "single",
        "x_yield": float(res.p[0]) if form.split else None,
        "A_path": path,
        "failed_forms": failures,
        "mu_wall": mu_wall,
        "I_wall": float(q["I"][0]),
        "I_max_exceeded": bool(np.max(q["I"]) > law.I_max),
    }
    bounds = form.bounds(res.p if form.split else None)
    mesh = np.concatenate([form.x_of_t(lo, hi, res.x) for lo, hi in bounds])
    return Profile(x=x, model="nonlocal", A=float(A), info=info, evaluate=evaluate, mesh=mesh, **q)


def _solve_form(
    law: LocalLaw,
    A: float,
    prob: ChannelProblem,
    local: Profile,
    split: bool,
    x_edge: float,
    tol: float,
    max_nodes: int,
) -> tuple[Any, list[float], _Form]:
    """solve_bvp in one form: directly at ``A``, else by continuation from a larger ``A``
    (the first of ``4 A, 16 A, ...`` that converges from the guess), stepping down to ``A``
    from each converged solution and halving the step (in log A) on failure.  A split
    solution whose yield point leaves ``(x0, W/2)`` fails at once: the wall does not yield."""
    span = prob.half_width - prob.x0
    y_scale = max(float(local.sigma_xy[0]), float(prob.g_wall or 0.0), 1e-300)

    def attempt(a: float, t: FloatArray | None, y: FloatArray | None, p: Any) -> Any:
        form = _Form(_Nonlocal(law, a, prob), split, tol, y_scale)
        if t is None or y is None:
            guess, ell = _guess(a, prob, local)
            # x - x0 ~ 3 L t^2 near the wall: the layer ends at t ~ sqrt(l / (3 L))
            ell_rel = math.sqrt(ell / (3.0 * ((x_edge - prob.x0) if split else span)))
            t, y, p = form.start(guess, _unit_mesh(ell_rel), x_edge)
        try:
            # trial Newton iterates may overflow; solve_bvp then reports failure
            with np.errstate(all="ignore"):
                r = solve_bvp(
                    form.fun,
                    form.bc,
                    t,
                    y,
                    p=p,
                    fun_jac=form.jac,
                    bc_jac=form.bc_jac,
                    tol=tol,
                    max_nodes=max_nodes,
                )
        except _RoundOff as e:  # a property of the right-hand side: continuation won't help
            raise _Failed(str(e), final=True) from None
        if not r.success:
            raise _Failed(str(r.message), final=False)
        if not np.all(np.isfinite(r.y)):
            raise _Failed("the solution is not finite", final=False)
        if not form.valid(r):
            raise _Failed(f"the yield point went to x = {float(r.p[0]):g}", final=True)
        return r, form

    path = [A]
    try:
        res, form = attempt(A, None, None, None)
        return res, path, form
    except _Failed as e:
        if e.final:
            raise GranflowError(str(e)) from None
        first = str(e)
    a_hi = A
    for _ in range(5):
        a_hi *= 4.0
        path.append(a_hi)
        try:
            res, form = attempt(a_hi, None, None, None)
            break
        except _Failed as e:
            if e.final:
                raise GranflowError(f"{first}; at A = {a_hi:g}: {e}") from None
    else:
        raise GranflowError(f"{first} (directly and from A up to {a_hi:g})")
    a_cur, step = a_hi, 4.0
    while a_cur > A:
        a_next = max(A, a_cur / step)
        path.append(a_next)
        try:
            # q = A d g' scales with A
            y_next = res.y.copy()
            y_next[2::3] *= a_next / a_cur
            res, form = attempt(a_next, res.x, y_next, res.p)
            a_cur = a_next
            step = min(4.0, step * 2.0)
        except _Failed as e:
            step = math.sqrt(step)
            if e.final or step < 1.05:
                raise GranflowError(
                    f"{first}; continuation in A stalled at A = {a_cur:g}: {e}"
                ) from None
    return res, path, form


class _Failed(Exception):
    """One solve_bvp attempt failed; ``final`` when continuation cannot help."""

    def __init__(self, message: str, final: bool) -> None:
        super().__init__(message)
        self.final = final
