"""Impacts inside a simulation: gap events, the impulse law, sequential impacts and the capture-velocity rest rule."""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from mechsys.errors import AnalysisError


def integrate_with_impacts(model, c, rhs, p, grid, y0, method, rtol, atol, event_fns, note_events,
                            capture_velocity):
    """Segments between impacts: gap = 0 (closing) stops the integrator, the impulse law gives the velocities of
    separation, and integration restarts. Rest rule: an impact whose approach speed is below capture_velocity is
    plastic and its contact becomes persistent (a constraint row), so a bouncing ball ends in finitely many
    impacts instead of a Zeno sequence. Persistent contacts do not lift off again (documented limitation)."""
    from mechsys.analysis.collide import resolve

    n = c.n
    impacts: list[dict] = []
    times, states = [0.0], [y0]
    t, y = 0.0, y0.copy()
    steps = 0
    t_end = float(grid[-1])
    stopped = False
    guard = 0
    while t < t_end and not stopped:
        guard += 1
        if guard > 100000:
            raise AnalysisError("more than 100000 impacts: increase the capture velocity")
        q0, u0 = y[:n], y[n:]
        gaps0 = c.gaps(t, q0, u0, p).ravel()
        vn0 = c.gap_A(t, q0, u0, p) @ u0  # (gap contacts are scleronomic here)
        touching0 = np.abs(gaps0) <= 1e-9 * (1 + np.max(np.abs(q0)))
        gap_events = []
        for k in range(len(c.gap_names)):
            if k in rhs.persistent or (touching0[k] and abs(vn0[k]) <= 1e-12 * max(1.0, np.max(np.abs(u0)))):
                continue  # touching at rest relative to each other: a zero-length crossing at the segment start

            def g(tt, yy, k=k):
                return float(c.gaps(tt, yy[:n], yy[n:], p)[k, 0])
            g.direction, g.terminal = -1.0, True
            gap_events.append((k, g))
        fns = [g for _, g in gap_events] + list(event_fns)
        t_eval = grid[(grid > t) & (grid <= t_end)]
        sol = solve_ivp(rhs, (t, t_end), y, method=method, rtol=rtol, atol=atol, t_eval=t_eval, events=fns or None)
        if not sol.success:
            raise AnalysisError(f"integration failed at t = {sol.t[-1]:.6g}: {sol.message}")
        steps += len(sol.t)
        if len(sol.t):
            times += list(sol.t)
            states += list(np.asarray(sol.y).T)
        user = type(sol)(sol)
        user.t_events = sol.t_events[len(gap_events):] if sol.t_events else None
        user.y_events = sol.y_events[len(gap_events):] if sol.y_events else None
        if note_events(user) and sol.status == 1:
            stopped = True
            break
        if sol.status != 1:
            break
        hit = [(float(ts[-1]), k) for (k, _), ts in zip(gap_events, sol.t_events) if len(ts)]
        if not hit:
            break
        t_hit = min(ts for ts, _ in hit)
        k_hit = [gap_events[i][0] for i, ((k, _), ts) in enumerate(zip(gap_events, sol.t_events)) if len(ts)]
        y = sol.y_events[[i for i, ts in enumerate(sol.t_events[:len(gap_events)]) if len(ts)][0]][-1].copy()
        t = t_hit
        q, u = y[:n], y[n:]
        gaps = c.gaps(t, q, u, p).ravel()
        touching = [c.gap_names[k] for k in range(len(c.gap_names))
                    if k not in rhs.persistent and abs(gaps[k]) <= 1e-9 * (1 + np.max(np.abs(q)))] or \
                   [c.gap_names[k] for k in k_hit]
        try:
            res = resolve(model, None, q, u, t, only=touching)
        except AnalysisError:
            continue  # grazing contact: nothing to resolve
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
            if np.all(lam > 1e-12 * max(1.0, float(np.max(np.abs(lam))))):
                captured = True
            else:
                del rhs.persistent[-len(trial):]
        for name in touching:
            k = c.gap_names.index(name)
            j = res.contacts.index(name)
            if captured or -res.normal_velocity_before[j] >= capture_velocity:  # round-off touches are no impacts
                impacts.append({"t": t, "contact": name, "impulse": float(res.impulses[j]),
                                "rates_before": {cn: float(v) for cn, v in zip(model.coordinates, u)},
                                "rates_after": {cn: float(v) for cn, v in zip(model.coordinates, u_new)},
                                "energy_loss": res.energy_loss, "captured": captured})
        u_new = sequential_impacts(model, c, p, t, q, u_new, rhs, impacts, resolve)
        y = np.concatenate([q, u_new])
        times.append(t)
        states.append(y)
    order = np.argsort(np.array(times), kind="stable")
    T_arr = np.array(times)[order]
    Y = np.array(states)[order]
    return T_arr, Y, steps, impacts, stopped


def sequential_impacts(model, c, p, t, q, u, rhs, impacts, resolve) -> np.ndarray:
    """Touching contacts that approach after an impact collide at the same instant, one after another
    (Krodkiewski problem 55): repeat until no touching contact approaches."""
    for _ in range(1000):
        gaps = c.gaps(t, q, u, p).ravel()
        vn = c.gap_A(t, q, u, p) @ u
        scale = 1e-12 * max(1.0, float(np.max(np.abs(u))))
        approaching = [c.gap_names[k] for k in range(len(c.gap_names)) if k not in rhs.persistent
                       and abs(gaps[k]) <= 1e-9 * (1 + np.max(np.abs(q))) and vn[k] < -scale]
        if not approaching:
            return u
        res = resolve(model, None, q, u, t, only=approaching[:1])
        name = approaching[0]
        j = res.contacts.index(name)
        impacts.append({"t": t, "contact": name, "impulse": float(res.impulses[j]),
                        "rates_before": {cn: float(v) for cn, v in zip(model.coordinates, u)},
                        "rates_after": {cn: float(v) for cn, v in zip(model.coordinates, res.rates_after)},
                        "energy_loss": res.energy_loss, "captured": False})
        u = res.rates_after
    raise AnalysisError("more than 1000 sequential impacts at one instant")
