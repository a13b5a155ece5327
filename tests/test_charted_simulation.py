"""`mechsys simulate` through gimbal lock (analysis/motion/charted.py): a spherical joint's angles are integrated in another
sequence near their singular set and written back in the file's sequence. Checked against an independent
reference written here without mechsys: Euler's equations for the body angular velocity with quaternion
kinematics, scipy's DOP853 at rtol 1e-12."""
from __future__ import annotations

import itertools
import math
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.motion.charted import simulate_charted
from mechsys.analysis.motion.simulate import SimulationOptions
from mechsys.cli import app
from mechsys.numeric.rotations import angles_closed, angles_near, rate_matrix, ratio, ratio_at, rotation

ROOT = Path(__file__).resolve().parents[1]
BODY = ROOT / "tests" / "data" / "torque_free_body.yaml"  # zyx, I = 1, 2, 4, no load
TOP = ROOT / "tests" / "data" / "beyond" / "top_zxz.yaml"  # zxz heavy symmetric top
TOL = {"rtol": 1e-11, "atol": 1e-13}


# ------------------------------------------------------------------------------ the reference (no mechsys)
def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def zyx(a):
    return _rz(a[0]) @ _ry(a[1]) @ _rx(a[2])


def zyx_omega(a, d):
    """Body-axes angular velocity of R = Rz(psi) Ry(theta) Rx(phi)."""
    _psi, th, ph = a
    dpsi, dth, dph = d
    return np.array([dph - dpsi * math.sin(th), dth * math.cos(ph) + dpsi * math.sin(ph) * math.cos(th),
                     -dth * math.sin(ph) + dpsi * math.cos(ph) * math.cos(th)])


def zxz(a):
    return _rz(a[0]) @ _rx(a[1]) @ _rz(a[2])


def zxz_omega(a, d):
    """Body-axes angular velocity of R = Rz(psi) Rx(theta) Rz(phi)."""
    _psi, th, ph = a
    dpsi, dth, dph = d
    return np.array([dpsi * math.sin(th) * math.sin(ph) + dth * math.cos(ph),
                     dpsi * math.sin(th) * math.cos(ph) - dth * math.sin(ph), dpsi * math.cos(th) + dph])


def _quaternion(R):
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    t = np.trace(R)
    k = int(np.argmax([t, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        w = math.sqrt(1 + t) / 2
        return np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                         (R[1, 0] - R[0, 1]) / (4 * w)])
    i, j, m = k - 1, k % 3, (k + 1) % 3
    v = np.zeros(3)
    v[i] = math.sqrt(1 + R[i, i] - R[j, j] - R[m, m]) / 2
    v[j] = (R[j, i] + R[i, j]) / (4 * v[i])
    v[m] = (R[m, i] + R[i, m]) / (4 * v[i])
    return np.array([(R[m, j] - R[j, m]) / (4 * v[i]), *v])


def _matrix(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def reference(inertia, R0, w0, times, weight=0.0):
    """Rotation matrices and body angular velocities at ``times`` (times[0] is the start; may run backwards):
    I w' + w x I w = torque, q' = q (0, w)/2. ``weight`` = m g l: centre of mass at l on body z, gravity -z."""
    inertia = np.asarray(inertia, dtype=float)

    def rhs(_t, y):
        q, w = y[:4], y[4:]
        dq = 0.5 * np.concatenate([[-q[1:] @ w], q[0] * w + np.cross(q[1:], w)])
        torque = weight * np.cross([0.0, 0.0, 1.0], _matrix(q).T @ [0.0, 0.0, -1.0]) if weight else np.zeros(3)
        return np.concatenate([dq, (torque - np.cross(w, inertia * w)) / inertia])

    sol = solve_ivp(rhs, (times[0], times[-1]), np.concatenate([_quaternion(R0), w0]), method="DOP853",
                    rtol=1e-12, atol=1e-12, t_eval=times)
    assert sol.success
    return np.array([_matrix(y[:4]) for y in sol.y.T]), sol.y[4:].T


# ------------------------------------------------------------------------------ helpers
def _load(path, angles, rates, names=("psi", "theta", "phi")):
    values = {n: float(a) for n, a in zip(names, angles)}
    values.update({f"der({n})": float(d) for n, d in zip(names, rates)})
    return mechsys.load(path, values)


def _errors(result, chart, omega_of, R_ref, w_ref):
    """Largest |R - R_ref| and |omega - omega_ref| over the output rows (rows with undefined rates skipped)."""
    eR = max(float(np.max(np.abs(chart(q) - R))) for q, R in zip(result.q, R_ref))
    ew = max(float(np.max(np.abs(omega_of(q, u) - w))) for q, u, w in zip(result.q, result.u, w_ref)
             if np.all(np.isfinite(u)))
    return eR, ew


def _conserved(result, inertia, omega_of):
    """Relative spread of E and of |angular momentum| (rows with defined rates)."""
    L = [np.linalg.norm(np.asarray(inertia) * omega_of(q, u)) for q, u in zip(result.q, result.u)
         if np.all(np.isfinite(u))]
    return float(np.ptp(result.E) / abs(result.E[0])), float(np.ptp(L) / L[0])


def _switches(result) -> str:
    return next((w for w in result.warnings if w.startswith("chart switches")), "")


LOCK = ([0.4, math.pi / 2, -0.3], [0.2, 1.5, 0.8])  # exactly at the zyx gimbal lock (body x axis along -z)


# ------------------------------------------------------------------------------ the rotation helpers
def test_closed_form_angles_ratio_and_nearest_angles_for_every_sequence():
    rng = np.random.default_rng(11)
    sequences = [s for s in ("".join(t) for t in itertools.product("xyz", repeat=3)) if s[0] != s[1] != s[2]]
    assert len(sequences) == 12
    for seq in sequences:
        for _ in range(50):
            a = rng.uniform(-4, 4, 3)
            R = rotation(seq, a)
            assert abs(ratio_at(seq, R) - ratio(rate_matrix(seq, a))) < 1e-12
            assert np.max(np.abs(rotation(seq, angles_closed(seq, R)) - R)) < 1e-9
            near = a + rng.normal(0, 0.3, 3)
            b = angles_near(seq, R, near)
            assert np.max(np.abs(rotation(seq, b) - R)) < 1e-12
            assert np.linalg.norm(b - near) <= np.linalg.norm(a - near) + 1e-9  # a itself is a candidate
        for middle in ((0.0, math.pi) if seq[0] == seq[2] else (math.pi / 2, -math.pi / 2)):
            R = rotation(seq, [0.4, middle, -0.9])
            assert ratio_at(seq, R) < 1e-15
            assert np.max(np.abs(rotation(seq, angles_closed(seq, R)) - R)) < 1e-12
            b = angles_near(seq, R, [0.5, middle, -0.7])  # the free sum split with the least motion
            assert np.max(np.abs(rotation(seq, b) - R)) < 1e-12 and np.linalg.norm(b - [0.5, middle, -0.7]) < 0.22


# ------------------------------------------------------------------------------ torque-free body, zyx
def test_torque_free_body_started_exactly_at_gimbal_lock():
    """Before: 'coordinate singularity: the zyx angles ... are singular at this orientation' (exit 1)."""
    angles, rates = LOCK
    r = simulate_charted(_load(BODY, angles, rates), SimulationOptions(8.0, 0.01, **TOL))
    R_ref, w_ref = reference([1, 2, 4], zyx(angles), zyx_omega(angles, rates), r.t)
    eR, ew = _errors(r, zyx, zyx_omega, R_ref, w_ref)
    assert eR < 1e-8 and ew < 1e-8, (eR, ew)
    dE, dL = _conserved(r, [1, 2, 4], zyx_omega)
    assert dE < 1e-9 and dL < 1e-9, (dE, dL)
    note = _switches(r)
    assert note.startswith("chart switches: ") and "zyx -> z" in note and "at t = 0 s" in note and "back at" in note
    assert int(note.split()[2]) >= 4  # the body tumbles back to the lock region several times
    assert list(r.q[0]) == angles and list(r.u[0]) == rates  # row 0 is the file's state
    assert r.coordinates == ["psi", "theta", "phi"] and np.all(np.isfinite(r.u))
    assert np.max(np.abs(np.diff(r.q, axis=0))) < 0.2  # continuous angles: no 2 pi or branch jumps


def _state_before(seconds):
    """The file state from which the body reaches LOCK exactly after ``seconds`` (the reference, run backwards)."""
    angles, rates = LOCK
    R, w = reference([1, 2, 4], zyx(angles), zyx_omega(angles, rates), np.array([0.0, -seconds]))
    R0, w0 = R[-1], w[-1]
    a0 = [math.atan2(R0[1, 0], R0[0, 0]), -math.asin(R0[2, 0]), math.atan2(R0[2, 1], R0[2, 2])]
    W = np.column_stack([zyx_omega(a0, e) for e in np.eye(3)])
    return a0, np.linalg.solve(W, w0)


def test_motion_through_the_gimbal_lock_mid_run_reports_the_undefined_rates():
    """The body passes exactly through the lock at t = 1.5 s: the zyx chart is singular there to round-off, so
    der(psi) and der(phi) are NaN (named in a warning) while the angles stay continuous through it."""
    a0, d0 = _state_before(1.5)
    r = simulate_charted(_load(BODY, a0, d0), SimulationOptions(4.0, 0.01, **TOL))
    R_ref, w_ref = reference([1, 2, 4], zyx(a0), zyx_omega(a0, d0), r.t)
    eR, ew = _errors(r, zyx, zyx_omega, R_ref, w_ref)
    assert eR < 1e-8 and ew < 1e-8, (eR, ew)
    dE, dL = _conserved(r, [1, 2, 4], zyx_omega)
    assert dE < 1e-9 and dL < 1e-9, (dE, dL)
    undefined = np.flatnonzero(~np.all(np.isfinite(r.u), axis=1))
    assert list(r.t[undefined]) == [1.5]
    k = undefined[0]
    middle_axis = np.array([0.0, math.cos(r.q[k, 2]), -math.sin(r.q[k, 2])])  # orthogonal to the other two
    assert np.isnan(r.u[k, 0]) and np.isnan(r.u[k, 2]) and abs(r.u[k, 1] - middle_axis @ w_ref[k]) < 1e-8
    assert abs(r.q[k, 1] - math.pi / 2) < 1e-9
    assert np.max(np.abs(np.diff(r.q, axis=0))) < 0.1  # theta crosses pi/2; psi and phi do not jump
    assert any(w.startswith("angle rates undefined: der(psi) and der(phi) are NaN at t = 1.5 s") for w in r.warnings)
    first = float(_switches(r).split(" at t = ")[1].split()[0])
    assert 0.5 < first < 1.5  # left zyx before the lock, not at it


def test_coarse_output_grid_switches_between_output_times():
    """With --dt 0.5 the switches fall between output rows; every row still matches the reference."""
    angles, rates = LOCK
    r = simulate_charted(_load(BODY, angles, rates), SimulationOptions(8.0, 0.5, **TOL))
    assert len(r.t) == 17
    R_ref, w_ref = reference([1, 2, 4], zyx(angles), zyx_omega(angles, rates), r.t)
    eR, ew = _errors(r, zyx, zyx_omega, R_ref, w_ref)
    assert eR < 1e-8 and ew < 1e-8, (eR, ew)
    times = [float(x.split()[0]) for x in _switches(r).split(" at t = ")[2:]]
    assert any(abs(t / 0.5 - round(t / 0.5)) > 1e-6 for t in times)


# ------------------------------------------------------------------------------ heavy top, zxz
def test_heavy_top_in_zxz_angles_passes_through_the_upright_position():
    """p_psi = p_phi, so the symmetry axis passes exactly through the vertical (theta = 0, the zxz lock) once per
    nutation period; theta changes sign continuously. Before: the chart's rates blew up there."""
    m, l, g, A0, C = 1.0, 0.1, 9.81, 0.004, 0.008
    A = A0 + m * l * l
    theta0, spin = 0.5, 20.0
    dpsi = C * spin / (A * (1 + math.cos(theta0)))  # A psi' sin^2 + C w3 cos = C w3: equal momenta
    angles, rates = [0.0, theta0, 0.0], [dpsi, -4.0, spin - dpsi * math.cos(theta0)]
    r = simulate_charted(_load(TOP, angles, rates), SimulationOptions(3.0, 0.005, **TOL))
    R_ref, w_ref = reference([A, A, C], zxz(angles), zxz_omega(angles, rates), r.t, weight=m * g * l)
    eR, ew = _errors(r, zxz, zxz_omega, R_ref, w_ref)
    assert eR < 1e-8 and ew < 1e-7, (eR, ew)  # |omega| is about 20 rad/s
    assert np.ptp(r.E) / abs(r.E[0]) < 1e-9
    assert r.q[:, 1].min() < -0.3 and r.q[:, 1].max() > 0.3  # through theta = 0, both ways
    assert np.max(np.abs(np.diff(r.q[:, 1]))) < 0.05
    assert _switches(r).startswith("chart switches: ") and "zxz -> z" in _switches(r)


# ------------------------------------------------------------------------------ command line and warm start
def test_cli_simulate_from_a_gimbal_lock_writes_the_files_angles(tmp_path):
    out = tmp_path / "lock.csv"
    args = ["simulate", str(BODY), "--t-end", "3", "--dt", "0.05", "-o", str(out),
            "--set", "theta=pi/2", "--set", "der(theta)=1.5", "--set", "der(phi)=0.8", "--set", "der(psi)=0.2",
            "--set", "psi=0.4", "--set", "phi=-0.3"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "chart switches: " in result.output  # a note under the summary table
    lines = out.read_text().splitlines()
    assert lines[0].split(",")[:7] == ["t", "psi", "theta", "phi", "der(psi)", "der(theta)", "der(phi)"]
    data = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])
    angles, rates = LOCK
    R_ref, _ = reference([1, 2, 4], zyx(angles), zyx_omega(angles, rates), data[:, 0])
    assert max(np.max(np.abs(zyx(q) - R)) for q, R in zip(data[:, 1:4], R_ref)) < 1e-7


def test_warm_plan_is_not_used_across_a_gimbal_lock(tmp_path):
    """A plan stored by a short run (no lock reached) must not carry a longer run through the lock in the
    singular chart: the warm run checks its rows and hands over to the full path, which switches charts."""
    from mechsys.analysis.motion.warm import run_planned, simulate_file
    from mechsys.numeric import native

    if native.compiler() is None:
        pytest.skip("the warm plan needs the native path")
    path = tmp_path / "body.yaml"
    path.write_text(BODY.read_text() + f"# {tmp_path.name} {time.time_ns()}\n")  # plans are keyed by the bytes
    a0, d0 = _state_before(1.5)
    sets = [f"{n}={float(v)!r}" for n, v in zip(("psi", "theta", "phi"), a0)]
    sets += [f"der({n})={float(v)!r}" for n, v in zip(("psi", "theta", "phi"), d0)]
    cold, model = simulate_file(path, sets, SimulationOptions(0.5, 0.01))
    assert model is not None and not _switches(cold)
    warm, model = simulate_file(path, sets, SimulationOptions(0.5, 0.01))
    if model is not None:
        pytest.skip("no usable compiled-code cache here: the plan was not stored")
    assert np.array_equal(warm.q, cold.q)
    assert run_planned(path, sets, SimulationOptions(3.0, 0.01)) is None
    far, model = simulate_file(path, sets, SimulationOptions(3.0, 0.01))
    assert model is not None and _switches(far) and "warm plan" not in " ".join(far.timings)
    assert np.max(np.abs(far.q[:51] - cold.q)) < 1e-9  # the first rows are the same motion


def test_a_model_with_explicit_time_is_not_recharted_and_says_so(tmp_path):
    """Windows restart at t = 0, so only autonomous models are re-charted; others run as before, with a warning
    when their angles come near a gimbal lock (and today's 'coordinate singularity' stop when started at one)."""
    path = tmp_path / "forced.yaml"
    path.write_text(BODY.read_text() + "forces:\n  - {type: torque, on: body, value: [0, 0, 0.001*sin(t)], "
                                       "frame: ground}\n")
    r = simulate_charted(_load(path, [0.4, math.pi / 2 - 0.3, -0.3], [0.2, 0.1, 0.8]), SimulationOptions(1.0, 0.01))
    assert not _switches(r)
    assert any(w.startswith("no chart switching: the rotation angles come within a conditioning ratio of 0.1")
               for w in r.warnings)


TUMBLING_BOX = """\
name: box thrown tumbling about its intermediate axis (written from the docs)
parameters: {m: 3.0, g: 9.81, eps: 0.05, w0: 4.0}
coordinates:
  x: {initial: 0, rate: 1.0}
  y: {initial: 0, rate: 0.5}
  z: {initial: 1, rate: 6.0}
  psi: {initial: 0, rate: eps}
  theta: {initial: 0, rate: w0}
  phi: {initial: 0, rate: eps}
links:
  body:
    joint: {type: free, parent: ground, coordinates: [x, y, z, psi, theta, phi]}
    mass: m
    center_of_mass: [0.1, -0.05, 0.2]
    shape: {box: {size: [0.3, 0.4, 0.5]}}
forces:
  - {type: gravity, acceleration: [0, 0, -g]}
"""


def test_the_angles_after_near_lock_passages_do_not_depend_on_the_output_interval(tmp_path):
    """The box's middle angle passes close to +-pi/2 five times in 4 s, where psi and phi swing by about pi within
    a few milliseconds. The file's angles were the nearer triple at each sample, so the side of each swing followed
    the output grid: theta(4 s) = -0.39 at --dt 0.01, 3.53 at 0.02, 5.89 at 0.04 (the same rotation). Followed
    along the interpolated path, every --dt gives the same continuous angles."""
    path = tmp_path / "box.yaml"
    path.write_text(TUMBLING_BOX, encoding="utf-8")
    runs = {}
    for dt in ("0.01", "0.02", "0.04"):
        out = tmp_path / f"{dt}.csv"
        r = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "4", "--dt", dt, "-o", str(out)])
        assert r.exit_code == 0, r.output
        assert "chart switches" in " ".join(r.output.split())
        runs[dt] = np.genfromtxt(out, delimiter=",", names=True)
    fine, middle, coarse = runs["0.01"], runs["0.02"], runs["0.04"]
    for name in ("psi", "theta", "phi"):
        assert np.max(np.abs(fine[name][::4] - coarse[name])) < 1e-8
        assert np.max(np.abs(middle[name][::2] - coarse[name])) < 1e-8
        assert np.max(np.abs(np.diff(fine[name]))) < np.pi  # continuous on the finest grid


SPUN_THROUGH_THE_LOCK = """\
name: body spun about y through its zyx lock at t = 1 s exactly
parameters: {Ix: 1.0, Iy: 4.0, Iz: 2.0}
coordinates:
  psi: {initial: 0, rate: 0}
  theta: {initial: 0, rate: pi/2}
  phi: {initial: 0, rate: 0}
links:
  body:
    joint: {type: spherical, parent: ground, coordinates: [psi, theta, phi]}
    mass: 1
    center_of_mass: [0, 0, 0.5]
    inertia: {xx: Ix, yy: Iy, zz: Iz}
    points: {tip: [0, 0, 1]}
outputs:
  a: acceleration(body.tip)
"""


def test_an_output_row_exactly_at_the_lock_is_nan_with_a_note_not_a_failure(tmp_path):
    """Spun about its y axis at pi/2 rad/s, the body's zyx middle angle is pi/2 at t = 1 s, an output time: the run
    stopped with 'the mass matrix is singular at t = 1' because the tip's acceleration was asked for. That row's
    outputs are now NaN (the file's angle rates are undefined there) with a note; the others are the closed form,
    the tip circling at radius 1: acceleration -w^2 (sin wt, 0, cos wt)."""
    path = tmp_path / "spun.yaml"
    path.write_text(SPUN_THROUGH_THE_LOCK, encoding="utf-8")
    out = tmp_path / "spun.csv"
    r = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "2", "--dt", "0.5", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "outputs undefined: a.x, a.y, a.z are NaN at t = 1 s" in " ".join(r.output.split())
    data = np.genfromtxt(out, delimiter=",", names=True)
    w = math.pi / 2
    at_lock = np.isclose(data["t"], 1.0)
    assert np.all(np.isnan(data["ax"][at_lock]))
    t = data["t"][~at_lock]
    assert np.allclose(data["ax"][~at_lock], -w**2 * np.sin(w * t), atol=1e-9)
    assert np.allclose(data["az"][~at_lock], -w**2 * np.cos(w * t), atol=1e-9)


def test_a_free_body_started_exactly_at_the_lock_with_an_acceleration_output(tmp_path):
    """The same body on a free joint, started at the lock (theta = pi/2 at t = 0, where the file's rates are
    given): the run switched charts, then the tip acceleration at t = 0 stopped the command with 'the mass matrix
    is singular at t = 0'. That row is NaN with a note; the others are the closed form: free, the body spins about
    its principal y axis through the centre of mass (which drifts at constant velocity), the tip at 0.5 from it:
    acceleration -w^2 0.5 (sin(wt + pi/2), 0, cos(wt + pi/2))."""
    path = tmp_path / "free.yaml"
    text = SPUN_THROUGH_THE_LOCK.replace("theta: {initial: 0,", "theta: {initial: pi/2,").replace(
        "coordinates: [psi, theta, phi]", "coordinates: [x, y, z, psi, theta, phi]").replace(
        "type: spherical", "type: free").replace("coordinates:\n", "coordinates:\n  x: {initial: 0}\n"
                                                 "  y: {initial: 0}\n  z: {initial: 0}\n", 1)
    path.write_text(text, encoding="utf-8")
    out = tmp_path / "free.csv"  # (at t = 2 s, theta = 3 pi/2: the lock again)
    r = CliRunner().invoke(app, ["simulate", str(path), "--t-end", "1.5", "--dt", "0.5", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "outputs undefined: a.x, a.y, a.z are NaN at t = 0 s" in " ".join(r.output.split())
    data = np.genfromtxt(out, delimiter=",", names=True)
    w = math.pi / 2
    assert np.all(np.isnan([data["ax"][0], data["ay"][0], data["az"][0]]))
    t = data["t"][1:]
    assert np.allclose(data["ax"][1:], -0.5 * w**2 * np.sin(w * t + w), atol=1e-9)
    assert np.allclose(data["az"][1:], -0.5 * w**2 * np.cos(w * t + w), atol=1e-9)


def test_a_force_naming_the_angles_keeps_the_file_s_chart(tmp_path):
    """A heavy top in zxz angles with a spin damping torque written in its own angles, -b*(der(psi)*cos(theta) +
    der(phi)) (the body-z rate): re-charted, the torque was read in zyx angles, another function, and the run was
    0.57 off in its rotation matrix within 2 s while its energy balance held. Started inside the switching zone
    (theta = 0.4), the run now stays in the file's angles, says why, and follows a quaternion integration of Euler's
    equations with that torque."""
    text = TOP.read_text().replace("  Ws: 40", "  Ws: 40\n  b: 0.002")
    text += "  - {type: torque, on: top, axis: z, value: -b*(der(psi)*cos(theta) + der(phi))}\n"
    path = tmp_path / "top_damped.yaml"
    path.write_text(text)
    a0, d0 = [0.0, 0.4, 0.0], [2.0, 0.0, 40.0]
    model = _load(path, a0, d0)
    result = simulate_charted(model, SimulationOptions(t_end=1.0, dt=0.05, method="DOP853", rtol=1e-12, atol=1e-12))
    assert not _switches(result)
    assert any("not re-charted because forces[1].value names" in w for w in result.warnings)
    inertia, b = np.array([0.004 + 0.1**2, 0.004 + 0.1**2, 0.008]), 0.002  # about the fixed point: A0 + m l^2

    def rhs(_t, y):
        q, w = y[:4], y[4:]
        dq = 0.5 * np.concatenate([[-q[1:] @ w], q[0] * w + np.cross(q[1:], w)])
        torque = 0.981 * np.cross([0.0, 0.0, 1.0], _matrix(q).T @ [0.0, 0.0, -1.0]) + [0.0, 0.0, -b * w[2]]
        return np.concatenate([dq, (torque - np.cross(w, inertia * w)) / inertia])

    sol = solve_ivp(rhs, (0.0, 1.0), np.concatenate([_quaternion(zxz(a0)), zxz_omega(a0, d0)]), method="DOP853",
                    rtol=1e-12, atol=1e-12, t_eval=result.t)
    R_ref, w_ref = np.array([_matrix(y[:4]) for y in sol.y.T]), sol.y[4:].T
    eR, ew = _errors(result, zxz, zxz_omega, R_ref, w_ref)
    assert eR < 1e-8 and ew < 1e-6


def test_a_run_that_switches_charts_starts_on_the_rolling_constraints_and_so_does_its_warm_plan(tmp_path,
                                                                                               monkeypatch):
    """A ball rolling on a plane, its file rates off the rolling rows (der(x) = 1 where r der(a2) = 0.9). The start
    holds the rates set (--set der(a2) = 9) and corrects the others: der(x) = r der(a2) = 0.9, and the ball rolls
    straight at that speed (the minimum-norm correction, before set values were held, gave 1 - 0.1/1.01). Spun
    about y it passes its zyx lock; the run that switched charts wrote the file's rates as its row t = 0 (residual
    0.1), and its warm plan started the next run from them: x(0.1) = 0.0910891, not 0.0900990."""
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    path = ROOT / "tests" / "data" / "beyond" / "ball_on_plane.yaml"
    sets = ["--set", "der(y)=0", "--set", "der(a3)=0", "--set", "der(a2)=9"]
    v = 0.1 * 9
    for t_end in ("1", "0.1"):
        out = tmp_path / f"run{t_end}.csv"
        r = CliRunner().invoke(app, ["simulate", str(path), *sets, "--t-end", t_end, "--dt", "0.01", "-o", str(out)])
        assert r.exit_code == 0, r.output
        data = np.genfromtxt(out, delimiter=",", names=True)
        assert np.max(data["residual"]) < 1e-12
        assert np.allclose(data["x"], v * data["t"], atol=1e-9) and np.allclose(data["derx"], v, atol=1e-9)
