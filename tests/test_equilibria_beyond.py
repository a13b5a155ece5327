"""Issue 11 acceptance tests: equilibria verdicts that can be trusted on any model.

Models in tests/data/beyond/ are written from docs/yaml-reference.md as a new user would. mechsys is driven only
through its CLI (`-f json`, `-f csv`, `simulate -o`); every expected number comes from tests/reference_mechanics.py,
which rebuilds each model from its geometry with plain sympy/numpy (own rotation matrices, own T and V, Lagrange's
equations, own linearization) and never imports mechsys.

Phenomena: the Furuta pendulum's relative equilibria (1); steady precession of a heavy symmetric top written in
three charts (2); the sleeping-top threshold C^2 w^2 = 4 A m g l (3); the intermediate-axis theorem for a torque-free
body in every axis assignment and two sequences, with gimbal-lock orientations among them (4); the centrifuge's
steady motions at 3, 12 and 25 rad/s (5).

Rule at a gimbal lock (a coordinate singularity of the chosen rotation sequence): the verdict must be the correct
one, or `undecided` with "coordinate singularity" in the reason; never a wrong verdict.
"""
from __future__ import annotations

import csv
import functools
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import reference_mechanics as ref
from mechsys.cli import app

ROOT = Path(__file__).resolve().parent.parent
BEYOND = ROOT / "tests" / "data" / "beyond"
CENTRIFUGE = ROOT / "systems" / "centrifuge.yaml"
runner = CliRunner()

STABLE, UNSTABLE, UNDECIDED = "stable", "unstable", "undecided"


# ---------------------------------------------------------------------------------------------------------------
# CLI helpers (results cached: several tests read the same run)


@functools.lru_cache(maxsize=None)
def cli(*args: str) -> str:
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.stdout


def sets(**values) -> tuple[str, ...]:
    """--set options; a key `der_x` becomes `der(x)`."""
    out: list[str] = []
    for name, value in values.items():
        name = f"der({name[4:]})" if name.startswith("der_") else name
        out += ["--set", f"{name}={float(value)!r}"]
    return tuple(out)


def equilibria(path: Path, *options: str) -> dict:
    return json.loads(cli("equilibria", str(path), *options, "-f", "json"))


def info_cyclic(path: Path) -> list[str]:
    return json.loads(cli("info", str(path), "-f", "json"))["cyclic"]


def spectrum(entry: dict) -> np.ndarray:
    return np.array([complex(re, im) for re, im in entry["eigenvalues"]])


def flagged_singular(entry: dict) -> bool:
    return entry["stability"] == UNDECIDED and "coordinate singularity" in entry["reason"]


def describe(entry: dict) -> str:
    return (f"{entry['coordinates']} rates {entry['rates']}: {entry['stability']} ({entry['reason']}); "
            f"eigenvalues {entry['eigenvalues']}")


def assert_same_spectrum(entry: dict, reference: np.ndarray, rel: float = 1e-6, zero: float = 1e-8) -> None:
    """Nonzero eigenvalues equal to `rel` relative (matched one to one); zero ones zero to `zero`*scale."""
    observed = list(spectrum(entry))
    reference = np.asarray(reference)
    scale = max(1.0, float(np.max(np.abs(reference))))
    assert len(observed) == len(reference), describe(entry)
    ref_zero = int(np.sum(np.abs(reference) <= 1e-9 * scale))
    obs_zero = sum(abs(z) <= zero * scale for z in observed)
    assert obs_zero == ref_zero, f"{describe(entry)}; reference {np.round(reference, 9)}"
    for lam in reference[np.abs(reference) > 1e-9 * scale]:
        k = int(np.argmin([abs(z - lam) for z in observed]))
        assert abs(observed[k] - lam) <= rel * abs(lam), f"{lam} missing: {describe(entry)}"
        observed.pop(k)


def reference_verdict(reference: np.ndarray) -> str:
    """UNSTABLE when some eigenvalue has a positive real part, else STABLE: with one positional degree of freedom
    left (Furuta, top) or in a conservative system with an oscillatory spectrum (free body) the linearization's
    verdict is the true one."""
    scale = max(1.0, float(np.max(np.abs(reference))))
    return UNSTABLE if np.max(reference.real) > 1e-6 * scale else STABLE


# ---------------------------------------------------------------------------------------------------------------
# 1. Furuta pendulum with a massive rod arm

FURUTA = BEYOND / "furuta_rod_arm.yaml"
FP = ref.load_parameters(FURUTA)


def furuta_reference():
    return ref.furuta(FP["ma"], FP["La"], FP["mp"], FP["Lp"], FP["g"])


def test_furuta_rod_arm_angle_is_cyclic():
    """The arm rod's rotational energy leaves cos(th1)^2 + sin(th1)^2 in M: th1 is cyclic all the same."""
    assert info_cyclic(FURUTA) == ["th1"]
    assert equilibria(FURUTA)["cyclic"] == ["th1"]


@pytest.mark.parametrize("arm_rate", [0.0, 10.0], ids=["at_rest", "arm_turning_10"])
def test_furuta_hanging_and_upright_relative_equilibria_found_with_reference_eigenvalues(arm_rate):
    """No hints, no --search. At rest: hanging (th2 = 0, stable) and upright (th2 = pi, unstable). With the arm
    turning at 10 rad/s (above sqrt(3 g/(2 Lp)) = 7.0) two conical steady motions th2 = +-acos(3 g/(2 Lp W^2))
    join them and the hanging one becomes unstable. Every steady motion of the reference, no other, with the
    reference's reduced-state eigenvalues (th2, th1', th2')."""
    system = furuta_reference()
    expected = ref.furuta_steady_motions(system, arm_rate)
    assert len(expected) == (2 if arm_rate == 0 else 4)
    data = equilibria(FURUTA, *sets(der_th1=arm_rate))
    found = [e["coordinates"]["th2"] for e in data["equilibria"]]
    assert len(found) == len(expected), [describe(e) for e in data["equilibria"]]
    for th2 in expected:
        matches = [e for e in data["equilibria"] if ref.circle_distance(e["coordinates"]["th2"], th2) < 1e-6]
        assert len(matches) == 1, (th2, found)
        entry = matches[0]
        assert entry["rates"]["th1"] == pytest.approx(arm_rate, abs=1e-9)
        reference = system.reduced_eigenvalues({"th2": th2}, {"th1": arm_rate}, ["th1"])
        assert_same_spectrum(entry, reference)
        assert entry["stability"] == reference_verdict(reference), describe(entry)
    if arm_rate == 0:
        verdicts = {round(abs(e["coordinates"]["th2"]), 6): e["stability"] for e in data["equilibria"]}
        assert verdicts == {0.0: STABLE, round(math.pi, 6): UNSTABLE}


# ---------------------------------------------------------------------------------------------------------------
# 2. Heavy symmetric top in three charts: steady precession

TOPS = {"zxz": BEYOND / "top_zxz.yaml", "cardan": BEYOND / "top_cardan.yaml",
        "resal": BEYOND / "top_resal_rotor.yaml", "xyz": BEYOND / "top_xyz.yaml"}
TP = ref.load_parameters(TOPS["zxz"])
M_, L_, G_, A0, C_ = TP["m"], TP["l"], TP["g"], TP["A0"], TP["C"]
A_PIVOT = A0 + M_ * L_**2                 # transverse moment about the pivot
MGL = M_ * G_ * L_
NU0 = math.pi / 3                         # nutation: 60 degrees from the upward vertical
SPIN = 60.0                               # total spin omega3 = n
W_CRIT = ref.sleeping_top_threshold(A_PIVOT, C_, MGL)      # 29.298 rad/s


def top_reference(chart: str) -> ref.LagrangeSystem:
    return ref.heavy_top(chart, M_, L_, G_, A0, C_)


def top_geometry(chart: str):
    """(sequence, symmetry axis index, centre of mass, principal moments) of the top in its model's body axes."""
    sequence, axis, _, _ = ref.TOP_CHARTS[chart]
    com, moments = [0.0, 0.0, 0.0], [A0, A0, A0]
    com[axis], moments[axis] = L_, C_
    return sequence, axis, com, moments


def precession_run(chart: str, root: int):
    """(options, precession rate, spin rate) of the steady precession `root` (0: slow, 1: fast) at NU0, SPIN."""
    rates = ref.precession_rates(A_PIVOT, C_, MGL, NU0, SPIN)
    assert len(rates) == 2
    W = rates[root]
    spin = ref.top_spin_rate(chart, NU0, W, SPIN)
    return sets(der_psi=W, der_phi=spin), W, spin


@pytest.mark.parametrize("chart", ["zxz", "cardan", "resal"])
def test_top_spin_is_cyclic_in_every_chart(chart):
    assert {"psi", "phi"} <= set(info_cyclic(TOPS[chart]))


@pytest.mark.parametrize("root", [0, 1], ids=["slow_precession", "fast_precession"])
@pytest.mark.parametrize("chart", ["zxz", "cardan", "resal"])
def test_top_steady_precession_at_both_roots_of_the_quadratic(chart, root):
    """A cos(nu) W^2 - C n W + m g l = 0 (A about the pivot): with der(psi) = W_k and the spin rate giving
    omega3 = n, the steady precession at nutation nu0 is listed (middle angle: nu0 in zxz and Resal, nu0 - pi/2 in
    the Cardan chart; the chart's second representation of the same orientation is accepted), its verdict is not
    'unstable' (the reference linearization is purely oscillatory) and its eigenvalues are the reference's."""
    options, W, spin = precession_run(chart, root)
    middle = ref.TOP_CHARTS[chart][3](NU0)
    equivalent = [middle, -middle] if chart != "cardan" else [middle, math.pi - middle]
    data = equilibria(TOPS[chart], *options)
    assert {"psi", "phi"} <= set(data["cyclic"])
    matches = [e for e in data["equilibria"]
               if min(ref.circle_distance(e["coordinates"]["theta"], v) for v in equivalent) < 1e-6]
    assert matches, [describe(e) for e in data["equilibria"]]
    entry = matches[0]
    assert entry["rates"]["psi"] == pytest.approx(W, rel=1e-9)
    assert entry["rates"]["phi"] == pytest.approx(spin, rel=1e-9)
    reference = top_reference(chart).reduced_eigenvalues({"theta": middle}, {"psi": W, "phi": spin},
                                                         ["psi", "phi"])
    assert reference_verdict(reference) == STABLE
    assert entry["stability"] not in (UNSTABLE, "asymptotically stable"), describe(entry)
    assert_same_spectrum(entry, reference)


def top_expected_verdict(chart: str, entry: dict, rates: dict) -> str | None:
    """The correct verdict of a listed top state, or None when it is not a steady motion at all. Upright (symmetry
    axis up): stable iff C^2 n^2 > 4 A m g l; hanging: stable; in between: from the reference linearization."""
    sequence, axis, com, moments = top_geometry(chart)
    names = ref.TOP_CHARTS[chart][2]
    angles = [entry["coordinates"].get(n, 0.0) for n in names]
    u = [rates.get(n, 0.0) for n in names]
    w = ref.body_angular_velocity(sequence, angles, u)
    scale = MGL + float(np.linalg.norm(np.asarray(moments) * w)) * float(np.linalg.norm(w))
    if ref.steady_motion_torque_residual(sequence, angles, u, com, moments, M_, (0, 0, -G_)) > 1e-6 * scale:
        return None
    cos_nu = float(ref.rotation_matrix(sequence, angles)[2, axis])
    if cos_nu > 1 - 1e-9:
        return STABLE if C_ * abs(w[axis]) > 2 * math.sqrt(A_PIVOT * MGL) else UNSTABLE
    if cos_nu < -1 + 1e-9:
        return STABLE
    cyclic = [n for n in names if n in rates]
    positional = {n: entry["coordinates"][n] for n in names if n not in rates}
    return reference_verdict(top_reference(chart).reduced_eigenvalues(positional, rates, cyclic))


def top_runs():
    runs = [pytest.param(chart, *precession_run(chart, root)[:1], id=f"{chart}-{name}")
            for chart in ("zxz", "cardan", "resal") for root, name in ((0, "slow"), (1, "fast"))]
    for factor in (0.95, 1.05):
        runs.append(pytest.param("xyz", sets(w=factor * W_CRIT), id=f"xyz-sleeping-{factor}"))
        runs.append(pytest.param("zxz", sets(der_psi=0.0, der_phi=factor * W_CRIT), id=f"zxz-sleeping-{factor}"))
    return runs


@pytest.mark.parametrize("chart, options", top_runs())
def test_top_every_listed_steady_motion_is_genuine_and_its_verdict_correct(chart, options):
    """Every row of the top's equilibria is a real steady motion (the angular-momentum balance about the pivot
    holds along q0 + rates*t, checked with the reference's own rotation matrices, valid at gimbal lock) with the
    correct verdict, or it is `undecided` with "coordinate singularity" in the reason. Gimbal locks here: zxz and
    Resal at theta = 0, pi; Cardan zyx at theta = +-pi/2; xyz at b = +-pi/2."""
    data = equilibria(TOPS[chart], *options)
    assert data["equilibria"]
    for entry in data["equilibria"]:
        if flagged_singular(entry):
            continue
        expected = top_expected_verdict(chart, entry, entry["rates"])
        assert expected is not None, "not a steady motion: " + describe(entry)
        assert entry["stability"] == expected, describe(entry)


# ---------------------------------------------------------------------------------------------------------------
# 3. Sleeping top: C^2 w^2 = 4 A m g l


@pytest.mark.parametrize("factor", [0.95, 1.05], ids=["below_threshold", "above_threshold"])
def test_sleeping_top_threshold_in_a_regular_chart(factor):
    """xyz chart (regular upright): a = b = 0 with spin w = factor * w_c is unstable below, stable above, with the
    reference eigenvalues: (A s^2 - m g l)^2 + C^2 w^2 s^2 = 0 and the family zero."""
    w = factor * W_CRIT
    data = equilibria(TOPS["xyz"], *sets(w=w))
    assert data["cyclic"] == ["c"]
    upright = [e for e in data["equilibria"] if abs(e["coordinates"]["a"]) < 1e-6 and abs(e["coordinates"]["b"]) < 1e-6]
    assert len(upright) == 1, [describe(e) for e in data["equilibria"]]
    entry = upright[0]
    assert entry["rates"]["c"] == pytest.approx(w, rel=1e-9)
    reference = top_reference("xyz").reduced_eigenvalues({}, {"c": w}, ["c"])
    assert reference_verdict(reference) == (UNSTABLE if factor < 1 else STABLE)
    assert entry["stability"] == (UNSTABLE if factor < 1 else STABLE), describe(entry)
    assert_same_spectrum(entry, reference)


@pytest.mark.parametrize("factor", [0.95, 1.05], ids=["below_threshold", "above_threshold"])
def test_sleeping_top_threshold_at_the_zxz_gimbal_lock(factor):
    """The same sleeping top in zxz angles: theta = 0 is a gimbal lock. Correct verdict, or undecided with
    "coordinate singularity" (never a wrong one). Total spin der(psi) + der(phi) = factor * w_c."""
    data = equilibria(TOPS["zxz"], *sets(der_psi=0.0, der_phi=factor * W_CRIT))
    upright = [e for e in data["equilibria"] if abs(e["coordinates"]["theta"]) < 1e-6]
    assert len(upright) == 1, [describe(e) for e in data["equilibria"]]
    entry = upright[0]   # gimbal lock of zxz
    assert entry["stability"] == (UNSTABLE if factor < 1 else STABLE) or flagged_singular(entry), describe(entry)


SWEEP = ("w", 25.0, 35.0, 11)        # grid step 1: w_c = 29.298 lies between 29 and 30


@functools.lru_cache(maxsize=None)
def sleeping_sweep_rows() -> list[dict]:
    name, lo, hi, n = SWEEP
    text = cli("equilibria", str(TOPS["xyz"]), "--sweep", f"{name}={lo}:{hi}:{n}", "-f", "csv")
    return list(csv.DictReader(io.StringIO(text)))


def classify_sweep_row(row: dict) -> tuple[float, str | None]:
    """(w, the correct verdict or None for a state that is no steady motion) of a branch row; the spin rate of
    the family is the swept w (`rate: w` in the file)."""
    w = float(row["w"])
    entry = {"coordinates": {"a": float(row["a"]), "b": float(row["b"])}}
    return w, top_expected_verdict("xyz", entry, {"c": w})


@pytest.mark.slow
def test_sleeping_top_sweep_verdict_changes_between_the_grid_points_bracketing_the_threshold():
    """--sweep w=25:35:11 -f csv: on every branch through the upright top (in either xyz representation), the
    verdict column is 'unstable' below w_c and 'stable' above, with rows on both sides within one grid step."""
    rows = sleeping_sweep_rows()
    assert rows and {"branch", "w", "a", "b", "stable", "verdict"} <= set(rows[0])
    step = (SWEEP[2] - SWEEP[1]) / (SWEEP[3] - 1)
    upright = []
    for row in rows:
        w, expected = classify_sweep_row(row)
        angles = (float(row["a"]), float(row["b"]), 0.0)
        if expected is not None and ref.rotation_matrix("xyz", angles)[2, 2] > 1 - 1e-9:
            upright.append((w, row["verdict"]))
    assert upright, rows[:5]
    below = [v for w, v in upright if w < W_CRIT * (1 - 1e-6)]
    above = [v for w, v in upright if w > W_CRIT * (1 + 1e-6)]
    assert set(below) == {UNSTABLE} and set(above) == {STABLE}, upright
    assert any(W_CRIT - step <= w < W_CRIT for w, _ in upright)
    assert any(W_CRIT < w <= W_CRIT + step for w, _ in upright)


@pytest.mark.slow
def test_sleeping_top_sweep_gives_no_verdict_to_gimbal_lock_artefacts():
    """Same sweep, every row: a state that is not a steady motion (the xyz chart's gimbal-lock roots a, b = +-pi/2,
    where gravity's moment is not balanced) must not carry a verdict other than 'undecided'; a real one carries
    the correct verdict (rows within 1e-6 of w_c are skipped)."""
    wrong = []
    for row in sleeping_sweep_rows():
        w, expected = classify_sweep_row(row)
        if abs(w - W_CRIT) < 1e-6 * W_CRIT:
            continue
        if (expected is None and row["verdict"] != UNDECIDED) or (expected is not None and row["verdict"] != expected):
            wrong.append((row["branch"], w, row["a"], row["b"], row["verdict"], expected))
    assert not wrong, wrong[:6]


# ---------------------------------------------------------------------------------------------------------------
# 4. Torque-free body: intermediate-axis theorem, every axis assignment, two sequences

FREE = {"zyx": BEYOND / "torque_free_zyx.yaml", "zxz": BEYOND / "torque_free_zxz.yaml"}
FB = ref.load_parameters(FREE["zyx"])
I1, I2, I3, SPIN_W = FB["Ix"], FB["Iy"], FB["Iz"], FB["w"]
assert I1 < I2 < I3
# Cyclic permutations of (I1, I2, I3) over body (x, y, z): every principal moment sits once on every body axis. Each
# run lists the spins with each body axis along ground z, so together they cover every axis assignment, including
# the gimbal locks: zyx with body x vertical (theta = +-pi/2), zxz with body z vertical (theta = 0 or pi).
ASSIGNMENTS = {"x1y2z3": (I1, I2, I3), "x2y3z1": (I2, I3, I1), "x3y1z2": (I3, I1, I2)}


@functools.lru_cache(maxsize=None)
def free_run(sequence: str, assignment: str) -> dict:
    Ix, Iy, Iz = ASSIGNMENTS[assignment]
    return equilibria(FREE[sequence], *sets(Ix=Ix, Iy=Iy, Iz=Iz))


def vertical_axis(sequence: str, entry: dict) -> tuple[int, bool]:
    """(body axis closest to ground z, whether it is exactly along it) for a listed row (psi is cyclic: 0)."""
    axis, misalignment = ref.vertical_body_axis(sequence, (0.0, entry["coordinates"]["theta"],
                                                           entry["coordinates"]["phi"]))
    return axis, misalignment < 1e-6


def spin_rate_constant(moments, axis: int) -> float:
    """kappa of a spin about principal axis `axis`: (Ik - Ia)(Ik - Ib)/(Ia Ib). kappa > 0: nutation at w sqrt(kappa)
    (stable); kappa < 0: growth rate w sqrt(-kappa) (unstable, the intermediate axis)."""
    Ik = moments[axis]
    Ia, Ib = (m for i, m in enumerate(moments) if i != axis)
    return (Ik - Ia) * (Ik - Ib) / (Ia * Ib)


free_cases = pytest.mark.parametrize("assignment", list(ASSIGNMENTS))
free_sequences = pytest.mark.parametrize("sequence", ["zyx", "zxz"])


@pytest.mark.slow
@free_cases
@free_sequences
def test_torque_free_intermediate_axis_theorem_in_every_axis_assignment(sequence, assignment):
    """Steady spin w about ground z with body axis k vertical, for k = x, y, z: stable when axis k carries I1 or
    I3, unstable with largest real eigenvalue w sqrt((I2-I1)(I3-I2)/(I1 I3)) when it carries I2; the stable ones
    show the nutation w sqrt(kappa). At a gimbal lock (zyx: body x vertical; zxz: body z vertical) the verdict
    must be correct or 'undecided' with "coordinate singularity"."""
    moments = ASSIGNMENTS[assignment]
    entries = free_run(sequence, assignment)["equilibria"]
    for axis in range(3):
        rows = [e for e in entries if vertical_axis(sequence, e) == (axis, True)]
        assert rows, f"no spin with body {'xyz'[axis]} vertical: {[describe(e) for e in entries]}"
        kappa = spin_rate_constant(moments, axis)
        for entry in rows:
            assert entry["rates"]["psi"] == pytest.approx(SPIN_W, rel=1e-12)
            if flagged_singular(entry):    # allowed only at a gimbal lock of the chart
                assert (sequence, axis) in {("zyx", 0), ("zxz", 2)}, describe(entry)
                continue
            lam = spectrum(entry)
            if kappa < 0:
                assert entry["stability"] == UNSTABLE, describe(entry)
                assert moments[axis] == I2
                assert max(lam.real) == pytest.approx(ref.intermediate_axis_growth(SPIN_W, I1, I2, I3), rel=1e-6)
            else:
                assert entry["stability"] == STABLE, describe(entry)
                nutation = SPIN_W * math.sqrt(kappa)
                assert min(abs(lam - 1j * nutation)) <= 1e-6 * nutation, describe(entry)


@pytest.mark.slow
@free_cases
@free_sequences
def test_torque_free_lists_no_gimbal_lock_artefacts(sequence, assignment):
    """Every listed row is a genuine steady spin about ground z: ground z is a principal (body coordinate) axis
    in the reported orientation, from the reference's own rotation matrices, and no eigenvalue is huge."""
    for entry in free_run(sequence, assignment)["equilibria"]:
        assert vertical_axis(sequence, entry)[1], "not a steady motion: " + describe(entry)
        assert np.max(np.abs(spectrum(entry)), initial=0.0) < 1e3, describe(entry)


@pytest.mark.parametrize("moments, rates", [
    pytest.param((I1, I3, I2), (0.0, 2.0, 0.0), id="major_axis_rotation_exactly_through_the_lock"),
    pytest.param((I1, I3, I2), (0.05, 2.0, 0.1), id="near_major_axis_passing_close_to_the_lock"),
    pytest.param((I1, I2, I3), (0.01, 2.0, 0.02), id="intermediate_axis_tumbling"),
])
def test_free_body_simulated_through_a_zyx_gimbal_lock_conserves_energy_and_momentum(tmp_path, moments, rates):
    """Starting at the identity with mostly der(theta), the zyx middle angle reaches +-pi/2 (body x vertical). The
    run must not stop ("carries no mass or inertia" or otherwise); energy and |angular momentum|, computed by the
    reference from the angles and rates, are conserved to 1e-6."""
    out = tmp_path / "run.csv"
    Ix, Iy, Iz = moments
    cli("simulate", str(FREE["zyx"]), *sets(Ix=Ix, Iy=Iy, Iz=Iz, psi=0, theta=0, phi=0, der_psi=rates[0],
                                            der_theta=rates[1], der_phi=rates[2]), "--t-end", "3", "-o", str(out))
    rows = list(csv.DictReader(out.read_text().splitlines()))
    assert float(rows[-1]["t"]) == pytest.approx(3.0)
    names = ("psi", "theta", "phi")
    invariants = np.array([ref.free_body_invariants("zyx", moments, [float(r[n]) for n in names],
                                                    [float(r[f"der({n})"]) for n in names]) for r in rows])
    assert min(abs(math.cos(float(r["theta"]))) for r in rows) < 0.05      # the lock was reached or nearly
    energy, momentum = invariants[:, 0], invariants[:, 1]
    assert np.ptp(energy) <= 1e-6 * energy[0]
    assert np.ptp(momentum) <= 1e-6 * momentum[0]


# ---------------------------------------------------------------------------------------------------------------
# 5. Centrifuge: every steady motion at 3, 12, 25 rad/s

CP = ref.load_parameters(CENTRIFUGE)


@pytest.mark.parametrize("speed, count", [(3, 2), (12, 4), (25, 4)])
def test_centrifuge_lists_every_steady_motion_without_search(speed, count):
    """dM = 50/7, Mo = speed*dM: alpha' = speed; the arm angles are the roots on (-pi, pi] of the beta row of the
    reference Lagrangian, found by dense sampling and brentq."""
    system = ref.centrifuge(*(CP[k] for k in ("I1", "m", "I2x", "I2y", "I2z", "a", "l", "g")))
    expected = ref.centrifuge_steady_angles(system, speed)
    assert len(expected) == count
    data = equilibria(CENTRIFUGE, "--set", "dM=50/7", "--set", f"Mo={speed}*50/7")
    found = sorted(e["coordinates"]["beta"] for e in data["equilibria"])
    assert found == pytest.approx(expected, abs=1e-6), data["message"]
    assert all(e["rates"]["alpha"] == pytest.approx(speed, rel=1e-9) for e in data["equilibria"])


# ---------------------------------------------------------------------------------------------------------------
# the reference itself (no mechsys): its closed forms agree with its Lagrangians


def test_reference_angular_velocity_matches_rotation_matrix_derivative():
    import sympy as sp
    q, u = sp.symbols("q1:4"), sp.symbols("u1:4")
    rng = np.random.default_rng(1)
    for sequence in ("zyx", "zxz", "xyz"):
        direct = ref.angular_velocity_body(ref.intrinsic(sequence, q), sp.Matrix(q), sp.Matrix(u))
        point = dict(zip((*q, *u), rng.uniform(-2, 2, 6)))
        assert np.allclose(np.array(direct.subs(point), dtype=float).ravel(),
                           ref.body_angular_velocity(sequence, [point[s] for s in q], [point[s] for s in u]))


@pytest.mark.parametrize("chart", ["zxz", "cardan", "resal"])
def test_reference_precession_quadratic_solves_each_charts_lagrangian(chart):
    system = top_reference(chart)
    middle = ref.TOP_CHARTS[chart][3](NU0)
    spectra = []
    for W in ref.precession_rates(A_PIVOT, C_, MGL, NU0, SPIN):
        spin = ref.top_spin_rate(chart, NU0, W, SPIN)
        residual = system.residual({"theta": middle}, {"psi": W, "phi": spin})
        assert np.max(np.abs(residual)) < 1e-12
        spectra.append(np.sort(np.abs(system.reduced_eigenvalues({"theta": middle}, {"psi": W, "phi": spin},
                                                                 ["psi", "phi"]))))
    zxz = [np.sort(np.abs(top_reference("zxz").reduced_eigenvalues(
        {"theta": NU0}, {"psi": W, "phi": ref.top_spin_rate("zxz", NU0, W, SPIN)}, ["psi", "phi"])))
        for W in ref.precession_rates(A_PIVOT, C_, MGL, NU0, SPIN)]
    assert np.allclose(spectra, zxz, rtol=1e-9, atol=1e-9)


def test_reference_sleeping_top_threshold_and_intermediate_axis_rate():
    top = top_reference("xyz")
    for factor, unstable in ((0.999, True), (1.001, False)):
        lam = top.reduced_eigenvalues({}, {"c": factor * W_CRIT}, ["c"])
        assert (np.max(lam.real) > 1e-6) == unstable
    body = ref.free_body("zyx", I1, I2, I3)
    lam = body.reduced_eigenvalues({"phi": math.pi / 2}, {"psi": SPIN_W}, ["psi"])   # body y vertical
    assert np.max(lam.real) == pytest.approx(ref.intermediate_axis_growth(SPIN_W, I1, I2, I3), rel=1e-9)
    lam = body.reduced_eigenvalues({}, {"psi": SPIN_W}, ["psi"])                       # body z vertical
    assert np.min(np.abs(lam - 1j * SPIN_W * math.sqrt(spin_rate_constant((I1, I2, I3), 2)))) < 1e-9


def test_a_precession_branch_born_at_a_gimbal_lock_is_swept():
    """Heavy top in zxz angles at spin der(phi) = 40, swept over der(psi) = 40..65: the steady precession branch leaves
    the sleeping top (theta = 0, a gimbal lock of zxz) at der(psi) = 50.07 and follows cos(theta) = (C phi' psi' -
    m g l)/((A - C) psi'^2), A = A0 + m l^2 about the pivot. It was dropped as 'a twin in other angles' of the
    sleeping top: compared at the first parameter value both reached, the branch point, where they are one motion."""
    result = runner.invoke(app, ["equilibria", str(BEYOND / "top_zxz.yaml"), "--set", "der(psi)=65", "--set",
                                 "der(phi)=40", "--sweep", "der(psi)=40:65:26", "-f", "csv"])
    assert result.exit_code == 0, result.output
    A, C, mgl = 0.004 + 1.0 * 0.1**2, 0.008, 1.0 * 9.81 * 0.1
    tilted = [r for r in csv.DictReader(io.StringIO(result.output)) if 1e-6 < abs(float(r["theta"])) < math.pi - 1e-6]
    assert len(tilted) >= 10 and max(float(r["der(psi)"]) for r in tilted) == 65.0
    for r in tilted:
        w = float(r["der(psi)"])
        assert abs(float(r["theta"])) == pytest.approx(math.acos((C * 40 * w - mgl) / ((A - C) * w * w)), abs=1e-8)


# ---------------------------------------------------------------------------------------------------------------
# distinct rests with the same mass positions; angles a swept parameter makes non-periodic


def test_rests_with_the_same_masses_but_other_spring_energies_are_distinct():
    """Snap-through linkage at P = 0 (tests/data/beyond/snap_through.yaml): the only potential is the spring's,
    k/2 (s - 1)^2, on the manifold where s = +-d(th1), d = sqrt(3.56 - 3.2 cos th1) the apex's distance from B.
    Stationary: s = 1 (cos th1 = 0.8, stable), or d'(th1) = 0 (th1 = 0, pi) with s = +-d: at th1 = 0, s = -0.6
    is a minimum of (d + 1)^2 (stable), s = +0.6 a maximum of (d - 1)^2; at th1 = pi both are unstable. The rests
    at th1 = 0 put the masses in the same places (the rod's particle at the apex, the sleeve massless) and were
    one: the stable s = -0.6 was dropped and the unstable +0.6 reported at th1 = 0."""
    data = equilibria(BEYOND / "snap_through.yaml", "--set", "P=0")
    got = sorted((round(e["coordinates"]["th1"], 6), round(e["coordinates"]["s"], 6), e["stability"] != "unstable")
                 for e in data["equilibria"])
    th = round(math.acos(0.8), 6)
    want = sorted([(-th, 1.0, True), (th, 1.0, True), (0.0, -0.6, True), (0.0, 0.6, False),
                   (round(math.pi, 6), -2.6, False), (round(math.pi, 6), 2.6, False)])
    assert got == want


def test_a_sweep_decides_the_angles_periodicity_over_the_swept_values():
    """The file's k = 0 makes th periodic; swept over k > 0 it is not (k th + sin th = tau). The sweep's rows were
    wrapped 2 pi off (68 of 89: residual up to 1.94), its fold at k = 0.32997 was reported at th = -1.907 and
    five folds beyond th = +-pi were missed (found only when another run's searches were in the cache). Every row
    now solves k th + sin th = tau, and the folds are those of k + cos th = 0 with it (scipy here)."""
    from scipy.optimize import brentq

    out = cli("equilibria", str(BEYOND / "torque_spring.yaml"), "--set", "tau=0.5", "--sweep", "k=0.05:0.5:10",
              "-f", "csv")
    rows = [r for r in csv.reader(io.StringIO(out)) if r]
    header = next(r for r in rows if r[0] == "branch")
    table = [dict(zip(header, r)) for r in rows if r[0].isdigit() and len(r) == len(header)]
    assert len(table) > 100
    for row in table:
        k, th = float(row["k"]), float(row["th"])
        assert abs(k * th + math.sin(th) - 0.5) < 1e-6
    # the folds: k = -cos th and k th + sin th = 0.5, i.e. g(th) = -th cos th + sin th - 0.5 = 0 with k in range
    def g(x: float) -> float:
        return -x * math.cos(x) + math.sin(x) - 0.5

    grid = np.linspace(-40, 40, 80001)
    roots = [brentq(g, a, b) for a, b in zip(grid[:-1], grid[1:]) if g(a) * g(b) < 0]
    want = sorted((-math.cos(x), x) for x in roots if 0.05 <= -math.cos(x) <= 0.5)
    data = equilibria(BEYOND / "torque_spring.yaml", "--set", "tau=0.5", "--sweep", "k=0.05:0.5:10")
    folds = sorted((b["value"], b["coordinates"]["th"]) for b in data["bifurcations"] if b["kind"] == "fold")
    assert len(want) == 6 and len(folds) == len(want)
    for (k, th), (k_want, th_want) in zip(folds, want):
        assert k == pytest.approx(k_want, abs=1e-6) and th == pytest.approx(th_want, abs=1e-6)


def test_a_cyclic_coordinate_not_reduced_because_of_constraints_is_named():
    """A governor with its sleeve tied by a holonomic constraint spins steadily at der(psi) = 10 (th = 0.339104),
    but with constraints the cyclic spindle is not reduced: the search looks for rests only. It said 'no
    equilibrium found ... widen it with --search'; the message now says why."""
    data = equilibria(BEYOND / "porter_governor.yaml")
    assert data["equilibria"] == []
    assert "with constraints the cyclic coordinate(s) psi are not reduced" in data["message"]


# ---------------------------------------------------------------------------------------------------------------
# a double zero eigenvalue split by rounding is no instability
HANGING = {"b1": 0.0, "c1": 0.0, "a2": 0.0, "b2": 0.0, "c2": 0.0, "a3": 0.0, "c3": 0.0}


def test_a_spinning_chain_of_ball_joints_hanging_is_not_called_unstable_for_its_free_twists():
    """Three boxes on ball joints hang down while the top one spins about the vertical (der(a1) = 0.5). The twists
    a2, a3 cost no energy (an independent effective-potential Hessian: 8e-18 and -1.5e-11 beside 0.57..13.9, no
    negative stiffness; the same frequencies 2.977, 3.975, 7.754, 8.743, 13.706, 14.848 rad/s). Their double zero
    eigenvalue came out as +-4.8e-8 beside 15 rad/s: `equilibria` said 'unstable', `modes` 'the motion grows'."""
    from mechsys import load
    from mechsys.analysis.equilibrium.equilibria import _polish, make_problem
    from mechsys.analysis.equilibrium.stability import assess
    from mechsys.numeric.parameters import parameter_values

    path = BEYOND / "chain_ball_spin.yaml"
    model = load(path, {**HANGING, "b3": 0.13})
    problem = make_problem(model)
    p = parameter_values(model)
    z = _polish(problem, problem.state(problem.equilibrium(np.zeros(len(problem.unknowns)))), p)
    e = problem.equilibrium(z)
    assess(problem, e, p)
    assert e.stability == UNDECIDED and "critical case" in e.reason and "flat" in e.reason
    assert np.max(np.abs(e.eigenvalues.real)) < 1e-6 * np.max(np.abs(e.eigenvalues))
    at = [x for c, v in {**HANGING, **e.coordinates}.items() for x in ("--at", f"{c}={v!r}")]
    modes = json.loads(cli("modes", path, *at, "-f", "json"))
    assert modes["unstable_modes"] == 0 and "grows" not in modes.get("note", "")
    assert sorted(abs(complex(*v).imag) for v in modes["eigenvalues"] if abs(complex(*v)) > 1) == \
        pytest.approx(sorted(2 * [2.977174, 3.974840, 7.753763, 8.743346, 13.70646, 14.84825]), rel=1e-6)


def _zxz(q1: float, q2: float, q3: float) -> np.ndarray:
    def rz(a):
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])

    def rx(a):
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])

    return rz(q1) @ rx(q2) @ rz(q3)


def test_rests_at_a_gimbal_lock_are_listed_once_whatever_sequence_classified_them():
    """A box on four springs (free joint, zxz): its rests at the zxz lock are continua of the file's angles (at
    q2 = pi only q1 - q3 counts). One rest was listed three times (re-charted twice to xzy, once to xyz) and
    another twice. Each listed rest is now one pose: positions and rotation matrices computed here differ."""
    out = equilibria(BEYOND / "box_on_springs_zxz.yaml")
    poses = [(np.array([c["x"], c["y"], c["z"]]), _zxz(c["q1"], c["q2"], c["q3"]))
             for c in (e["coordinates"] for e in out["equilibria"])]
    for i, (r1, R1) in enumerate(poses):
        for r2, R2 in poses[:i]:
            assert np.max(np.abs(r1 - r2)) > 1e-6 or np.max(np.abs(R1 - R2)) > 1e-6
    stable = [pose for pose, e in zip(poses, out["equilibria"]) if e["stability"] == STABLE]
    assert len(stable) == 1 and np.allclose(stable[0][1], np.eye(3), atol=1e-9)  # the box level, at the lock


def test_modes_say_that_the_stable_rest_was_found_at_the_lock():
    """`modes` of the same box vibrated about an unstable rest and said 'the search found no stable equilibrium',
    where the stable one (level, z = 0.1547) was found at the zxz lock and passed over."""
    note = json.loads(cli("modes", BEYOND / "box_on_springs_zxz.yaml", "-f", "json"))["note"]
    assert "the stable equilibrium found" in note and "z = 0.154723" in note and "coordinate singularity" in note
    assert "found no stable" not in note


# ---------------------------------------------------------------------------------------------------------------
# Time written where a few random times do not see it (a step, a ramp) or in a constraint

_SPIN_ARM = """name: spinarm
parameters: {{M: 2.0, a: 0.4, m: 1.5, L: 0.6, g: 9.81, W: 7.0}}
coordinates:
  psi: {psi}
  theta: {{initial: 0.3}}
links:
  arm:
    joint: {{type: revolute, parent: ground, axis: y, coordinate: psi}}
    mass: M
    center_of_mass: [a/2, 0, 0]
  rod:
    joint: {{type: revolute, parent: arm, axis: z, coordinate: theta, origin: [a, 0, 0]}}
    mass: m
    center_of_mass: [0, -L/2, 0]
    shape: {{rod: {{length: L, axis: y}}}}
forces:
  - {{type: gravity, acceleration: [0, -g, 0]}}
{constraints}"""


def test_a_drive_written_as_a_constraint_that_moves_with_time_has_no_rests(tmp_path):
    """A rod pendulum on an arm held by the constraint psi - W*t. Its velocity row psi' - W has no t in it, so the
    model passed for autonomous: the constraint was read at t = 0 and `equilibria` listed the pendulum on an arm at
    rest (theta = 0 at sqrt(3g/2L) = 4.95 rad/s) where the arm spins at W. No configuration satisfies it at rest:
    refused, naming the constraint; `info` calls the model rheonomic. Written as a prescribed spin (the remedy the
    message gives), its relative rests are the stationary points of the effective potential
    U = -m g (L/2) cos(theta) - W^2/2 (m (a + (L/2) sin(theta))^2 + m L^2/12 sin^2(theta)) (own derivation)."""
    from scipy.optimize import brentq

    held = tmp_path / "held.yaml"
    spin = "constraints:\n  - {type: holonomic, name: spin, expression: psi - W*t}\n"
    held.write_text(_SPIN_ARM.format(psi="{initial: 0, rate: W}", constraints=spin))
    result = runner.invoke(app, ["equilibria", str(held)])
    assert result.exit_code == 1
    assert "the constraint 'spin' moves with time" in result.output
    assert "make it prescribed" in result.output
    info = runner.invoke(app, ["info", str(held)])
    assert info.exit_code == 0 and "rheonomic, non-autonomous" in info.output

    prescribed = tmp_path / "prescribed.yaml"
    prescribed.write_text(_SPIN_ARM.format(psi='{prescribed: "W*t"}', constraints=""))
    m, a, L, g, W = 1.5, 0.4, 0.6, 9.81, 7.0

    def dU(th):
        return m * g * L / 2 * math.sin(th) - W ** 2 * (m * (a + L / 2 * math.sin(th)) * L / 2 * math.cos(th)
                                                       + m * L ** 2 / 12 * math.sin(th) * math.cos(th))

    grid = np.linspace(-math.pi, math.pi, 2001)
    roots = sorted(brentq(dU, x, y, xtol=1e-14) for x, y in zip(grid[:-1], grid[1:]) if dU(x) * dU(y) < 0)
    data = json.loads(runner.invoke(app, ["equilibria", str(prescribed), "-f", "json"]).output)
    found = sorted(e["coordinates"]["theta"] for e in data["equilibria"])
    assert found == pytest.approx(roots, abs=1e-8)
    assert roots[1] == pytest.approx(1.32190, abs=1e-5)


@pytest.mark.parametrize("force", ["F0*(1 + sign(t - t1))/2", "F0*min(max(t - t1, 0), 1)"])
def test_a_step_or_ramp_in_time_is_time_dependence(tmp_path, force):
    """A block on a spring loaded by a step (or a ramp) at t1 = 2 s. d/dt at four random times in [-1.3, 1.7] was zero
    each time (before the step, or a DiracDelta evaluated as 0), so the model passed for autonomous and `equilibria`
    gave the unloaded rest x = 0; `info` said autonomous."""
    path = tmp_path / "step.yaml"
    path.write_text("name: step\nparameters: {m: 1, k: 100, c: 2, F0: 10, t1: 2}\ncoordinates:\n  x: {initial: 0}\n"
                    "links:\n  block:\n    joint: {type: prismatic, parent: ground, axis: x, coordinate: x}\n"
                    "    mass: m\nforces:\n  - {type: torsional_spring, coordinate: x, stiffness: k}\n"
                    f"  - {{type: generalized_force, coordinate: x, value: \"{force}\"}}\n")
    result = runner.invoke(app, ["equilibria", str(path)])
    assert result.exit_code == 1 and "non-autonomous" in result.output
    assert "non-autonomous" in runner.invoke(app, ["info", str(path)]).output
