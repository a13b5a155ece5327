"""`mechsys simulate --animate`: GIFs of planar mechanisms, drawn positions checked against the models' geometry."""
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

import mechsys
from mechsys.analysis.motion.simulate import simulate
from mechsys.cli import app
from mechsys.errors import InputError
from mechsys.report.animation import (animation_frames, default_fps, geometry, gif_delay_ms, link_polyline,
                                      plane_basis, plane_of_motion, sample_indices)

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def run_model(path: Path, t_end: float = 0.6, dt: float = 0.02, **overrides):
    model = mechsys.load(path, overrides or None, release_prescribed=True)
    return model, simulate(model, t_end, dt)


@pytest.mark.parametrize("name", ["double_pendulum", "slider_crank", "four_bar"])
def test_gif_written_for_planar_systems(tmp_path, name):
    gif = tmp_path / f"{name}.gif"
    r = invoke("simulate", ROOT / "systems" / f"{name}.yaml", "--t-end", 0.5, "--dt", 0.05, "--animate", gif)
    assert r.exit_code == 0, r.output + r.stderr
    with Image.open(gif) as im:
        assert im.format == "GIF" and im.n_frames == 11  # one frame per output row (0, 0.05, ..., 0.5)
        assert im.size == (400, 400)
        im.seek(0)
        first = np.asarray(im.convert("RGB")).copy()
        im.seek(im.n_frames - 1)
        last = np.asarray(im.convert("RGB"))
    assert not np.array_equal(first, last)  # the mechanism moved
    assert [p.name for p in tmp_path.iterdir()] == [gif.name]  # no temporary file left behind


@pytest.mark.parametrize("fps, delay", [(["--fps", 10], 100), (["--fps", 1000 / 30], 30), ([], 50)])
def test_fps_sets_the_frame_delay(tmp_path, fps, delay):
    gif = tmp_path / "dp.gif"
    r = invoke("simulate", ROOT / "systems" / "double_pendulum.yaml", "--t-end", 0.2, "--dt", 0.05,
               "--animate", gif, *fps)
    assert r.exit_code == 0, r.stderr
    with Image.open(gif) as im:  # default: real time, one 0.05 s output interval per frame
        assert im.n_frames == 5 and im.info["duration"] == delay


def test_gif_delays():
    assert [gif_delay_ms(f) for f in (10, 1000 / 30, 40, 60, 1000, 0.1)] == [100, 30, 20, 20, 20, 5000]
    assert default_fps(np.linspace(0, 5, 201)) == pytest.approx(40) and default_fps(np.zeros(1)) == 10


@pytest.mark.parametrize("path, sets", [(ROOT / "systems" / "gyrostabilizer.yaml", []),
                                        (ROOT / "tests" / "data" / "torque_free_body.yaml",
                                         ["--set", "der(theta)=0.5"])])
def test_non_planar_system_is_a_clean_input_error(tmp_path, path, sets):
    gif, csv = tmp_path / "x.gif", tmp_path / "x.csv"
    r = invoke("simulate", path, "--t-end", 0.3, "--dt", 0.05, *sets, "--animate", gif, "-o", csv)
    assert r.exit_code == 2
    assert "--animate supports planar systems" in r.stderr and path.name in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []  # neither the GIF nor the result file


@pytest.mark.parametrize("args, message", [(["--animate", "out.png"], "write the animation as a .gif"),
                                           (["--animate", "no/such/dir/a.gif"], "does not exist"),
                                           (["--animate", "a.gif", "--fps", "0"], "--fps")])
def test_bad_animate_options_rejected_before_simulating(tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("mechsys.analysis.motion.simulate.simulate", lambda *a, **k: pytest.fail("simulated"))
    r = invoke("simulate", ROOT / "systems" / "double_pendulum.yaml", *args)
    assert r.exit_code == 2 and message in r.stderr and "Traceback" not in r.stderr


def test_double_pendulum_drawn_points_follow_the_model_convention():
    """theta1 from the downward vertical, theta2 relative to rod 1, y up (the YAML's header)."""
    model, result = run_model(ROOT / "systems" / "double_pendulum.yaml")
    frames = animation_frames(model, result)
    p = model.parameters
    l1, l2 = p["l1"], p["l2"]
    th1, th2 = result.q[:, 0], result.q[:, 1]
    labels = frames.geometry.labels
    elbow = frames.xy[:, labels.index("rod2.origin")]
    assert np.allclose(elbow, np.column_stack([l1 * np.sin(th1), -l1 * np.cos(th1)]), atol=1e-12)
    tip = frames.xy[:, labels.index("rod2.rod_end1")]  # the far end of rod 2 (centre of mass - l2/2 along y)
    expected_tip = elbow + np.column_stack([l2 * np.sin(th1 + th2), -l2 * np.cos(th1 + th2)])
    assert np.allclose(tip, expected_tip, atol=1e-12)
    assert np.allclose(frames.xy[:, labels.index("rod1.com")], elbow / 2, atol=1e-12)
    assert np.allclose(frames.xy[:, labels.index("ground.joint(rod1)")], 0.0)
    assert frames.axis_labels == ("x [m]", "y [m]")
    rod1 = next(link for link in frames.geometry.links if link.name == "rod1")
    k = 17
    drawn = link_polyline(frames.xy[k], rod1)
    assert np.allclose(drawn[0], [0.0, 0.0])  # the hinge at O
    assert any(np.allclose(row, [l1 * np.sin(th1[k]), -l1 * np.cos(th1[k])]) for row in drawn)


def test_closed_loops_are_drawn_closed():
    model, result = run_model(ROOT / "systems" / "four_bar.yaml")
    frames = animation_frames(model, result)
    labels = frames.geometry.labels
    assert np.allclose(frames.xy[:, labels.index("coupler.B")], frames.xy[:, labels.index("rocker.B")], atol=1e-9)
    assert np.allclose(frames.xy[:, labels.index("rocker.origin")], [model.parameters["l1"], 0.0])
    model, result = run_model(ROOT / "systems" / "slider_crank.yaml")
    frames = animation_frames(model, result)
    labels = frames.geometry.labels
    assert np.allclose(frames.xy[:, labels.index("crank.A")], frames.xy[:, labels.index("rod.A")], atol=1e-9)
    slider = frames.xy[:, labels.index("slider.origin")]
    assert np.allclose(slider, np.column_stack([result.q[:, 2], np.zeros(len(result.t))]), atol=1e-12)


def test_geometry_names_each_point_once():
    model = mechsys.load(ROOT / "systems" / "four_bar.yaml")
    geo = geometry(model)
    # the coupler's joint on the crank is the crank's far end (l2, 0, 0): drawn once, under the first name
    assert "crank.joint(coupler)" in geo.labels and "crank.rod_end2" not in geo.labels
    assert [g for g in geo.ground if geo.labels[g].startswith("ground.")] == geo.ground and len(geo.ground) == 2


def test_plane_detection():
    t = np.linspace(0, 2, 30)
    # a pendulum turning about ground y: points move in the z-x plane
    xyz = np.stack([np.column_stack([np.sin(t), 0 * t + 0.3, -np.cos(t)]), np.zeros((30, 3))], axis=1)
    omega = np.zeros((30, 1, 3))
    omega[:, 0, 1] = 1.0
    n = plane_of_motion(xyz, omega)
    assert n is not None and np.allclose(np.abs(n), [0, 1, 0])
    basis, labels = plane_basis(n)
    assert labels == ("z [m]", "x [m]") and np.allclose(np.cross(basis[0], basis[1]), n)
    # the same points with a tilted rotation axis: not planar
    tilted = omega.copy()
    tilted[15:, 0] = [0.0, 0.8, 0.6]
    assert plane_of_motion(xyz, tilted) is None
    # no rotation, translation along x only: drawn in x-y
    slide = np.stack([np.column_stack([t, 0 * t, 0 * t])], axis=1)
    assert np.allclose(plane_of_motion(slide, np.zeros((30, 1, 3))), [0, 0, 1])
    # no rotation, a point moving in 3-D: not planar
    helix = np.stack([np.column_stack([np.cos(t), np.sin(t), t])], axis=1)
    assert plane_of_motion(helix, np.zeros((30, 1, 3))) is None


def test_sampling_keeps_at_most_200_frames_with_both_ends():
    rows = sample_indices(1001)
    assert len(rows) <= 200 and rows[0] == 0 and rows[-1] == 1000 and np.all(np.diff(rows) > 0)
    assert np.array_equal(sample_indices(7), np.arange(7))


def test_animation_frames_rejects_non_planar_directly():
    model, result = run_model(ROOT / "systems" / "gyrostabilizer.yaml", t_end=0.2, dt=0.05)
    with pytest.raises(InputError, match="moves in three dimensions"):
        animation_frames(model, result)
