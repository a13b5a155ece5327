"""Impacts inside a simulation: gap events, the impulse law, sequential impacts and the capture-velocity rest rule."""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable

import numpy as np

from mechsys.analysis.motion.events import solve_ivp  # events located inside steps (near-tangential touches)
from mechsys.errors import AnalysisError

if TYPE_CHECKING:
    from mechsys.analysis.impact.collide import ImpactResult
    from mechsys.analysis.motion.simulate import Compiled, Integration, RightHandSide
    from mechsys.mechanics.model import MechanicalModel


def _pressed(rhs, t: float, q: np.ndarray, u: np.ndarray, trial: list[int], step: float = 0.0) -> list[int]:
    """The touching contacts among ``trial`` that a persistent row would press (compressive multiplier). Rows are
    added together and the most tensile one is dropped until the rest are all compressive. A force that is zero
    right now is judged a moment later (``_soon``): after a plastic impact on a body whose spring is at its free
    length, or on a pendulum bob hanging straight down, the contact force starts at 0 and grows; judged 'not
    pressed', the bodies passed through each other, unwatched."""
    trial = list(trial)
    base = list(rhs.persistent)
    while trial:
        rhs.persistent[:] = base + trial
        try:
            acc, lam = rhs.accelerations(t, q, u)
            lam = lam[-len(trial):]
            tol = 1e-12 * _force_scale(rhs, t, q, u, lam)
            if np.all(lam > tol):
                return trial
            if np.all(lam >= -tol):
                later = _soon(rhs, t, q, u, acc, step)[-len(trial):]
                zero = np.abs(lam) <= tol
                if np.all(later[zero] > _round_off(rhs, t, q, u, later)):
                    return trial
                lam = np.where(zero, later, lam)
        finally:
            rhs.persistent[:] = base
        del trial[int(np.argmin(lam))]
    return []


def _round_off(rhs, t: float, q: np.ndarray, u: np.ndarray, lam: np.ndarray) -> float:
    """What multipliers below count as zero: 1e-9 of the forces at play: the balls of a Newton's cradle at rest
    touch with forces of 1e-17, and are not pressed."""
    return 1e-9 * _force_scale(rhs, t, q, u, lam)


def _force_scale(rhs, t: float, q: np.ndarray, u: np.ndarray, lam: np.ndarray) -> float:
    """The forces at play: the largest generalized force or multiplier, in the model's units (a floor of 1 N
    called a MEMS ball's 1e-13 N weight on the floor 'not pressed', and the ball fell through it)."""
    f = rhs.c.eqs.evaluate(t, q, u, rhs.p)[1]
    return max(float(np.max(np.abs(f), initial=0.0)), float(np.max(np.abs(lam), initial=0.0)), 1e-300)


def _soon(rhs, t: float, q: np.ndarray, u: np.ndarray, acc: np.ndarray, step: float) -> np.ndarray:
    """The multipliers a moment dt later along the constrained motion (one Euler step, dt a thousandth of the
    step size reached, 1e-6 s before any step): the sign of their rate where they are zero now."""
    dt = 1e-3 * step if step > 0 else 1e-6
    return rhs.accelerations(t + dt, q + dt * u, u + dt * acc)[1]


def _lift_off_functions(rhs, c, p) -> list:
    """Terminal events on the multipliers of the persistent contacts: a contact force turning tensile (falling
    through 0) ends the segment so that the contact can be released."""
    n = c.n
    fns = []
    for j, k in enumerate(list(rhs.persistent)):
        count = len(rhs.persistent)

        def h(tt, yy, j=j, count=count):
            return float(rhs.accelerations(tt, yy[:n], yy[n:])[1][-count + j])
        h.direction, h.terminal = -1.0, True
        fns.append((k, h))
    return fns


def contact_state(model: MechanicalModel, c: Compiled, p: np.ndarray, t: float, q: np.ndarray,
                  u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(gaps, normal velocities) of the gap contacts at (t, q, u); an AnalysisError naming the contact when its
    geometry is degenerate there (a zero radius: the gap's derivative divides by zero)."""
    from mechsys.analysis.impact.collide import contact_degeneracy

    try:
        with np.errstate(all="ignore"):
            gaps, vn = c.gaps(t, q, u, p).ravel(), c.gap_A(t, q, u, p) @ u
    except (ZeroDivisionError, ValueError, OverflowError):
        gaps = vn = np.array([np.nan])
    if not (np.all(np.isfinite(gaps)) and np.all(np.isfinite(vn))):
        raise contact_degeneracy(model, t, q, u, p) or AnalysisError(
            f"the contact gaps or their rates are not finite at t = {t:.6g} (a division by zero in a gap: check "
            "the parameters)")
    return gaps, vn


def _segment(job: Integration, t: float, y: np.ndarray, fns: list, lift_events: list, h: float, reach: int):
    """One solve of the impact loop, from (t, y) to t_end or to the first terminal event; for closed loops to an
    output point about ``reach`` steps of size h away (as simulate's closed-loop paths do), where the state is
    projected onto the constraints (the outputs inside it too), and again over half the steps when its outputs
    drift off the constraints.
    The result carries the ``reach`` used and where the segment ends (``seg_end``)."""
    from mechsys.analysis.motion.simulate import inner_rows, segment_end

    c, p, grid, rtol, atol = job.c, job.p, job.grid, job.rtol, job.atol
    t_end = float(grid[-1])
    k = int(np.searchsorted(grid, t + 1e-13 * max(1.0, abs(t)), side="right")) - 1
    while True:
        seg_end = float(grid[segment_end(grid, k, reach, h)]) if c.m and k < len(grid) - 1 else t_end
        t_eval = grid[(grid > t) & (grid <= seg_end)]
        # a resting state lets the integrator take huge steps: bound them by the output interval so that a
        # multiplier turning tensile between two step ends is not stepped over
        options = {"max_step": float(grid[1] - grid[0])} if lift_events and len(grid) > 1 else {}
        if h > 0.0:
            options["first_step"] = min(h, seg_end - t, options.get("max_step", h))
        sol = solve_ivp(job.rhs, (t, seg_end), y, method=job.method, rtol=rtol, atol=atol, t_eval=t_eval,
                        events=fns or None, **options)
        if not sol.success:
            raise AnalysisError(f"integration failed at t = {sol.t_reached:.6g}: {sol.message}")
        if c.m:
            inner = sol.t < seg_end if sol.status != 1 else np.ones(len(sol.t), dtype=bool)
            rows = inner_rows(c, p, sol.t[inner], sol.y[:, inner].T, rtol, atol)
            if rows is None and reach:
                reach //= 2  # the outputs inside the segment drifted off the constraints: again, shorter
                continue
            if rows is not None:
                sol.y[:, inner] = rows.T
        sol.reach, sol.seg_end = reach, seg_end
        return sol


def integrate_with_impacts(job: Integration, y0: np.ndarray, capture_velocity: float
                           ) -> tuple[np.ndarray, np.ndarray, int | None, list[dict], bool, list[tuple]]:
    """Segments between impacts: gap = 0 (closing) stops the integrator, the impulse law gives the velocities of
    separation, and integration restarts. Rest rule: an impact whose approach speed is below capture_velocity is
    plastic and its contact becomes persistent (a constraint row), so a bouncing ball ends in finitely many
    impacts instead of a Zeno sequence. A contact touching at rest that would be pressed becomes persistent too
    (a block laid on a table, or after a plastic impact). A persistent contact lifts off when its multiplier
    turns tensile (an event), and a touching contact at rest that opens ends the segment once its gap exceeds a
    small threshold, so that its next closing is an event again."""
    from mechsys.analysis.impact.collide import joint_impulses, resolve
    from mechsys.analysis.motion.simulate import PROJECTION_STEPS, check_on_manifold, project

    model, c, rhs, p, grid = job.model, job.c, job.rhs, job.p, job.grid
    n = c.n
    impacts: list[dict] = []
    times, states = [0.0], [y0]
    active: list[tuple] = [()]  # the persistent contacts at each stored state (its multipliers need their rows)
    t, y = 0.0, y0.copy()
    steps = None  # solve_ivp with t_eval does not tell its steps; the summary says n/a
    t_end = float(grid[-1])
    stopped = False
    guard = 0
    released: set = set()  # contacts just released by a lift-off: not re-captured at the restart
    grazing: set = set()  # contacts whose closing had nothing to resolve: touching at rest at the restart
    stalled, t_last = 0, None  # restarts at the same instant (no progress)
    h, reach = 0.0, PROJECTION_STEPS  # the step size reached; steps per projected segment (closed loops)
    while t < t_end and not stopped:
        guard += 1
        if guard > 100000 + (len(grid) if c.m else 0):
            raise AnalysisError("more than 100000 impacts: increase the capture velocity")
        stalled = stalled + 1 if t == t_last else 0
        t_last = t
        if stalled > 50:
            raise AnalysisError(f"the contacts make no progress at t = {t:.10g}: the same closing is met again and "
                                f"again (try another --capture-velocity or --method)")
        q0, u0 = y[:n], y[n:]
        gaps0, vn0 = contact_state(model, c, p, t, q0, u0)  # (gap contacts are scleronomic here)
        touching0 = np.abs(gaps0) <= 1e-9 * (1 + np.max(np.abs(q0)))
        at_rest = [k for k in range(len(c.gap_names)) if k not in rhs.persistent and touching0[k]
                   and (abs(vn0[k]) <= 1e-12 * max(1.0, np.max(np.abs(u0))) or k in grazing)]
        held = _pressed(rhs, t, q0, u0, [k for k in at_rest if k not in released], h)
        if held and grazing:
            # a grazing contact held at rest keeps no normal velocity: its persistent row holds the acceleration
            # only, and a ball grazed at 1.5e-6 m/s after its last bounce (BDF) drifted up at that speed forever
            G = c.gap_A(t, q0, u0, p)[held]
            u0 = u0 - np.linalg.lstsq(G, vn0[held], rcond=None)[0]
            y = np.concatenate([q0, u0])
        grazing = set()
        rhs.persistent.extend(held)
        rhs.rested.update(rhs.persistent)
        released = set()
        gap_events, open_events = [], []
        delta = 1e-8 * (1 + np.max(np.abs(q0)))
        for k in range(len(c.gap_names)):
            if k in rhs.persistent:
                continue
            if k in at_rest:
                # touching at rest relative to each other: a zero-length crossing at the segment start; end the
                # segment if the gap opens, so that its closing is watched again

                def o(tt, yy, k=k):
                    return float(c.gaps(tt, yy[:n], yy[n:], p)[k, 0]) - delta
                o.direction, o.terminal = 1.0, True
                open_events.append((k, o))
                continue

            if touching0[k] and vn0[k] > 0:
                # touching and separating (just after an impact): g(t0) = 0 would make the root finder return t0
                # itself; g / (t - t0), which tends to the separation speed at t0, has the same later roots

                def g(tt, yy, k=k, t0=t, v0=float(vn0[k])):
                    if tt <= t0:
                        return v0
                    return float(c.gaps(tt, yy[:n], yy[n:], p)[k, 0]) / (tt - t0)
            else:
                def g(tt, yy, k=k):
                    return float(c.gaps(tt, yy[:n], yy[n:], p)[k, 0])
            g.direction, g.terminal = -1.0, True
            gap_events.append((k, g))
        lift_events = _lift_off_functions(rhs, c, p)
        own = gap_events + open_events + lift_events
        fns = [g for _, g in own] + list(job.event_fns)
        # closed loops: a segment ends at an output point about PROJECTION_STEPS steps of the size reached away (as
        # simulate's closed-loop paths do), where the state is projected onto the constraints; shorter when its
        # outputs drift off the constraints
        sol = _segment(job, t, y, fns, lift_events, h, reach)
        reach, h, seg_end = sol.reach, sol.h_next or 0.0, sol.seg_end
        if len(sol.t):
            times += list(sol.t)
            states += list(np.asarray(sol.y).T)
            active += [tuple(rhs.persistent)] * len(sol.t)
        user = type(sol)(sol)
        user.t_events = sol.t_events[len(own):] if sol.t_events else None
        user.y_events = sol.y_events[len(own):] if sol.y_events else None
        if sol.status == 1:
            _add_coincident(job, user, sol, len(own), t, y)
        if job.note_events(user) and sol.status == 1:
            # the last row is the state at the stopping event (the report names it there), as without contacts
            t_stop, y_stop = _stop_state(job, user)
            if c.m:
                q_stop, u_stop = project(c, p, t_stop, y_stop[:n], y_stop[n:])
                y_stop = np.concatenate([q_stop, u_stop])
            keep = [i for i, tt in enumerate(times) if tt < t_stop]
            times, states, active = ([times[i] for i in keep] + [t_stop], [states[i] for i in keep] + [y_stop],
                                     [active[i] for i in keep] + [tuple(rhs.persistent)])
            stopped = True
            break
        if sol.status != 1:
            if seg_end >= t_end:
                break
            q, u = project(c, p, seg_end, sol.y[:n, -1], sol.y[n:, -1])
            check_on_manifold(c, p, seg_end, q, u)
            t, y = seg_end, np.concatenate([q, u])
            states[-1] = y
            continue
        fired = [(float(ts[-1]), i) for i, ts in enumerate(sol.t_events[:len(own)]) if len(ts)]
        if not fired:
            break
        t_first, i_first = min(fired)
        if i_first >= len(gap_events):
            # a resting contact opened, or a persistent one turned tensile: restart from there
            t, y = t_first, sol.y_events[i_first][-1].copy()
            for _t, i in fired:
                if i >= len(gap_events) + len(open_events) and abs(_t - t_first) <= 1e-12 * max(1.0, abs(t)):
                    k = own[i][0]
                    rhs.persistent.remove(k)
                    released.add(k)
            times.append(t)
            states.append(y)
            active.append(tuple(rhs.persistent))
            continue
        hit = [(t_ev, i) for t_ev, i in fired if i < len(gap_events)]
        t_hit = min(ts for ts, _ in hit)
        k_hit = [gap_events[i][0] for _t, i in hit]
        y = sol.y_events[hit[0][1]][-1].copy()
        t = t_hit
        q, u = y[:n], y[n:]
        gaps = c.gaps(t, q, u, p).ravel()
        touching = [c.gap_names[k] for k in range(len(c.gap_names))
                    if k not in rhs.persistent and abs(gaps[k]) <= 1e-9 * (1 + np.max(np.abs(q)))] or \
                   [c.gap_names[k] for k in k_hit]
        try:
            res = resolve(model, None, q, u, t, only=touching)
        except AnalysisError:
            # grazing: nothing approaches to resolve. The contact touches at rest: at the restart it is held if
            # pressed, else watched for opening (restarting on its closing met it again at the same instant
            # forever: a ball come to rest on an incline, 100,000 restarts and 2.5 min before an error)
            grazing = {c.gap_names.index(x) for x in touching}
            continue
        speed = float(np.max(-res.normal_velocity_before[[res.contacts.index(x) for x in touching]]))
        u_new = res.rates_after
        captured = False
        if speed < capture_velocity:
            # rest rule: a slow impact is plastic; the contact stays closed only if it is pressed (compressive
            # force), so bodies that merely touch (a Newton's cradle at rest) are not glued together
            res = resolve(model, None, q, u, t, only=touching, restitution=0.0)
            u_new = res.rates_after
            trial = [c.gap_names.index(x) for x in touching]
            rhs.persistent.extend(trial)
            lam = rhs.accelerations(t, q, u_new)[1][-len(trial):]
            if np.all(lam > 1e-12 * _force_scale(rhs, t, q, u_new, lam)):
                captured = True
                rhs.rested.update(trial)
            else:
                del rhs.persistent[-len(trial):]
        for name in touching:
            j = res.contacts.index(name)
            if captured or -res.normal_velocity_before[j] >= capture_velocity:  # round-off touches are no impacts
                impacts.append(_record(model, t, name, res, u, u_new, captured, q, p, joint_impulses))
        u_new = sequential_impacts(model, c, p, t, q, u_new, rhs, impacts, resolve)
        if c.m:
            q, u_new = project(c, p, t, q, u_new)
            check_on_manifold(c, p, t, q, u_new)
        y = np.concatenate([q, u_new])
        times.append(t)
        states.append(y)
        active.append(tuple(rhs.persistent))
    order = np.argsort(np.array(times), kind="stable")
    T_arr = np.array(times)[order]
    Y = np.array(states)[order]
    return T_arr, Y, steps, impacts, stopped, [active[i] for i in order]


def _stop_state(job: Integration, user) -> tuple[float, np.ndarray]:
    """(t, state) of the earliest stopping event of a solve's file events."""
    stops = [(float(ts[-1]), ys[-1]) for (_n, _e, _d, action), ts, ys in zip(job.model.events, user.t_events,
                                                                            user.y_events)
             if action == "stop" and len(ts)]
    return min(stops, key=lambda ev: ev[0])


def _add_coincident(job: Integration, user, sol, skip: int, t0: float, y0: np.ndarray) -> None:
    """Add to ``user`` (the file's events of a solve that a terminal event ended) the events that cross zero at
    that very instant without being recorded: scipy keeps only the events up to the first terminal one, and an
    event written like a contact's gap (`y` falling beside `gap: y`) crosses with it, up to rounding, so which of
    the two came first depended on the tolerances (a stop at the first touchdown ran on to the second, or to the
    end). A crossing: the event's value at the end has at most 1e-9 of its size at the solve's last output before
    it (or its start), which is on the side its direction leaves."""
    fired = [(float(ts[-1]), i) for i, ts in enumerate(sol.t_events[:skip]) if len(ts)]
    if not fired or not job.event_fns:
        return
    t_end, i_end = min(fired)
    y_end = sol.y_events[i_end][-1]
    before = [k for k, tt in enumerate(sol.t) if tt < t_end]
    t_prev, y_prev = (float(sol.t[before[-1]]), sol.y[:, before[-1]]) if before else (t0, y0)
    t_events, y_events = list(user.t_events), list(user.y_events)
    for k, fn in enumerate(job.event_fns):
        if len(t_events[k]) and abs(float(t_events[k][-1]) - t_end) <= 1e-12 * max(1.0, abs(t_end)):
            continue
        g_prev, g_end = float(fn(t_prev, y_prev)), float(fn(t_end, y_end))
        side = {-1.0: g_prev > 0, 1.0: g_prev < 0}.get(float(getattr(fn, "direction", 0.0)), g_prev != 0)
        if side and abs(g_end) <= 1e-9 * abs(g_prev):
            t_events[k] = np.append(t_events[k], t_end)
            y_events[k] = np.vstack([np.asarray(y_events[k]).reshape(-1, len(y_end)), y_end])
    user.t_events, user.y_events = t_events, y_events


def _record(model, t, name, res, u, u_new, captured, q, p, joint_impulses) -> dict:
    """One row of the impact table (rates as {coordinate: value}; friction and joint impulses included)."""
    j = res.contacts.index(name)
    joints = res.joint_impulses if np.array_equal(u_new, res.rates_after) else \
        joint_impulses(model, q, u, u_new, res.impulses, p, t, res.tangential_impulses)
    return {"t": t, "contact": name, "impulse": float(res.impulses[j]),
            "rates_before": {cn: float(v) for cn, v in zip(model.coordinates, u)},
            "rates_after": {cn: float(v) for cn, v in zip(model.coordinates, u_new)},
            "energy_loss": res.energy_loss, "captured": captured,
            "tangential_impulse": [float(x) for x in res.tangential_impulses[j]], "mode": res.modes[j],
            "joint_impulses": joints}


def sequential_impacts(model: MechanicalModel, c: Compiled, p: np.ndarray, t: float, q: np.ndarray, u: np.ndarray,
                       rhs: RightHandSide, impacts: list[dict],
                       resolve: Callable[..., ImpactResult]) -> np.ndarray:
    """Touching contacts that approach after an impact collide at the same instant, one after another
    (Krodkiewski problem 55): repeat until no touching contact approaches. Resting (persistent) contacts take
    part: a ball struck while it rests on the floor is driven into it and bounces off it. A resting contact that
    separates after the impacts is released (the old pivot of a rocking block when its other corner lands): its
    row would otherwise hold the bodies together, and the block sank through the floor gaining energy."""
    for _ in range(1000):
        gaps, vn = contact_state(model, c, p, t, q, u)
        scale = 1e-12 * max(1.0, float(np.max(np.abs(u))))
        approaching = [c.gap_names[k] for k in range(len(c.gap_names))
                       if abs(gaps[k]) <= 1e-9 * (1 + np.max(np.abs(q))) and vn[k] < -scale]
        if not approaching:
            rhs.persistent[:] = [k for k in rhs.persistent if vn[k] <= scale]
            return u
        res = resolve(model, None, q, u, t, only=approaching[:1])
        name = approaching[0]
        impacts.append(_record(model, t, name, res, u, res.rates_after, False, q, p, None))
        u = res.rates_after
    raise AnalysisError("more than 1000 sequential impacts at one instant")
