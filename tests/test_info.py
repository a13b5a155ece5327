"""`info`: DOF of every bundled system, mobility counting (Krodkiewski eq. 1.8, Fig. 8), system classes."""
from dataclasses import asdict as asdict_info
from pathlib import Path

import pytest

import mechsys
from mechsys.analysis.info import system_info

ROOT = Path(__file__).resolve().parents[1]

# (file, DOF = independent velocities, configuration DOF, prescribed count)
EXPECTED = [
    ("centrifuge", 2, 2, 0),
    ("gyrostabilizer", 2, 2, 1),
    ("indicator", 1, 1, 2),
    ("problem57", 1, 1, 0),
    ("motor_arm", 2, 2, 0),
    ("double_pendulum", 2, 2, 0),
    ("cart_pendulum", 2, 2, 0),
    ("spring_chain", 3, 3, 0),
    ("slider_crank", 1, 1, 0),
    ("four_bar", 1, 1, 0),
    ("rolling_disk", 3, 5, 0),
    ("wheel_on_axle", 1, 1, 2),
]


def test_every_bundled_system_is_listed_here():
    bundled = {p.stem for p in (ROOT / "systems").glob("*.yaml")}
    assert {name for name, *_ in EXPECTED} <= bundled


@pytest.mark.parametrize("name, dof, config_dof, prescribed", EXPECTED, ids=[e[0] for e in EXPECTED])
def test_dof_of_bundled_systems(name, dof, config_dof, prescribed):
    info = system_info(mechsys.load(ROOT / "systems" / f"{name}.yaml"))
    assert info.dof == dof
    assert info.configuration_dof == config_dof
    assert len(info.prescribed) == prescribed
    assert info.dof_formula == info.dof  # Grübler-Kutzbach count agrees with the constraint rank


def test_krodkiewski_fig8_mobility_is_5():
    info = system_info(mechsys.load(ROOT / "tests" / "data" / "fig8_mobility.yaml"))
    assert sorted(j.joint_class for j in info.joints) == [2, 3]
    assert info.mobility == 5 and info.dof == 5


def test_classes_of_textbook_systems():
    ind = system_info(mechsys.load(ROOT / "systems" / "indicator.yaml"))
    assert ind.rheonomic and ind.autonomous and ind.holonomic  # constant prescribed rates: autonomous EOM
    disk = system_info(mechsys.load(ROOT / "systems" / "rolling_disk.yaml"))
    assert not disk.holonomic
    cen = system_info(mechsys.load(ROOT / "systems" / "centrifuge.yaml"))
    assert cen.cyclic == ["alpha"] and cen.system_class == "holonomic, scleronomic, autonomous"


CARTS = """name: two_carts
parameters: {m: 1, L: 0.5}
coordinates:
  x1: {initial: 0, rate: 0}
  x2: {initial: 0.5, rate: 0}
links:
  cart1: {particle: true, mass: m, joint: {type: prismatic, parent: ground, axis: x, coordinate: x1}}
  cart2: {particle: true, mass: m, joint: {type: prismatic, parent: ground, axis: x, coordinate: x2}}
"""


def test_a_coordinate_in_a_holonomic_constraint_is_not_cyclic(tmp_path):
    """Two free carts on a line are each cyclic (T = m(x1'^2 + x2'^2)/2 only); a rod x2 - x1 = L between them
    enters the velocity rows only through constant coefficients (A = [-1, 1]), yet shifting x1 alone breaks it,
    so neither is cyclic any more. Before the fix the slider-crank's x4 was reported cyclic the same way."""
    free, rod = tmp_path / "free.yaml", tmp_path / "rod.yaml"
    free.write_text(CARTS)
    rod.write_text(CARTS + "constraints:\n  - {type: holonomic, name: rod, expression: x2 - x1 - L}\n")
    assert system_info(mechsys.load(free)).cyclic == ["x1", "x2"]
    assert system_info(mechsys.load(rod)).cyclic == []
    for name in ("slider_crank", "four_bar"):
        assert system_info(mechsys.load(ROOT / "systems" / f"{name}.yaml")).cyclic == []
    driven = system_info(mechsys.load(ROOT / "docs" / "examples" / "slider_crank_driven.yaml"))
    assert driven.cyclic == []


def test_redundant_constraint_is_detected(tmp_path):
    text = (ROOT / "systems" / "centrifuge.yaml").read_text()
    text += "constraints:\n  - {type: holonomic, expression: beta - 0.1}\n  - {type: holonomic, expression: 2*beta - 0.2}\n"
    path = tmp_path / "redundant.yaml"
    path.write_text(text)
    info = system_info(mechsys.load(path))
    assert info.constraint_rank == 1 and info.redundant_constraints == 1 and info.dof == 1


def test_the_symbolic_proof_of_a_cyclic_coordinate_has_a_size_budget(monkeypatch):
    """Issue 13: `mechsys info` on the bicycle spent 30 s failing to prove its wheel angles cyclic symbolically
    (33 entries of 84,000 operations); entries larger than SYMBOLIC_BUDGET tree nodes together are not tried
    (the basis stays "numeric", decided at random states), smaller ones are, smallest first."""
    import sympy as sp

    from mechsys.mechanics import symmetry

    q, a = sp.symbols("q a")
    tried = []
    monkeypatch.setattr(symmetry, "_constant_in", lambda e, s: tried.append(e) or True)
    small = [sp.sin(q) ** 2 + sp.cos(q) ** 2, a * sp.cos(q) ** 2 + a * sp.sin(q) ** 2 + a]
    assert symmetry._proven_constant(small, q) and tried == [small[0], small[1]]
    big = q
    for _ in range(14):  # a shared tree: cheap to build, over 20,000 nodes when walked
        big = big * sp.cos(big) + a
    tried.clear()
    assert not symmetry._proven_constant(small + [big], q) and tried == []
    assert symmetry._size(big, 100) == 101


@pytest.mark.parametrize("name", ["four_bar", "centrifuge", "rolling_disk"])
def test_a_second_info_reads_its_matrices_from_the_cache_and_says_the_same(name, tmp_path, monkeypatch):
    """Issue 13: `info` compiled M and A (sympy CSE) on every run; where it still compiles them (an entry that
    floating point does not evaluate, forced here), their generated code is cached like the simulation's. A cached
    run generates no code and gives what an uncached one gives."""
    import mechsys.analysis.info as info

    monkeypatch.setattr(info, "_evaluated", lambda *args: None)
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    uncached = asdict_info(system_info(mechsys.load(ROOT / "systems" / f"{name}.yaml")))
    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    first = asdict_info(system_info(mechsys.load(ROOT / "systems" / f"{name}.yaml")))

    def no_code(*args, **kwargs):
        raise AssertionError("a cached info generated code")

    monkeypatch.setattr(info, "matrix_source", no_code)
    second = asdict_info(system_info(mechsys.load(ROOT / "systems" / f"{name}.yaml")))
    assert first == second == uncached


@pytest.mark.parametrize("name", ["four_bar", "centrifuge", "rolling_disk", "indicator", "gyrostabilizer"])
def test_info_evaluates_m_and_a_without_code_and_says_what_compiled_code_says(name, monkeypatch):
    """`info` evaluates A and M at its three states over their expression DAGs (no CSE, no compiled code): the
    facts equal those of the compiled matrices."""
    import mechsys.analysis.info as info

    monkeypatch.setenv("MECHSYS_CACHE", "off")
    evaluated = asdict_info(system_info(mechsys.load(ROOT / "systems" / f"{name}.yaml")))
    monkeypatch.setattr(info, "matrix_source", lambda *a, **k: pytest.fail("compiled"))
    assert asdict_info(system_info(mechsys.load(ROOT / "systems" / f"{name}.yaml"))) == evaluated
    monkeypatch.undo()
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    monkeypatch.setattr(info, "_evaluated", lambda *args: None)
    assert asdict_info(system_info(mechsys.load(ROOT / "systems" / f"{name}.yaml"))) == evaluated


def test_a_mass_matrix_that_floating_point_does_not_evaluate_is_compiled(tmp_path, monkeypatch):
    """A user's `max(...)` in a mass (Max is not an elementary function for dag.Evaluation): `info` compiles M
    and A instead, and says what it says of the same model with the value written out."""
    import mechsys.analysis.info as info

    monkeypatch.setenv("MECHSYS_CACHE", "off")
    text = (ROOT / "systems" / "double_pendulum.yaml").read_text()
    with_max, plain = tmp_path / "with_max.yaml", tmp_path / "plain.yaml"
    with_max.write_text(text.replace("    mass: m2\n", "    mass: max(m2, 0.5)\n"))
    plain.write_text(text)
    assert "max(m2, 0.5)" in with_max.read_text()
    model = mechsys.load(with_max)
    p = [model.parameters[s.name] for s in model.parameter_symbols]
    assert info._evaluated(model, [(0.0, [0.1, 0.2], [0.0, 0.0])], p) is None
    facts = asdict_info(system_info(model))
    assert {k: v for k, v in facts.items() if k != "name"} == \
        {k: v for k, v in asdict_info(system_info(mechsys.load(plain))).items() if k != "name"}


def test_the_autonomy_decision_is_remembered_and_equals_a_fresh_one(tmp_path, monkeypatch):
    """MechanicalModel.is_autonomous scans the whole equations for t (half a second on the bicycle); the answer is
    stored per structure and parameter values. Stored equals fresh for a model without t, one whose prescribed
    constant spins leave t that cancels (the indicator: autonomous), and one excited by a given motion of its
    base (not autonomous); another parameter value is decided again."""
    import mechsys
    from mechsys.mechanics.model import MechanicalModel
    from tests.helpers import DATA_DIR, SYSTEMS_DIR

    monkeypatch.setenv("MECHSYS_CACHE", str(tmp_path / "cache"))
    decided = []
    real = MechanicalModel._decide_autonomous
    monkeypatch.setattr(MechanicalModel, "_decide_autonomous", lambda self, m: decided.append(m) or real(self, m))
    cases = [(SYSTEMS_DIR / "centrifuge.yaml", True), (SYSTEMS_DIR / "indicator.yaml", True),
             (DATA_DIR / "chain_base_excitation.yaml", False)]
    for path, expected in cases:
        before = len(decided)
        assert mechsys.load(path).is_autonomous() is expected  # decided
        assert mechsys.load(path).is_autonomous() is expected  # read back: a new model object, no decision
        assert len(decided) == before + 1
    mechsys.load(SYSTEMS_DIR / "indicator.yaml", {"Omega": 100}).is_autonomous()
    assert len(decided) == 4


def _rods(n: int, gravity: bool) -> str:
    """An n-link pendulum of rods with relative angles, written as a user would."""
    lines = ["name: rods", "parameters: {m: 0.7, l: 0.9, g: 9.81}", "coordinates:"]
    lines += [f"  q{k}: {{initial: 0.1, rate: 0}}" for k in range(1, n + 1)] + ["links:"]
    for k in range(1, n + 1):
        parent = "ground" if k == 1 else f"rod{k - 1}"
        origin = "" if k == 1 else ", origin: [l, 0, 0]"
        lines += [f"  rod{k}:", f"    joint: {{type: revolute, parent: {parent}, axis: z, coordinate: q{k}{origin}}}",
                  "    mass: m", "    center_of_mass: [l/2, 0, 0]", "    shape: {rod: {length: l, axis: x}}"]
    if gravity:
        lines += ["forces:", "  - {type: gravity, acceleration: [0, -g, 0]}"]
    return "\n".join(lines) + "\n"


def test_a_chain_s_angles_are_shown_not_cyclic_without_compiled_code(tmp_path, monkeypatch):
    """Issue 13: the cyclic decision compiled M and f whole (29 s of the 80-link chain's `info`). Shifting one
    angle changes a few small entries: evaluated in floating point (symmetry._Entries), no code is compiled. The
    first angle changes f only (gravity); without gravity it is cyclic (the chain turns as a whole: closed form),
    which the shift test confirms, walking the equations at its states (dag.Points): still nothing compiled."""
    from mechsys.mechanics import symmetry

    monkeypatch.setenv("MECHSYS_CACHE", "off")
    compiled = []
    real = symmetry._Shifts._fn
    monkeypatch.setattr(symmetry._Shifts, "_fn", lambda self, k: compiled.append(k) or real(self, k))
    for gravity, cyclic in ((True, []), (False, ["q1"])):
        path = tmp_path / f"rods_{gravity}.yaml"
        path.write_text(_rods(12, gravity))
        compiled.clear()
        decision = mechsys.load(path).cyclic_decision
        assert decision.names == cyclic
        assert compiled == []


MODELS = sorted([*(ROOT / "systems").glob("*.yaml"), *(ROOT / "tests" / "data" / "beyond").glob("*.yaml")])


@pytest.mark.parametrize("path", MODELS, ids=[p.stem for p in MODELS])
def test_the_quick_cyclic_tests_decide_as_the_compiled_ones(path, monkeypatch):
    """The cyclic coordinates (and their basis) of every bundled model and the user-written ones (tops, Furuta,
    torque-free bodies) are the same with the uncompiled first test as with the compiled test alone, and the same
    with the shift test's one walk over all its states (dag.Points: M, f, A, b and Phi) as with its compiled
    functions. (One test: the default decision, with both quick paths, is computed once.)"""
    from mechsys.mechanics import symmetry

    monkeypatch.setenv("MECHSYS_CACHE", "off")
    quick = mechsys.load(path).cyclic_decision
    with monkeypatch.context() as patch:
        patch.setattr(symmetry._Entries, "dependent", lambda self, q: False)
        alone = mechsys.load(path).cyclic_decision
    assert (quick.names, quick.basis, quick.denied) == (alone.names, alone.basis, alone.denied)
    monkeypatch.setattr(symmetry._Shifts, "_walked", lambda self, k, walk, count: None)
    compiled = mechsys.load(path).cyclic_decision
    assert (quick.names, quick.basis, quick.denied) == (compiled.names, compiled.basis, compiled.denied)


def test_points_evaluates_as_compiled_code_at_every_point():
    """dag.Points gives what the compiled matrix gives at each point (the bicycle's M, f, A, b), to round-off;
    nan outside the reals, None for a node it does not know."""
    import numpy as np
    import sympy as sp

    from mechsys.mechanics.dag import Points
    from mechsys.numeric.lambdify import compile_matrix

    model = mechsys.load(ROOT / "systems" / "bicycle.yaml")
    eq = model.equations("kane")
    rng = np.random.default_rng(5)
    k = 6
    q, u = rng.uniform(-2, 2, (k, len(model.q))), rng.uniform(-2, 2, (k, len(model.u)))
    p = np.array([model.parameters[s.name] for s in model.parameter_symbols])
    values = {model.t: np.zeros(k), **{s: q[:, j] for j, s in enumerate(model.q)},
              **{s: u[:, j] for j, s in enumerate(model.u)}, **dict(zip(model.parameter_symbols, p))}
    walk = Points(values)
    for mat in (eq.M, eq.f, eq.A, eq.b):
        fn = compile_matrix(mat, model.t, model.q, model.u, model.parameter_symbols)
        walked = np.array([np.broadcast_to(walk.of(e), (k,)) for e in mat]).T
        for s in range(k):
            want = np.asarray(fn(0.0, q[s], u[s], p), dtype=float).ravel()
            assert np.allclose(walked[s], want, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(want).max()))
    x = sp.Symbol("x")
    out = Points({x: np.array([4.0, -4.0])}).of(sp.sqrt(x) + x**3)
    assert out[0] == 2.0 + 64.0 and np.isnan(out[1])
    assert Points({x: np.array([1.0])}).of(sp.Piecewise((x, x > 0), (0, True))) is None
    assert Points({}).of(x + 1) is None


BALANCE = """\
name: watch_balance
description: a watch's balance wheel and its lever, each on a hairspring
parameters: {Ib: 1.2e-10, kh: 5e-6, ml: 2e-6, ll: 3e-3}
coordinates: {phi: {initial: 0.5}, psi: {}}
links:
  balance:
    joint: {type: revolute, parent: ground, axis: z, coordinate: phi}
    inertia: {zz: Ib}
  lever:
    joint: {type: revolute, parent: ground, axis: z, coordinate: psi, origin: [0.01, 0, 0]}
    mass: ml
    center_of_mass: [ll, 0, 0]
forces:
  - {type: torsional_spring, coordinate: phi, stiffness: kh}
  - {type: torsional_spring, coordinate: psi, stiffness: kh}
"""


def test_facts_of_small_si_models_are_relative_to_their_own_scale(tmp_path, monkeypatch):
    """A watch balance (M = diag(1.2e-10, 1.8e-11) kg m^2, positive definite) was said to have a singular mass
    matrix, and a four-bar scaled to micrometres and nanograms had every coordinate 'massless' and a constraint
    rank of 0 (3 DOF): thresholds had a floor of 1 under the matrices' scale. Grubler: the balance has 2 DOF, the
    four-bar 1 (rank 2), as at metre scale."""
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    path = tmp_path / "balance.yaml"
    path.write_text(BALANCE)
    info = system_info(mechsys.load(path))
    assert info.dof == 2 and not info.massless_coordinates and not info.notes
    scaled = {"l1": 0.4e-6, "l2": 0.1e-6, "l3": 0.35e-6, "l4": 0.3e-6, "m2": 0.5e-9, "m3": 1.2e-9, "m4": 0.8e-9}
    micro = mechsys.load(ROOT / "systems" / "four_bar.yaml", {k: str(v) for k, v in scaled.items()})
    info = system_info(micro)
    assert (info.constraint_rank, info.dof, info.massless_coordinates) == (2, 1, [])


def test_a_picometre_four_bar_keeps_its_loop(monkeypatch):
    """The four-bar with its bars scaled to picometres was refused: 'this constraint references no coordinate (it
    is identically satisfied)', its loop rows (1e-12 m) taken for round-off by absolute thresholds. Dimensional
    analysis: the loop keeps rank 2 and 1 DOF, and the mass matrix at the same angles scales with s^2 (masses
    kept)."""
    import numpy as np

    monkeypatch.setenv("MECHSYS_CACHE", "off")
    s = 1e-12
    lengths = {"l1": 0.4, "l2": 0.1, "l3": 0.35, "l4": 0.3}
    path = ROOT / "systems" / "four_bar.yaml"
    big, small = mechsys.load(path), mechsys.load(path, {k: repr(v * s) for k, v in lengths.items()})
    info = system_info(small)
    assert (info.constraint_rank, info.dof, info.massless_coordinates) == (2, 1, [])
    angles = {q: v for q, v in zip(big.q, (0.7, 0.4, 2.1))}

    def mass_matrix(model):
        values = {p: model.parameters[p.name] for p in model.parameter_symbols}
        M = model.equations("kane").M.subs(angles).subs(values)
        return np.array(M.evalf(), dtype=float)

    assert np.allclose(mass_matrix(small) / s ** 2, mass_matrix(big), rtol=1e-12, atol=0)


MEMS_DRIVEN = """\
name: mems_drive
parameters: {m: 1.0e-9, L: 1.0e-4, g: 9.81, A: 2.0e-5, w: 300}
coordinates:
  s: {prescribed: A*sin(w*t)}
  theta: {initial: 0.1}
links:
  cart:
    joint: {type: prismatic, parent: ground, axis: x, coordinate: s}
  rod:
    joint: {type: revolute, parent: cart, axis: z, coordinate: theta}
    mass: m
    center_of_mass: [0, -L/2, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
"""


def test_a_mems_pendulum_on_a_shaken_pivot_is_not_autonomous(tmp_path, monkeypatch):
    """A 100 um rod on a pivot shaken as A sin(w t), A = 20 um, w = 300 rad/s: the pivot's acceleration A w^2 =
    1.8 m/s^2 (18 % of g) enters f as m L/2 A w^2 sin(w t) cos(theta), which d/dt does not leave at 0 (closed form).
    d/dt of f is 1e-10 in SI units, and against max(1, |f|) it was taken for 0: 'autonomous', and `equilibria`
    reported theta = 0 'asymptotically stable' for a forced motion. At lab scale it was refused, as now here."""
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    path = tmp_path / "mems_drive.yaml"
    path.write_text(MEMS_DRIVEN)
    model = mechsys.load(path)
    assert not model.is_autonomous()
    from typer.testing import CliRunner

    from mechsys.cli import app

    result = CliRunner().invoke(app, ["equilibria", str(path)])
    assert result.exit_code == 1 and "non-autonomous" in result.output


def test_a_prescribed_coordinate_used_only_in_a_force_is_no_joint_freedom(tmp_path, monkeypatch):
    """A pendulum pushed by a generalized force u = A sin(w t), u written as a prescribed coordinate: no joint uses
    u, so the DOF formula subtracts nothing (MO = 1, DOF 1, as with the torque written in t) and the kinematics hold
    no time (scleronomic). It gave 'DOF by formula 0', rheonomic, and a note blaming dependent constraints."""
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    path = tmp_path / "pushed.yaml"
    path.write_text("""\
name: pushed
parameters: {m: 1, l: 1, g: 9.81, A: 0.2, w: 3}
coordinates:
  theta: {initial: 0.1}
  u: {prescribed: A*sin(w*t)}
links:
  rod:
    joint: {type: revolute, parent: ground, axis: z, coordinate: theta}
    mass: m
    center_of_mass: [0, -l, 0]
forces:
  - {type: gravity, acceleration: [0, -g, 0]}
  - {type: generalized_force, coordinate: theta, value: u}
""")
    info = system_info(mechsys.load(path))
    assert (info.mobility, info.prescribed, info.dof_formula, info.dof, info.rheonomic) == (1, [], 1, 1, False)
    assert not info.notes
    driven = mechsys.load(ROOT / "systems" / "gyrostabilizer.yaml")  # a joint uses its prescribed spin: L counts it
    assert system_info(driven).prescribed and system_info(driven).rheonomic


def test_the_cyclic_decision_does_not_depend_on_the_units_scale(monkeypatch):
    """A spatial RSSR linkage (a user's model) in metres and scaled to 1e-10 m: the same facts. Scaled, the shift
    test compared differences of 1e-13 against an absolute 1e-9 and called the rocker angle q4 cyclic, although
    shifting it opens the loop. Only the coupler's idle spin s3 is cyclic at both scales (proven symbolically)."""
    monkeypatch.setenv("MECHSYS_CACHE", "off")
    path = ROOT / "tests" / "data" / "beyond" / "rssr_linkage.yaml"
    lengths = {"a": 0.1, "b": 0.5, "c": 0.3, "d": 0.45, "e": 0.15}
    metres = mechsys.load(path)
    tiny = mechsys.load(path, {k: str(v * 1e-9) for k, v in lengths.items()})
    for model in (metres, tiny):
        decision = model.cyclic_decision
        assert (decision.names, decision.basis) == (["s3"], {"s3": "symbolic"})
        info = system_info(model)
        assert (info.constraint_rank, info.dof, info.massless_coordinates) == (3, 2, ["s3", "q4"])
