"""The figures of the docs gallery (docs/index.md, README.md), made from the bundled models by the commands the
tutorial shows: `make docs` runs this before building the site. Usage: python docs/hooks/gallery.py [MECHSYS]"""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FIGURES = ROOT / "docs" / "figures"
MECHSYS = str(Path(sys.argv[1]).resolve()) if len(sys.argv) > 1 else str(Path(sys.executable).with_name("mechsys"))
COMMANDS = {  # figure -> the tutorial's command(s) that draw it (in a scratch folder)
    "tutorial_centrifuge_fold.png": [
        "equilibria systems/centrifuge.yaml --set dM=7.142857142857143 --sweep Mo=10:70:61 --plot fig.png -f csv"],
    "tutorial_chain_frf.png": [
        "modes systems/spring_chain.yaml --at x1=0 --at x2=0 --at x3=0 --frf 0:100:2001 --input x1 --response x3 "
        "-f csv --plot fig.png"],
    "tutorial_slider_crank.png": ["simulate docs/examples/slider_crank_driven.yaml --t-end 2 --plot fig.png"],
    "tutorial_indicator_map.png": ["sweep systems/indicator.yaml --param omega1=-30:30:61 --run equilibria -q -o map.csv",
                                   "plot map.csv -o fig.png"],
    "tutorial_centrifuge_basin.png": [
        "sweep systems/centrifuge.yaml --param beta=-3:3:25 --param der(beta)=-6:6:13 --run simulate "
        "--option t_end=200 -q -o basin.csv"],
    "work_precision_double_pendulum.png": [
        "bench systems/double_pendulum.yaml --t-end 5 --plot fig.png"],
}
#: the 3-D still: a frame of `simulate --animate` rendered by headless Chromium (skipped without it)
STILL = ("rolling_disk_3d.png", "simulate systems/rolling_disk.yaml --t-end 2.5 --dt 0.025 --set lean=0.3 "
                                "--set der(x)=1 --set der(yaw)=-2.475978465683165 --animate fig.html", 40)
# (a steady turn: the yaw rate is a root of the steady-turning condition at lean 0.3, tests/test_outputs.py)


def run_block(page: Path, folder: Path) -> None:
    """Run the page's `<!-- run -->` python block (it writes basin.png) in the folder."""
    code = re.search(r"<!-- run -->\n```python\n(.*?)```", page.read_text(), re.S).group(1)
    (folder / "block.py").write_text(code)
    subprocess.run([sys.executable, "block.py"], cwd=folder, check=True, capture_output=True)


def main() -> None:
    for name, commands in COMMANDS.items():
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            for sub in ("systems", "docs"):
                (folder / sub).symlink_to(ROOT / sub)
            for command in commands:
                subprocess.run([MECHSYS, *command.split()], cwd=folder, check=True, capture_output=True)
            if name == "tutorial_centrifuge_basin.png":
                run_block(ROOT / "docs" / "tutorial" / "02-centrifuge.md", folder)
                shutil.copy(folder / "basin.png", FIGURES / name)
            else:
                shutil.copy(folder / "fig.png", FIGURES / name)
        print(f"docs/figures/{name}")
    still()


def still() -> None:
    """The 3-D still of the gallery, with the DevTools driver of tests/test_view3d.py (one browser tab)."""
    name, command, frame = STILL
    if shutil.which("chromium") is None:
        print(f"docs/figures/{name}: skipped (no chromium on PATH)")
        return
    sys.path.insert(0, str(ROOT / "tests"))
    from PIL import Image
    from test_view3d import Browser

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "systems").symlink_to(ROOT / "systems")
        subprocess.run([MECHSYS, *command.split()], cwd=folder, check=True, capture_output=True)
        browser = Browser(folder / "profile")
        try:
            tab = browser.tab(f"{(folder / 'fig.html').as_uri()}#frame={frame}", str(frame))
            Image.fromarray(tab.screenshot().astype("uint8")).save(FIGURES / name)
        finally:
            browser.close()
    print(f"docs/figures/{name}")


if __name__ == "__main__":
    main()
