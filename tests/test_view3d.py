"""3-D views (`simulate --animate run.html`, `mechsys view`): the drawn positions read back from the HTML and
checked against closed forms, the options' errors, and real renderings in headless Chromium."""
from __future__ import annotations

import base64
import csv
import fcntl
import importlib.util
import io
import json
import os
import re
import select
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
SYSTEMS = ROOT / "systems"
runner = CliRunner()
needs_plotly = pytest.mark.skipif(importlib.util.find_spec("plotly") is None,
                                  reason="the 3-D views need plotly (pip install 'mechsys[view]')")


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


# ----------------------------------------------------------------------------------------- reading a page back
def _json_args(text: str, call: str, count: int) -> list | None:
    """The first ``count`` JSON arguments after the div id of ``call`` (e.g. Plotly.newPlot) in the page's script."""
    m = re.search(re.escape(call) + r"""\(\s*["']mechsys-view["']\s*,\s*""", text)
    if m is None:
        return None
    decoder, pos, args = json.JSONDecoder(), m.end(), []
    for _ in range(count):
        value, pos = decoder.raw_decode(text, pos)
        args.append(value)
        pos = re.compile(r"\s*,?\s*").match(text, pos).end()
    return args


def read_page(path: Path) -> tuple[list[dict], list[dict]]:
    """(traces, frames) of a page written by mechsys: the arguments of Plotly.newPlot and Plotly.addFrames."""
    text = path.read_text(encoding="utf-8")
    plot = _json_args(text, "Plotly.newPlot", 1)
    frames = _json_args(text, "Plotly.addFrames", 1)
    assert plot is not None, "no Plotly.newPlot call for the view's div"
    return plot[0], frames[0] if frames else []


def read_layout(path: Path) -> dict:
    return _json_args(path.read_text(encoding="utf-8"), "Plotly.newPlot", 2)[1]


def numbers(value) -> np.ndarray:
    """A plotly array: a JSON list (None for a gap) or a typed array {dtype, bdata} (plotly >= 6)."""
    if isinstance(value, dict):
        return np.frombuffer(base64.b64decode(value["bdata"]), dtype=np.dtype(value["dtype"])).astype(float)
    return np.array([np.nan if v is None else v for v in value], dtype=float)


def xyz(trace: dict) -> np.ndarray:
    return np.column_stack([numbers(trace[a]) for a in "xyz"])


def frame_trace(data: list[dict], frame: dict, name: str) -> dict:
    """The trace named ``name`` as frame ``frame`` sets it."""
    index = next(i for i, tr in enumerate(data) if tr.get("name") == name)
    return frame["data"][frame["traces"].index(index)]


def labelled_points(data: list[dict], frame: dict | None) -> dict[str, np.ndarray]:
    """Label -> drawn position of the 'points' trace (frame 0's data when ``frame`` is None)."""
    base = next(tr for tr in data if tr.get("name") == "points")
    rows = xyz(base if frame is None else frame_trace(data, frame, "points"))
    return dict(zip(base["text"], rows))


def read_csv(path: Path) -> dict[str, np.ndarray]:
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    return {name: np.array([float(r[i]) for r in rows[1:]]) for i, name in enumerate(rows[0])}


def evenly_spread(n: int, frames: int) -> np.ndarray:
    return np.unique(np.round(np.linspace(0, n - 1, frames)).astype(int))


# ----------------------------------------------------------------------------------------- positions
@pytest.fixture(scope="module")
def double_pendulum_run(tmp_path_factory):
    """1 s at dt = 0.002: 501 output rows, drawn as 200 frames."""
    folder = tmp_path_factory.mktemp("dp")
    page, result = folder / "dp.html", folder / "dp.csv"
    r = invoke("simulate", SYSTEMS / "double_pendulum.yaml", "--t-end", 1, "--dt", 0.002, "-o", result,
               "--animate", page, "--fps", 25)
    assert r.exit_code == 0, r.output + r.stderr
    return page, read_csv(result)


@needs_plotly
def test_double_pendulum_frames_are_the_closed_form_tips(double_pendulum_run):
    page, res = double_pendulum_run
    data, frames = read_page(page)
    rows = evenly_spread(len(res["t"]), 200)
    assert len(frames) == 200 and rows[0] == 0 and rows[-1] == len(res["t"]) - 1
    assert [f["name"] for f in frames] == [str(k) for k in range(200)]
    l1, l2 = 0.6, 0.5
    for k, row in enumerate(rows):
        th1, th12 = res["theta1"][row], res["theta1"][row] + res["theta2"][row]
        tip1 = np.array([l1 * np.sin(th1), -l1 * np.cos(th1), 0.0])
        tip2 = tip1 + np.array([l2 * np.sin(th12), -l2 * np.cos(th12), 0.0])
        drawn = labelled_points(data, frames[k])
        assert np.max(np.abs(drawn["rod1.joint(rod2)"] - tip1)) < 1e-9
        assert np.max(np.abs(drawn["rod2.rod_end1"] - tip2)) < 1e-9
        rod2 = xyz(frame_trace(data, frames[k], "rod2 (rod)"))  # the cap centres are the rod's two ends
        ends = rod2[-2:]
        assert min(np.max(np.abs(ends - [tip2, tip1])), np.max(np.abs(ends - [tip1, tip2]))) < 1e-9


@needs_plotly
def test_double_pendulum_controls_follow_the_rows_and_fps(double_pendulum_run):
    page, res = double_pendulum_run
    layout = read_layout(page)
    steps = layout["sliders"][0]["steps"]
    times = res["t"][evenly_spread(len(res["t"]), 200)]
    assert [float(s["label"]) for s in steps] == pytest.approx(times, abs=1e-5)
    assert [s["args"][0] for s in steps] == [[str(k)] for k in range(200)]
    play, pause = layout["updatemenus"][0]["buttons"]
    assert play["label"] == "Play" and play["args"][1]["frame"]["duration"] == pytest.approx(40)  # --fps 25
    assert pause["label"] == "Pause"


@needs_plotly
def test_page_is_self_contained(double_pendulum_run):
    page, _ = double_pendulum_run
    text = page.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>") and "plotly.js" in text[:20000]
    assert re.search(r"<script[^>]*\bsrc=", text) is None and re.search(r"<link[^>]*\bhref=", text) is None
    assert len(text) > 3_000_000  # plotly.js inlined


@pytest.fixture(scope="module")
def rolling_disk_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("disk")
    page, result = folder / "disk.html", folder / "disk.csv"
    r = invoke("simulate", SYSTEMS / "rolling_disk.yaml", "--t-end", 3, "--dt", 0.03, "-o", result, "--animate", page)
    assert r.exit_code == 0, r.output + r.stderr
    return page, read_csv(result)


@needs_plotly
@pytest.mark.parametrize("k", [0, 17, 50, 100])
def test_rolling_disk_is_drawn_at_the_models_centre_and_tilt(rolling_disk_run, k):
    page, res = rolling_disk_run
    data, frames = read_page(page)
    assert len(frames) == len(res["t"]) == 101
    x, y, yaw, lean = (res[n][k] for n in ("x", "y", "yaw", "lean"))
    r = 0.3
    centre = np.array([x + r * np.sin(yaw) * np.sin(lean), y - r * np.cos(yaw) * np.sin(lean), r * np.cos(lean)])
    axis = np.array([-np.sin(yaw) * np.cos(lean), np.cos(yaw) * np.cos(lean), np.sin(lean)])  # lean frame's y
    mesh = xyz(frame_trace(data, frames[k], "disk (disk)"))
    caps = mesh[-2:]  # the centres of the two faces
    assert np.max(np.abs(caps.mean(axis=0) - centre)) < 1e-9
    assert np.max(np.abs(np.cross(caps[1] - caps[0], axis))) < 1e-9 and np.linalg.norm(caps[1] - caps[0]) > 0
    rim = mesh[:-2] - centre
    radial = rim - np.outer(rim @ axis, axis)
    assert np.allclose(np.linalg.norm(radial, axis=1), r, atol=1e-9)
    assert np.allclose(np.abs(rim @ axis), 0.015, atol=1e-9)  # half of the drawn thickness r/10


@needs_plotly
def test_rolling_disk_centre_point_is_drawn_too(rolling_disk_run):
    page, res = rolling_disk_run
    data, frames = read_page(page)
    k = 80
    drawn = labelled_points(data, frames[k])["disk.origin"]
    x, y, yaw, lean = (res[n][k] for n in ("x", "y", "yaw", "lean"))
    expected = [x + 0.3 * np.sin(yaw) * np.sin(lean), y - 0.3 * np.cos(yaw) * np.sin(lean), 0.3 * np.cos(lean)]
    assert np.max(np.abs(drawn - expected)) < 1e-9


# ----------------------------------------------------------------------------------------- mechsys view
@needs_plotly
def test_view_writes_the_initial_configuration(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = invoke("view", SYSTEMS / "double_pendulum.yaml", "--set", "theta1=1.1")
    assert r.exit_code == 0, r.output + r.stderr
    assert r.stdout == "wrote double_pendulum.html\n"
    data, frames = read_page(tmp_path / "double_pendulum.html")
    assert frames == []
    drawn = labelled_points(data, None)
    tip1 = np.array([0.6 * np.sin(1.1), -0.6 * np.cos(1.1), 0.0])
    tip2 = tip1 + 0.5 * np.array([np.sin(1.4), -np.cos(1.4), 0.0])
    assert np.max(np.abs(drawn["rod2.rod_end1"] - tip2)) < 1e-12
    assert [p.name for p in tmp_path.iterdir()] == ["double_pendulum.html"]  # no temporary file left


@needs_plotly
def test_view_assembles_a_closed_loop_like_simulate(tmp_path):
    """A poor guess of the coupler angle: the drawn loop is closed, and the view is the run's first frame."""
    view, run = tmp_path / "view.html", tmp_path / "run.html"
    r = invoke("view", SYSTEMS / "four_bar.yaml", "--set", "theta3=0.2", "-o", view)
    assert r.exit_code == 0, r.output + r.stderr
    r = invoke("simulate", SYSTEMS / "four_bar.yaml", "--set", "theta3=0.2", "--t-end", 0.1, "--dt", 0.05,
               "--animate", run)
    assert r.exit_code == 0, r.output + r.stderr
    drawn = labelled_points(read_page(view)[0], None)
    assert np.max(np.abs(drawn["coupler.B"] - drawn["rocker.B"])) < 1e-9
    data, frames = read_page(run)
    first = labelled_points(data, frames[0])
    assert drawn.keys() == first.keys()
    assert max(np.max(np.abs(drawn[k] - first[k])) for k in drawn) < 1e-12


@needs_plotly
def test_non_planar_model_gets_an_html_view(tmp_path):
    page = tmp_path / "gyro.html"
    r = invoke("simulate", SYSTEMS / "gyrostabilizer.yaml", "--t-end", 0.2, "--dt", 0.05, "--animate", page)
    assert r.exit_code == 0, r.output + r.stderr
    data, frames = read_page(page)
    assert len(frames) == 5
    assert any(tr.get("name") == "joint frames" for tr in data) and any(tr.get("name") == "ground" for tr in data)


# ----------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("args, message", [
    (["simulate", "--animate", "out.png"], "write the animation as a .gif file (planar mechanisms) or as an .html"),
    (["simulate", "--animate", "a.html", "--fps", "0"], "--fps 0.0: must be a positive number"),
    (["simulate", "--animate", "no/such/dir/a.html"], "directory no/such/dir does not exist"),
    (["view", "-o", "view.png"], "--output view.png: write the 3-D view as an .html file"),
    (["view", "-o", "no/such/dir/v.html"], "directory no/such/dir does not exist"),
])
@needs_plotly
def test_bad_options_are_one_line_before_any_work(tmp_path, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("mechsys.analysis.motion.simulate.simulate", lambda *a, **k: pytest.fail("simulated"))
    monkeypatch.setattr("mechsys.load", lambda *a, **k: pytest.fail("loaded"))
    r = invoke(args[0], SYSTEMS / "double_pendulum.yaml", *args[1:])
    assert r.exit_code == 2, r.output + r.stderr
    assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args", [["simulate", "--animate", "run.html"], ["view"]])
def test_missing_plotly_is_one_clear_line(tmp_path, monkeypatch, args):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("mechsys.report.view3d.plotly_available", lambda: False)
    monkeypatch.setattr("mechsys.load", lambda *a, **k: pytest.fail("loaded"))
    r = invoke(args[0], SYSTEMS / "double_pendulum.yaml", *args[1:])
    assert r.exit_code == 2
    assert "the 3-D view needs plotly, which is not installed (pip install 'mechsys[view]')" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_gif_of_a_non_planar_model_points_to_the_html_view(tmp_path):
    r = invoke("simulate", SYSTEMS / "gyrostabilizer.yaml", "--t-end", 0.1, "--dt", 0.05,
               "--animate", tmp_path / "g.gif")
    assert r.exit_code == 2 and "write an .html file for a 3-D view" in r.stderr


# ----------------------------------------------------------------------------------------- a real browser
CHROMIUM = shutil.which("chromium")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not on PATH (apt-get install chromium)")
BROWSER_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--hide-scrollbars",
                 "--host-resolver-rules=MAP * ~NOTFOUND"]  # offline: any network request would fail
WIDTH, HEIGHT = 900, 700


class Browser:
    """Headless Chromium driven over the DevTools protocol on a pipe (--remote-debugging-pipe: commands on the
    child's fd 3, answers on its fd 4): one process for the module, one tab per page."""

    def __init__(self, profile: Path):
        to_child, self._to_child = os.pipe()
        self._from_child, from_child = os.pipe()
        high = [fcntl.fcntl(fd, fcntl.F_DUPFD, 10) for fd in (to_child, from_child)]  # clear of 3 and 4

        def fds() -> None:
            os.dup2(high[0], 3)
            os.dup2(high[1], 4)

        self.proc = subprocess.Popen([CHROMIUM, *BROWSER_FLAGS, f"--user-data-dir={profile}",
                                      "--remote-debugging-pipe", "about:blank"], pass_fds=(3, 4),
                                     preexec_fn=fds, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for fd in (to_child, from_child, *high):
            os.close(fd)
        self._next, self._buffer = 0, b""

    def send(self, method: str, params: dict | None = None, session: str | None = None,
             timeout: float = 60.0) -> dict:
        self._next += 1
        message = {"id": self._next, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self._to_child, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            while b"\0" not in self._buffer:
                ready, _, _ = select.select([self._from_child], [], [], max(0.0, deadline - time.monotonic()))
                chunk = os.read(self._from_child, 1 << 20) if ready else b""
                assert chunk, f"no answer from chromium to {method}"
                self._buffer += chunk
            raw, self._buffer = self._buffer.split(b"\0", 1)
            answer = json.loads(raw)
            if answer.get("id") == self._next:
                assert "error" not in answer, answer["error"]
                return answer["result"]

    def tab(self, url: str, frame: str) -> "Tab":
        """A new tab of WIDTH x HEIGHT pixels at ``url``, once the page shows ``frame``."""
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        tab = Tab(self, self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"])
        tab.send("Emulation.setDeviceMetricsOverride",
                 {"width": WIDTH, "height": HEIGHT, "deviceScaleFactor": 1, "mobile": False})
        tab.open(url, frame)
        return tab

    def close(self) -> None:
        try:
            self.send("Browser.close", timeout=10)
        except AssertionError:
            pass
        finally:
            os.close(self._to_child)
            os.close(self._from_child)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


class Tab:
    def __init__(self, browser: Browser, session: str):
        self.browser, self.session = browser, session

    def send(self, method: str, params: dict | None = None) -> dict:
        return self.browser.send(method, params, self.session)

    def evaluate(self, expression: str):
        return self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True})["result"].get("value")

    def frame(self) -> str | None:
        """The frame the page says it shows: its view div's data-frame attribute (None before it is drawn)."""
        return self.evaluate("(document.getElementById('mechsys-view') || {getAttribute: () => null})"
                             ".getAttribute('data-frame')")

    def wait(self, frame: str, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while self.frame() != frame:
            assert time.monotonic() < deadline, f"data-frame is {self.frame()!r}, not {frame!r}"
            time.sleep(0.1)

    def open(self, url: str, frame: str) -> None:
        """Go to ``url`` (a new #frame=N of the same page: no reload) and wait until the page shows ``frame``;
        the tab comes to the front first: tabs behind draw nothing."""
        self.send("Page.bringToFront")
        self.send("Page.navigate", {"url": url})
        self.wait(frame)

    def screenshot(self) -> np.ndarray:
        from PIL import Image

        png = base64.b64decode(self.send("Page.captureScreenshot", {"format": "png"})["data"])
        with Image.open(io.BytesIO(png)) as im:
            return np.asarray(im.convert("RGB")).astype(int)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    if CHROMIUM is None:
        pytest.skip("chromium is not on PATH (apt-get install chromium)")
    b = Browser(tmp_path_factory.mktemp("chromium") / "profile")
    yield b
    b.close()


@pytest.fixture(scope="module")
def double_pendulum_tab(browser, double_pendulum_run):
    return browser.tab(f"{double_pendulum_run[0].as_uri()}#frame=0", "0")


def scene_area(img: np.ndarray) -> np.ndarray:
    """The 3-D scene: below the title, left of the legend, above the play controls."""
    return img[40:HEIGHT - 110, :WIDTH - 140]


def tinted(img: np.ndarray, color: str, tol: float = 30.0) -> int:
    """Pixels of ``color`` under some shading: a multiple 0.4 ... 1.2 of it, within ``tol`` per channel."""
    rgb = np.array([int(color[i:i + 2], 16) for i in (1, 3, 5)], dtype=float)
    scale = (img @ rgb) / (rgb @ rgb)
    fits = np.max(np.abs(img - scale[..., None] * rgb), axis=2) <= tol
    return int(np.sum(fits & (scale >= 0.4) & (scale <= 1.2)))


def check_two_frames(tab: Tab, page: Path, later: int, color: str) -> None:
    """Frame 0, then frame N by a change of the hash (the page follows it): both drawn, and not alike."""
    tab.open(f"{page.as_uri()}#frame=0", "0")
    first = scene_area(tab.screenshot())
    tab.open(f"{page.as_uri()}#frame={later}", str(later))
    second = scene_area(tab.screenshot())
    for img in (first, second):
        assert len(np.unique(img.reshape(-1, 3), axis=0)) > 200  # not blank: shading, lines, grid, labels
        assert tinted(img, color) > 300  # WebGL drew the link in its colour (shaded)
    changed = np.sum(np.any(first != second, axis=2))
    assert changed > 500, f"frames 0 and {later} look alike ({changed} pixels differ)"


@needs_plotly
@needs_chromium
@pytest.mark.slow
def test_double_pendulum_renders_in_headless_chromium(double_pendulum_tab, double_pendulum_run):
    check_two_frames(double_pendulum_tab, double_pendulum_run[0], 150, "#ff7f0e")  # rod2's orange


@needs_plotly
@needs_chromium
@pytest.mark.slow
def test_play_button_and_hash_beyond_the_end(double_pendulum_tab, double_pendulum_run):
    tab, page = double_pendulum_tab, double_pendulum_run[0]
    tab.open(f"{page.as_uri()}#frame=100000", "199")  # beyond the end: the last frame
    tab.open(f"{page.as_uri()}#frame=20", "20")
    tab.evaluate("document.querySelector('.updatemenu-button').dispatchEvent(new MouseEvent('click'))")
    deadline = time.monotonic() + 30
    while int(tab.frame()) < 25:  # playing on from the current frame
        assert time.monotonic() < deadline, f"Play did not advance the frames (at {tab.frame()})"
        time.sleep(0.1)


@needs_plotly
@needs_chromium
@pytest.mark.slow
def test_rolling_disk_renders_in_headless_chromium(browser, rolling_disk_run):
    page = rolling_disk_run[0]
    check_two_frames(browser.tab(f"{page.as_uri()}#frame=0", "0"), page, 90, "#2ca02c")  # the disk's green
