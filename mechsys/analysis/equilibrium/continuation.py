"""Pseudo-arclength continuation of equilibrium branches F(x, p) = 0 with fold, branch-point and Hopf detection."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
from scipy.optimize import brentq, linear_sum_assignment

from mechsys.numeric.parallel import Share, Workers

ArrayFn = Callable[[np.ndarray, float], np.ndarray]
# a compiled corrector for the tracer's scales (s, r) and tolerance: called as _Tracer.newton(z_guess, border,
# max_iter, monotone), it returns (z, iterations, the Jacobian [Fx s | Fp] at z) or None (numeric/native.py)
Corrector = Callable[[np.ndarray, np.ndarray, int, bool], "tuple[np.ndarray, int, np.ndarray] | None"]
Compiled = Callable[[np.ndarray, np.ndarray, float], Corrector]

_MAX_CORRECTOR_ITER = 10     # Newton iterations per corrector before the step is halved
_MAX_START_ITER = 50         # Newton iterations for the start point at fixed p
_EASY_ITER = 3               # corrector iterations that count as "easy": grow the step
_GROW = 1.3
_COS_MAX_TURN = np.cos(np.radians(30.0))  # consecutive tangents turning more than this: halve the step
_LOCATE_XTOL = 1e-13         # arclength tolerance when locating events (gives p to ~1e-9 relative and better)
_DP_ZERO = 1e-10             # |tangent_p| below this counts as "no p-direction" (start at a fold)


@dataclass(frozen=True, eq=False)
class ContinuationOptions:
    """How a branch is traced (continue_branch tells what each does): the arclength step (first, smallest,
    largest), the step limit, Newton's tolerance, the half-width of the imaginary axis for eigenvalues, and the
    scales of the unknowns in the arclength (``x_scale``) and in Newton's convergence test (``tol_scale``)."""

    ds: float = 0.05
    ds_min: float = 1e-6
    ds_max: float = 0.5
    max_steps: int = 2000
    tol: float = 1e-10
    tol_re: float = 1e-9
    x_scale: float | np.ndarray | None = None
    tol_scale: float | np.ndarray | None = None

    def __post_init__(self) -> None:
        if not (0.0 < self.ds_min <= self.ds_max and self.ds > 0.0):
            raise ValueError("continuation: need 0 < ds_min <= ds_max and ds > 0")


@dataclass
class BranchPoint:
    p: float
    x: np.ndarray            # the unknowns
    eigenvalues: np.ndarray  # complex, from the caller's eig callback (stability of this point)
    stable: bool             # all Re(eigenvalues) < -tol_re (callers may refine it: see `verdict`)
    verdict: str = ""        # a caller's Lyapunov verdict of this point (bifurcation.sweep: the point analysis's)


@dataclass
class Bifurcation:
    kind: str      # "fold", "branch_point", "hopf", "zero_eigenvalue" or "collision" (see continue_branch)
    p: float
    x: np.ndarray
    index: int     # index in the branch's point list just before the event


@dataclass
class Branch:
    points: list[BranchPoint] = field(default_factory=list)
    bifurcations: list[Bifurcation] = field(default_factory=list)
    truncated: bool = False  # the step limit ended it inside the range (not a bound, a closed loop or ds_min)
    stalled: list[float] = field(default_factory=list)  # p where it ended inside the range: no step >= ds_min
    undefined: list[tuple[float, str]] = field(default_factory=list)  # (p, why) where it ended: no eigenvalues


class _Fail(Exception):
    """A re-corrected point inside a step could not be computed."""


class Undefined(_Fail):
    """Raised by an ``eig`` callback where the eigenvalues are not defined (e.g. a singular linearization): the
    branch ends at that point, with the reason (``Branch.undefined``), instead of the whole sweep failing."""


def _solve(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    try:
        out = np.linalg.solve(J, r)
        if np.all(np.isfinite(out)):
            return out
    except np.linalg.LinAlgError:
        pass
    return np.linalg.lstsq(J, r, rcond=None)[0]


def _sign_changed(a: float, b: float) -> bool:
    """True when a is nonzero and b is zero or of the opposite sign (an exact zero is reported once)."""
    return (a > 0.0 and b <= 0.0) or (a < 0.0 and b >= 0.0)


def _is_real(ev: np.ndarray) -> np.ndarray:
    return np.abs(ev.imag) <= 1e-7 * (1.0 + np.abs(ev))


def _scale(value, n: int, name: str) -> np.ndarray:
    if value is None:
        return np.ones(n)
    out = np.broadcast_to(np.asarray(value, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(out)) or np.any(out <= 0.0):
        raise ValueError(f"{name} must be positive and finite")
    return out


class _Tracer:
    """The scaled problem: z = (x / x_scale, p); the arclength and all tangents live in z. Newton's convergence
    is judged in x / tol_scale (default: x_scale), so unknowns weighted down in the arclength (a large x_scale)
    are still solved to the full tolerance."""

    def __init__(self, F: ArrayFn, Fx: ArrayFn, Fp: ArrayFn, eig: ArrayFn, n: int, options: ContinuationOptions,
                 compiled: Compiled | None = None) -> None:
        self.F, self.Fx, self.Fp, self.eig = F, Fx, Fp, eig
        self.n = n
        self.s = _scale(options.x_scale, n, "x_scale")
        # z -> tolerance units: (x / tol_scale, p)
        tol_scale = options.tol_scale
        self.r = np.append(self.s / (_scale(tol_scale, n, "tol_scale") if tol_scale is not None else self.s), 1.0)
        self.tol, self.tol_re = options.tol, options.tol_re
        self.compiled = compiled(self.s, self.r, self.tol) if compiled is not None else None

    # -- conversions and evaluations --------------------------------------------------------------
    def z_of(self, x: np.ndarray, p: float) -> np.ndarray:
        return np.concatenate([np.asarray(x, dtype=float).reshape(self.n) / self.s, [float(p)]])

    def xp(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        return z[:self.n] * self.s, float(z[self.n])

    def residual(self, z: np.ndarray) -> np.ndarray:
        x, p = self.xp(z)
        return np.asarray(self.F(x, p), dtype=float).reshape(self.n)

    def jac(self, z: np.ndarray) -> np.ndarray:
        """[Fx * x_scale | Fp], n x (n+1); the last point's is kept (a node's tangent and det read the same)."""
        key = z.tobytes()
        last = self.__dict__.get("_last_jac")
        if last is not None and last[0] == key:
            return last[1].copy()
        x, p = self.xp(z)
        A = np.asarray(self.Fx(x, p), dtype=float).reshape(self.n, self.n) * self.s[None, :]
        b = np.asarray(self.Fp(x, p), dtype=float).reshape(self.n)
        out = np.column_stack([A, b])
        self.__dict__["_last_jac"] = (key, out.copy())
        return out

    def det(self, z: np.ndarray) -> float:
        return float(np.linalg.det(self.jac(z)[:, :self.n]))

    def eigenvalues(self, z: np.ndarray) -> np.ndarray:
        x, p = self.xp(z)
        return np.atleast_1d(np.asarray(self.eig(x, p), dtype=complex)).ravel()

    # -- Newton on the bordered system -------------------------------------------------------------
    def newton(self, z_guess: np.ndarray, border: np.ndarray, max_iter: int = _MAX_CORRECTOR_ITER,
               monotone: bool = True) -> tuple[np.ndarray, int] | None:
        """Solve [F(z); border.(z - z_guess)] = 0 from z_guess; (z, iterations) or None. The compiled corrector,
        when there is one, takes the same steps and keeps the Jacobian at z for the point's tangent."""
        if self.compiled is not None:
            res = self.compiled(z_guess, border, max_iter, monotone)
            if res is None:
                return None
            self.__dict__["_last_jac"] = (res[0].tobytes(), res[2])
            return res[0], res[1]
        z = z_guess.copy()
        prev = np.inf
        for k in range(1, max_iter + 1):
            try:
                Fv = self.residual(z)
                A = self.jac(z)
            except (ArithmeticError, ValueError):
                return None
            if not (np.all(np.isfinite(Fv)) and np.all(np.isfinite(A))):
                return None
            r = np.concatenate([Fv, [border @ (z - z_guess)]])
            dz = _solve(np.vstack([A, border]), -r)
            if not np.all(np.isfinite(dz)):
                return None
            z = z + dz
            step = float(np.max(np.abs(dz * self.r)))
            zmax = 1.0 + float(np.max(np.abs(z * self.r)))
            if step <= self.tol * zmax:
                # a least-squares step on a singular Jacobian can be tiny without solving F = 0: check F
                try:
                    res = float(np.max(np.abs(self.residual(z)), initial=0.0))
                except (ArithmeticError, ValueError):
                    return None
                if res <= 1e3 * self.tol * (1.0 + float(np.max(np.abs(A / self.r))) * zmax):
                    return z, k
                return None
            if monotone and k >= 2 and step > 2.0 * prev:
                return None
            prev = step
        return None

    def correct_fixed_p(self, z_guess: np.ndarray, max_iter: int = _MAX_CORRECTOR_ITER,
                        monotone: bool = True) -> np.ndarray | None:
        e = np.zeros(self.n + 1)
        e[self.n] = 1.0
        res = self.newton(z_guess, e, max_iter, monotone)
        if res is None:
            return None
        z = res[0]
        z[self.n] = z_guess[self.n]
        return z

    # -- tangents ----------------------------------------------------------------------------------
    def tangent(self, z: np.ndarray, t_ref: np.ndarray | None) -> np.ndarray:
        """Unit null vector of [Fx | Fp] at z; oriented by t_ref (positive dot product) when given."""
        A = self.jac(z)
        v = None
        if t_ref is not None:
            rhs = np.zeros(self.n + 1)
            rhs[-1] = 1.0
            try:
                v = np.linalg.solve(np.vstack([A, t_ref]), rhs)
                if not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0.0:
                    v = None
            except np.linalg.LinAlgError:
                v = None
        if v is None:
            _, _, Vt = np.linalg.svd(A)
            v = Vt[-1].copy()
        v /= np.linalg.norm(v)
        if t_ref is not None and v @ t_ref < 0.0:
            v = -v
        return v


@dataclass
class _Node:
    z: np.ndarray
    t: np.ndarray
    det: float
    ev: np.ndarray


def _pos_counts(ev: np.ndarray, tol_re: float) -> tuple[int, int]:
    real = _is_real(ev)
    pos = ev.real > tol_re
    return int(np.sum(pos & real)), int(np.sum(pos & ~real))


def _upper(ev: np.ndarray) -> np.ndarray:
    """The complex eigenvalues with Im > 0 (one of each conjugate pair)."""
    return ev[~_is_real(ev) & (ev.imag > 0)]


def _matched(a: np.ndarray, b: np.ndarray) -> list[tuple[complex, complex]]:
    """Eigenvalues of two neighbouring points paired by least total distance (as many pairs as the shorter)."""
    if len(a) == 0 or len(b) == 0:
        return []
    rows, cols = linear_sum_assignment(np.abs(a[:, None] - b[None, :]))
    return [(complex(a[i]), complex(b[j])) for i, j in zip(rows, cols)]


def _real_crossing(ev0: np.ndarray, ev1: np.ndarray, tol_re: float):
    """Pair (by sorting) the real eigenvalues at both ends and return the pair that crosses 0."""
    a = np.sort(ev0[_is_real(ev0)].real).astype(complex)
    b = np.sort(ev1[_is_real(ev1)].real).astype(complex)
    if len(a) != len(b) or len(a) == 0:
        return None
    crossing = [k for k in range(len(a)) if (a[k].real > tol_re) != (b[k].real > tol_re)]
    if not crossing:
        return None
    k = min(crossing, key=lambda j: abs(a[j].real) + abs(b[j].real))
    return a[k], b[k]


class _Continuation:
    def __init__(self, tr: _Tracer, p_min: float, p_max: float, options: ContinuationOptions) -> None:
        self.tr = tr
        self.p_min, self.p_max = float(p_min), float(p_max)
        self.ds, self.ds_min, self.ds_max = float(options.ds), float(options.ds_min), float(options.ds_max)
        self.max_steps = int(options.max_steps)
        self.hopf_at_end = False  # the previous step found a Hopf point exactly at its end

    def node(self, z: np.ndarray, t: np.ndarray) -> _Node:
        return _Node(z, t, self.tr.det(z), self.tr.eigenvalues(z))

    def point(self, nd: _Node) -> BranchPoint:
        x, p = self.tr.xp(nd.z)
        ev = nd.ev
        stable = bool(np.all(ev.real < -self.tr.tol_re))
        return BranchPoint(p=p, x=x, eigenvalues=ev.copy(), stable=stable)

    # -- points inside a step, parameterized by the projection s on the previous tangent -------------
    def at(self, a: _Node, b: _Node, s: float) -> np.ndarray:
        s1 = float(a.t @ (b.z - a.z))
        if s <= 0.0:
            return a.z
        if s >= s1:
            return b.z
        zp = a.z + (s / s1) * (b.z - a.z)
        res = self.tr.newton(zp, a.t, max_iter=4 * _MAX_CORRECTOR_ITER)
        if res is None:
            raise _Fail
        return res[0]

    def locate(self, a: _Node, b: _Node, g: Callable[[float], float], g0: float, g1: float,
               pred: Callable[[float], bool] | None = None) -> float:
        """Arclength s in [0, s1] where g changes sign (Brent), else bisection on pred (event happened by s)."""
        s1 = float(a.t @ (b.z - a.z))
        try:
            if g1 == 0.0:
                return s1
            if g0 * g1 < 0.0:
                return float(brentq(g, 0.0, s1, xtol=_LOCATE_XTOL, maxiter=200))
            if pred is not None:
                lo, hi = 0.0, s1
                while hi - lo > _LOCATE_XTOL * (1.0 + s1):
                    mid = 0.5 * (lo + hi)
                    if pred(mid):
                        hi = mid
                    else:
                        lo = mid
                return hi
        except (_Fail, ValueError, RuntimeError):
            pass
        if g0 != g1 and np.isfinite(g0) and np.isfinite(g1):
            return float(np.clip(s1 * g0 / (g0 - g1), 0.0, s1))
        return 0.5 * s1

    def detect(self, a: _Node, b: _Node, index: int) -> list[tuple[float, Bifurcation]]:
        tr = self.tr
        n = tr.n
        tol_re = tr.tol_re
        events: list[tuple[str, float]] = []
        ta, tb = a.t[n], b.t[n]
        ta = 0.0 if abs(ta) < _DP_ZERO else ta
        fold = _sign_changed(ta, tb)
        if fold:
            def g_fold(s: float) -> float:
                return float(tr.tangent(self.at(a, b, s), a.t)[n])
            events.append(("fold", self.locate(a, b, g_fold, ta, tb)))

        ra, ca = _pos_counts(a.ev, tol_re)
        rb, cb = _pos_counts(b.ev, tol_re)
        dn, dr, dc = (rb + cb) - (ra + ca), rb - ra, cb - ca
        real_cross = dn != 0 and dr != 0 and not (dc != 0 and dn % 2 == 0 and abs(dn) >= 2)

        if not fold and ta != 0.0:  # ta == 0: the step starts at a fold (only possible at the start point)
            if _sign_changed(a.det, b.det):
                def g_det(s: float) -> float:
                    return tr.det(self.at(a, b, s))
                events.append(("branch_point", self.locate(a, b, g_det, a.det, b.det)))
            elif real_cross:
                events.append(("zero_eigenvalue", self._locate_real(a, b)))
        hopfs = self._hopf(a, b, index)
        events += [("hopf", s) for s in hopfs]
        # a complex pair left or reached the imaginary axis without crossing it transversally: on a conservative
        # (gyroscopic) branch two eigenvalues meet on the axis and split off it (Krein collision): no Hopf point
        if dn != 0 and dc != 0 and not real_cross and not hopfs and not self.hopf_at_end:
            s = self._locate_count(a, b)
            if self._collision(a, b, s):
                events.append(("collision", s))
        self.hopf_at_end = any(s >= float(a.t @ (b.z - a.z)) for s in hopfs)

        out = []
        for kind, s in events:
            try:
                z = self.at(a, b, s)
            except _Fail:
                s1 = float(a.t @ (b.z - a.z))
                z = a.z + (s / s1) * (b.z - a.z) if s1 > 0 else a.z
            x, p = tr.xp(z)
            out.append((s, Bifurcation(kind=kind, p=p, x=x, index=index)))
        out.sort(key=lambda e: e[0])
        return out

    # -- Hopf points: a simple complex pair crossing the imaginary axis transversally ------------------------
    def _hopf(self, a: _Node, b: _Node, index: int) -> list[float]:
        """Arclengths in the step where a complex pair crosses the imaginary axis transversally.

        The pair (eigenvalues of the two ends matched by least total distance) must have Re < -tol_re at one end
        and Re > tol_re at the other, or end exactly on the axis and be off it on the other side just beyond
        that end (a probe point: the crossing is then at the end). The located crossing must lie on the axis
        with Im != 0, and be simple (no other eigenvalue there): where a pair only reaches the axis and stays on
        it, or two eigenvalues meet on it (a conservative branch), the crossing speed on one side is zero."""
        tol = self.tr.tol_re
        s1 = float(a.t @ (b.z - a.z))
        out = []
        for la, lb in _matched(_upper(a.ev), _upper(b.ev)):
            on_a, on_b = abs(la.real) <= tol, abs(lb.real) <= tol
            if on_a and on_b:
                continue
            if on_a or on_b:
                # the end on the axis: the step before (or after) decides, from the far side of that end
                if on_a and index > 0:
                    continue  # decided by the previous step (its far side is this step's other end)
                near = a if on_a else b
                beyond = self._probe(near, -1.0 if on_a else 1.0, s1)
                if beyond is None:
                    continue
                lc = beyond[np.argmin(np.abs(beyond - (la if on_a else lb)))]
                ref = lb if on_a else la
                if abs(lc.real) > tol and lc.real * ref.real < 0.0 and self._simple(near.ev, la if on_a else lb):
                    out.append(0.0 if on_a else s1)
                continue
            if la.real * lb.real > 0.0:
                continue
            s, lam = self._track_root(a, b, la, lb)
            if s is not None and abs(lam.real) <= 1e-3 * max(abs(la.real), abs(lb.real)) \
                    and not _is_real(np.array([lam]))[0] and self._simple(self.tr.eigenvalues(self.at(a, b, s)), lam):
                out.append(s)
        return out

    def _track_root(self, a: _Node, b: _Node, la: complex, lb: complex) -> tuple[float | None, complex]:
        """Where the real part of the eigenvalue followed from la (at a) to lb (at b) vanishes (Brent)."""
        tr = self.tr
        s1 = float(a.t @ (b.z - a.z))
        last = {}

        def g(s: float) -> float:
            ev = _upper(tr.eigenvalues(self.at(a, b, s)))
            if len(ev) == 0:
                raise _Fail
            ref = la + (s / s1) * (lb - la) if s1 > 0 else la
            last[s] = ev[np.argmin(np.abs(ev - ref))]
            return float(last[s].real)

        try:
            s = float(brentq(g, 0.0, s1, xtol=_LOCATE_XTOL, maxiter=200))
            g(s)  # the followed eigenvalue at the root
            return s, last[s]
        except (_Fail, ArithmeticError, ValueError, RuntimeError):
            return None, 0j

    def _probe(self, nd: _Node, side: float, h: float) -> np.ndarray | None:
        """Eigenvalues at the branch point about h beyond nd (side +1: along its tangent, -1: against it)."""
        for _ in range(4):
            res = self.tr.newton(nd.z + side * h * nd.t, nd.t, max_iter=4 * _MAX_CORRECTOR_ITER)
            if res is not None:
                try:
                    return self.tr.eigenvalues(res[0])
                except (ArithmeticError, ValueError):
                    return None
            h *= 0.5
        return None

    @staticmethod
    def _simple(ev: np.ndarray, lam: complex) -> bool:
        """No other eigenvalue at lam (an eigenvalue meeting another where it crosses is not a Hopf point)."""
        d = np.sort(np.abs(ev - lam))
        return len(d) < 2 or d[1] > 1e-5 * (1.0 + abs(lam))

    def _collision(self, a: _Node, b: _Node, s: float) -> bool:
        """Two eigenvalues meet on the imaginary axis at s (within the location tolerance)."""
        try:
            ev = _upper(self.tr.eigenvalues(self.at(a, b, s)))
        except (_Fail, ArithmeticError, ValueError):
            return False
        tol = 1e-4 * (1.0 + float(np.max(np.abs(ev), initial=0.0)))
        close = np.abs(ev[:, None] - ev[None, :]) <= tol
        on_axis = np.abs(0.5 * (ev[:, None] + ev[None, :]).real) <= tol
        return bool(np.any(np.triu(close & on_axis, 1)))

    def _count_changed(self, a: _Node, b: _Node) -> Callable[[float], bool]:
        """pred(s): the number of eigenvalues with Re > tol_re at s differs from a's."""
        tr = self.tr
        n0 = sum(_pos_counts(a.ev, tr.tol_re))
        return lambda s: sum(_pos_counts(tr.eigenvalues(self.at(a, b, s)), tr.tol_re)) != n0

    def _locate_count(self, a: _Node, b: _Node) -> float:
        """Arclength where the number of eigenvalues with Re > tol_re changes (bisection)."""
        return self.locate(a, b, lambda s: 0.0, 1.0, 1.0, self._count_changed(a, b))

    def _locate_real(self, a: _Node, b: _Node) -> float:
        """Arclength where a real eigenvalue crosses 0 (Brent on it, else bisection on the count)."""
        tr = self.tr
        s1 = float(a.t @ (b.z - a.z))
        pair = _real_crossing(a.ev, b.ev, tr.tol_re)
        if pair is None:
            return self._locate_count(a, b)
        l0, l1 = pair

        def g(s: float) -> float:
            ev = tr.eigenvalues(self.at(a, b, s))
            ev = ev[_is_real(ev)]
            if len(ev) == 0:
                raise _Fail
            ref = l0 + (s / s1) * (l1 - l0) if s1 > 0 else l0
            return float(ev[np.argmin(np.abs(ev - ref))].real)

        return self.locate(a, b, g, float(l0.real), float(l1.real), self._count_changed(a, b))

    # -- the predictor-corrector loop ----------------------------------------------------------------
    def run(self, z0: np.ndarray, direction: float) -> tuple[Branch, bool]:
        tr = self.tr
        n = tr.n
        t0 = tr.tangent(z0, None)
        if abs(t0[n]) > _DP_ZERO:
            t0 = t0 * np.sign(t0[n]) * np.sign(direction)
        else:
            k = int(np.argmax(np.abs(t0) > _DP_ZERO))
            t0 = t0 * np.sign(t0[k]) * np.sign(direction)
        start = self.node(z0, t0)
        cur = start
        self.hopf_at_end = False
        branch = Branch(points=[self.point(start)], bifurcations=[])
        closed = False
        ds = min(max(self.ds, self.ds_min), self.ds_max)
        arc = 0.0
        accepted = attempts = 0
        while accepted < self.max_steps and attempts < 20 * self.max_steps:
            attempts += 1
            final = False
            res = tr.newton(cur.z + ds * cur.t, cur.t)
            z1 = t1 = None
            iters = _MAX_CORRECTOR_ITER
            if res is not None:
                z1, iters = res
                if np.linalg.norm(z1 - (cur.z + ds * cur.t)) > ds:
                    z1 = None
            if z1 is not None:
                try:
                    t1 = tr.tangent(z1, cur.t)
                except (np.linalg.LinAlgError, ValueError):
                    t1 = None
                if t1 is None or (t1 @ cur.t < _COS_MAX_TURN and ds > 2.0 * self.ds_min):
                    z1 = None
            if z1 is not None and not (self.p_min <= z1[n] <= self.p_max):
                bound = self.p_max if z1[n] > self.p_max else self.p_min
                if cur.z[n] == bound:
                    break  # already on the boundary, stepping out of the range
                theta = (bound - cur.z[n]) / (z1[n] - cur.z[n])
                guess = cur.z + theta * (z1 - cur.z)
                guess[n] = bound
                zc = tr.correct_fixed_p(guess)
                if zc is None or float(cur.t @ (zc - cur.z)) <= 0.0:
                    z1 = None
                else:
                    z1, t1, final = zc, tr.tangent(zc, cur.t), True
            if z1 is None:
                ds *= 0.5
                if ds < self.ds_min:
                    branch.stalled.append(float(cur.z[n]))  # the corrector failed down to the smallest step
                    break
                continue
            seg = float(cur.t @ (z1 - cur.z))
            if accepted >= 2 and arc > 2.0 * seg and start.t @ cur.t > 0.0:
                s_st = float(cur.t @ (start.z - cur.z))
                if 0.0 < s_st <= seg * (1.0 + 1e-12):
                    chord = cur.z + (s_st / seg) * (z1 - cur.z)
                    if np.linalg.norm(start.z - chord) <= 0.25 * np.linalg.norm(z1 - cur.z):
                        z1, t1, final, closed = start.z, start.t, True, True
            try:
                nxt = self.node(z1, t1) if not closed else start
                found = self.detect(cur, nxt, len(branch.points) - 1)
            except Undefined as exc:
                # the linearization is not defined at z1 or between (a singular split): approach the point by
                # smaller steps, so that the events before it are found; the branch ends there at the smallest step
                ds *= 0.5
                closed = False
                if ds < self.ds_min:
                    branch.undefined.append((float(z1[n]), str(exc)))
                    break
                continue
            for _, bif in found:
                branch.bifurcations.append(bif)
            branch.points.append(self.point(nxt) if not closed else branch.points[0])
            accepted += 1
            arc += float(np.linalg.norm(z1 - cur.z))
            cur = nxt
            if final:
                break
            if iters <= _EASY_ITER:
                ds = min(ds * _GROW, self.ds_max)
        branch.truncated = not (final or closed) and (accepted >= self.max_steps or attempts >= 20 * self.max_steps)
        if closed:
            first = branch.points[0]
            branch.points[-1] = BranchPoint(p=first.p, x=first.x.copy(), eigenvalues=first.eigenvalues.copy(),
                                            stable=first.stable)
        return branch, closed


def _setup(F: ArrayFn, Fx: ArrayFn, Fp: ArrayFn, x0, p0: float, p_min: float, p_max: float, eig: ArrayFn,
           options: ContinuationOptions, compiled: Compiled | None = None) -> tuple[_Continuation, np.ndarray]:
    """The continuation of one start, corrected onto the branch at fixed p0 (ValueError when that fails)."""
    if not p_min < p_max:
        raise ValueError(f"continuation: need p_min < p_max, got [{p_min}, {p_max}]")
    if not p_min <= p0 <= p_max:
        raise ValueError(f"continuation: start parameter p0={p0} is outside [{p_min}, {p_max}]")
    x0 = np.atleast_1d(np.asarray(x0, dtype=float)).ravel()
    tr = _Tracer(F, Fx, Fp, eig, len(x0), options, compiled)
    z = tr.correct_fixed_p(tr.z_of(x0, p0), max_iter=_MAX_START_ITER, monotone=False)
    if z is None:
        try:
            z0 = tr.z_of(x0, p0)
            r = float(np.max(np.abs(tr.residual(z0))))
            finite = bool(np.all(np.isfinite(tr.jac(z0))))
        except (ArithmeticError, ValueError):
            r, finite = float("nan"), False
        if not (finite and np.isfinite(r)):
            raise ValueError(f"continuation: the equations or their derivatives cannot be evaluated at the start "
                             f"point (p={p0}): they are not defined or not smooth there")
        raise ValueError(f"continuation: Newton correction of the start point at fixed p={p0} did not converge "
                         f"in {_MAX_START_ITER} iterations (|F(x0, p0)| = {r:.3g}); x0 is not near an "
                         f"equilibrium at p0, or the Jacobian Fx is wrong")
    return _Continuation(tr, p_min, p_max, options), z


def continue_branch(F: ArrayFn, Fx: ArrayFn, Fp: ArrayFn, x0: np.ndarray | Sequence[float], p0: float,
                    p_min: float, p_max: float, eig: ArrayFn, *, direction: float = +1.0,
                    **options: Any) -> Branch:
    """Follow the branch F(x, p) = 0 through (x0, p0) by pseudo-arclength continuation, in one direction.

    ``options``: the fields of ContinuationOptions (ds, ds_min, ds_max, max_steps, tol, tol_re, x_scale, tol_scale),
    by name. The start is corrected by Newton at fixed p0 (``ValueError`` if that fails). The first tangent is the
    null vector of [Fx | Fp], oriented so that dp has the sign of ``direction``; if dp ~ 0 at the start (a start at
    a fold) it is oriented so that its first nonzero component has the sign of ``direction`` (positive for +1), and
    a fold exactly at the start is not reported (``sweep_parameter`` reports it). Arclength is measured in
    (x / x_scale, p): a large x_scale weights an unknown down (an auxiliary unknown that grows along the branch would
    otherwise take the steps), while Newton still solves it to ``tol`` relative to ``tol_scale`` (default x_scale).
    The branch ends when p leaves [p_min, p_max] (the last point is placed exactly on the bound), after
    ``max_steps`` steps (``truncated``), when the step would drop below ``ds_min`` (the corrector fails even there:
    the equations are not smooth, or not defined, beyond; ``stalled`` records p), or when it closes on its start
    (the last point then repeats the first). Events are located between consecutive points: "fold" (tangent dp
    changes sign), "branch_point" (det Fx changes sign without a fold), "zero_eigenvalue" (a real eigenvalue of
    ``eig`` crosses 0 while the branch neither folds nor branches: ``eig`` sees more than Fx, e.g. the extremum of a
    cyclic momentum along a family of steady motions), "hopf" (a simple complex pair of ``eig`` crosses the
    imaginary axis transversally: Re < -tol_re on one side, > tol_re on the other) and "collision" (the number of
    eigenvalues with Re > tol_re changes because two eigenvalues meet on the imaginary axis and leave it: a
    conservative, gyroscopic branch, Krein collision; not a Hopf point); |Re| <= tol_re counts as 0.
    """
    if not direction:
        raise ValueError("continue_branch: direction must be nonzero")
    cont, z0 = _setup(F, Fx, Fp, x0, p0, p_min, p_max, eig, ContinuationOptions(**options))
    return cont.run(z0, direction)[0]


def _on_branch(cont: _Continuation, branch: Branch, z: np.ndarray) -> bool:
    """Whether the corrected point z lies on the traced branch (re-corrected onto it, not just near a chord)."""
    tr = cont.tr
    key = tr.s.tobytes()
    cached = branch.__dict__.get("_z")
    if cached is None or cached[0] != key or len(cached[1]) != len(branch.points):
        cached = branch.__dict__["_z"] = (key, np.array([tr.z_of(pt.x, pt.p) for pt in branch.points]))
    zs = cached[1]
    scale = 1.0 + float(np.max(np.abs(z)))
    if len(zs) == 1:
        return bool(np.linalg.norm(zs[0] - z) <= 1e-7 * scale)
    a, d = zs[:-1], np.diff(zs, axis=0)
    L = np.linalg.norm(d, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = d / L[:, None]
        s = np.einsum("ij,ij->i", t, z - a)
        off = np.linalg.norm(z - (a + s[:, None] * t), axis=1)
    near = (L > 0.0) & (s >= -1e-9 * scale) & (s <= L * (1 + 1e-9)) & (off <= L)
    for k in range(len(L)):  # in order along the branch, as the segments come
        if L[k] == 0.0:
            if np.linalg.norm(z - a[k]) <= 1e-7 * scale:
                return True
            continue
        if not near[k]:
            continue
        res = tr.newton(a[k] + s[k] * t[k], t[k])
        if res is not None and np.linalg.norm(res[0] - z) <= 1e-6 * scale:
            return True
    return False


def sweep_parameter(F: ArrayFn, Fx: ArrayFn, Fp: ArrayFn, starts: list[tuple[np.ndarray, float]], p_min: float,
                    p_max: float, eig: ArrayFn, skipped: list[tuple[float, str]] | None = None,
                    share: Share | None = None, compiled: Compiled | None = None,
                    **options: Any) -> list[Branch]:
    """Trace each start both ways (direction -1 and +1) and merge the two halves into one branch along the arc.

    The merged points run from the end of the direction -1 half, through the start, to the end of the +1 half;
    bifurcation indices refer to the merged list. A start that lies on an already-traced branch is skipped; a
    closed branch is traced once. ``options``: the fields of ContinuationOptions, as for ``continue_branch``.
    A start where ``eig`` raises Undefined is not traced; its (p, reason) is appended to ``skipped``. The starts
    are traced in forked workers where more than one process is available (numeric/parallel.py: the branches are
    those of the serial loop); ``share`` carries state of ``eig`` back from them (e.g. a memo). ``compiled`` makes
    a compiled corrector for a tracer (``Compiled``), which then replaces the Python Newton loop.
    """
    chosen = ContinuationOptions(**options)
    setups = [_setup(F, Fx, Fp, x0, p0, p_min, p_max, eig, chosen, compiled) for x0, p0 in starts]

    def half(j: int) -> tuple[Branch, bool] | str:
        """Start j // 2 traced forward (j even) or backward: (half branch, closed), or the reason eig is
        undefined at the start."""
        cont, z0 = setups[j // 2]
        try:
            return cont.run(z0, -1.0 if j % 2 else +1.0)
        except Undefined as exc:
            return str(exc)

    out: list[Branch] = []

    def new(k: int, since: int = 0) -> bool:
        return not any(_on_branch(setups[k][0], br, setups[k][1]) for br in out[since:])

    with Workers(half, 2 * len(starts), share) as workers:
        # a start on a branch already traced is skipped. Workers trace the halves of the next starts ahead; a
        # start found on a branch that finished meanwhile is then dropped (and a backward half when the forward
        # one closed), so the branches are those of the serial loop. Only starts at the parameter value of those
        # in flight go ahead: distinct roots at one value lie on one branch only past a fold, while a start at
        # another value often lies on a branch still being traced (work thrown away)
        handles: dict[int, tuple[Any, Any, int]] = {}  # start -> (forward, backward, branches checked against)
        ahead = 0
        for k in range(len(setups)):
            while ahead < len(setups) and len(handles) < workers.processes \
                    and all(starts[j][1] == starts[ahead][1] for j in handles):
                if new(ahead):
                    handles[ahead] = (workers.submit(2 * ahead), workers.submit(2 * ahead + 1), len(out))
                ahead += 1
            if k not in handles:
                continue
            fwd_handle, bwd_handle, checked = handles.pop(k)
            if not new(k, checked):
                workers.discard(fwd_handle, bwd_handle)
                continue
            fwd = workers.result(fwd_handle)
            bwd = None
            if isinstance(fwd, str) or fwd[1]:  # undefined at the start, or closed: no backward half
                workers.discard(bwd_handle)
            else:
                bwd = workers.result(bwd_handle)
            undefined = fwd if isinstance(fwd, str) else bwd if isinstance(bwd, str) else None
            if undefined is not None:  # at the start itself
                if skipped is not None:
                    skipped.append((float(starts[k][1]), undefined))
                continue
            out.append(fwd[0] if bwd is None else _merge(bwd[0], fwd[0]))
    return out


def _merge(bwd: Branch, fwd: Branch) -> Branch:
    m = len(bwd.points)
    points = list(reversed(bwd.points)) + fwd.points[1:]
    bifs = [Bifurcation(b.kind, b.p, b.x, m - 2 - b.index) for b in reversed(bwd.bifurcations)]
    start = fwd.points[0]
    # a fold exactly at the start (not reported by either half): both halves leave it towards the same side in p
    if len(bwd.points) > 1 and len(fwd.points) > 1:
        dpb, dpf = bwd.points[1].p - start.p, fwd.points[1].p - start.p
        first_fold = any(b.kind == "fold" and b.index == 0 for b in bwd.bifurcations + fwd.bifurcations)
        if dpb * dpf > 0.0 and not first_fold:
            bifs.append(Bifurcation("fold", start.p, start.x.copy(), m - 1))
    x_tol = 1e-7 * (1.0 + float(np.max(np.abs(start.x), initial=0.0)))
    for b in fwd.bifurcations:
        dup = any(c.kind == b.kind and abs(c.p - b.p) <= 1e-9 * (1 + abs(b.p)) and
                  float(np.max(np.abs(c.x - b.x), initial=0.0)) <= x_tol for c in bifs)
        if not dup:
            bifs.append(Bifurcation(b.kind, b.p, b.x, b.index + m - 1))
    bifs.sort(key=lambda b: b.index)
    return Branch(points=points, bifurcations=bifs, truncated=bwd.truncated or fwd.truncated,
                  stalled=bwd.stalled + fwd.stalled, undefined=bwd.undefined + fwd.undefined)
