"""The examples of the documentation are tests (issue 16).

Every shell example in README.md, docs/*.md, docs/tutorial/*.md and docs/howto/*.md that runs `mechsys` is run
from a scratch folder that sees the repository's `systems/`, `tests/` and `docs/` (output files land in the
scratch folder), its exit code is compared, and the output it shows is compared with what the tool prints; every
```yaml block is validated (model files by the loader, fragments against the JSON Schema); every python block
marked `<!-- run -->` is executed with its page. The conventions are documented for writers in
docs/howto/docs-examples.md.

Commands run through `mechsys.cli.main` in this process (argv, working folder, COLUMNS and the streams set as for
the console script), which saves loading sympy and the model for each of the ~100 examples;
MECHSYS_DOCS_SUBPROCESS=1 runs each as a subprocess of the installed `mechsys` instead.
Development: `python tests/test_docs_examples.py [PATH-PART...]` runs the examples of the matching pages and
prints one line per example.
"""
from __future__ import annotations

import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md"), *(ROOT / "docs" / "tutorial").glob("*.md"),
                *(ROOT / "docs" / "howto").glob("*.md")])
SHELL = {"", "sh", "bash", "console", "shell"}
OUTPUT_OPTIONS = {"-o", "--output", "--plot", "--animate", "--events", "--impacts", "--junit", "--markdown"}
MARKER = re.compile(r"^\s*<!--\s*(illustrative|slow-example|fragment|run)\b(.*?)-->\s*$")
FENCE = re.compile(r"^(\s*)```(\w*)\s*$")
REMARK = re.compile(r"\s{2,}\(([a-z][^()]*)\)\s*$")
TIME_LIMIT = 20.0  # seconds: a slower example should be marked <!-- slow-example --> (reported, never a failure:
#                   tests check correctness, not wall time)


# ------------------------------------------------------------------------------------------------ extraction
@dataclass
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    lang: str
    lines: list[str]
    marker: str = ""  # illustrative | slow-example | fragment | run | ""
    after: list[str] = field(default_factory=list)  # Markdown right after the fence (pasted output)

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


@dataclass
class Command:
    block: Block
    text: str  # the command as written (without the remark)
    shown: list[str]  # shown output lines
    exit: int = 0
    python: bool = False  # a <!-- run --> python block, run in the page's folder between its commands

    @property
    def where(self) -> str:
        return self.block.where


def blocks(page: Path) -> list[Block]:
    lines = page.read_text().splitlines()
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, lang = len(m.group(1)), m.group(2).lower()
        j = i + 1
        while j < len(lines) and not re.match(r"^\s*```\s*$", lines[j]):
            j += 1
        body = [ln[indent:] if ln[:indent].strip() == "" else ln.lstrip() for ln in lines[i + 1:j]]
        k = i - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        mm = MARKER.match(lines[k]) if k >= 0 else None
        block = Block(page, i + 1, lang, body, mm.group(1) if mm else "")
        block.after = _pasted_output(lines, j + 1)
        out.append(block)
        i = j + 1
    return out


def _pasted_output(lines: list[str], start: int) -> list[str]:
    """Markdown tables, bullet notes and bold titles right after a fence (separated by blank lines)."""
    out, i = [], start
    while i < len(lines):
        if not lines[i].strip():
            i += 1
            continue
        if not re.match(r"^(\||- |\*\*|#{3} )", lines[i]):
            break
        while i < len(lines) and lines[i].strip():
            out.append(lines[i])
            i += 1
    return out


def commands(block: Block) -> list[Command]:
    if block.lang == "python" and block.marker == "run":
        return [Command(block, "python", [], python=True)]
    if block.lang not in SHELL:
        return []
    console = any(ln.startswith("$ ") for ln in block.lines)
    out: list[Command] = []
    i = 0
    lines = block.lines
    while i < len(lines):
        ln = lines[i]
        if console and ln.startswith("$ "):
            text, i = _joined(lines, i, ln[2:])
            shown = []
            while i < len(lines) and not lines[i].startswith("$ "):
                shown.append(lines[i])
                i += 1
            if text.strip() == "echo $?" and out:
                out[-1].exit = int(shown[0].strip())
                continue
            out.append(Command(block, text, shown))
        elif not console and block.lang in ("sh", "bash", "shell") and ln.startswith("mechsys "):
            text, i = _joined(lines, i, ln)
            out.append(Command(block, text, []))
        else:
            i += 1
    return [c for c in out if c.text.split()[:1] == ["mechsys"]]  # (`$ cd ...`, `dask ...`: not run)


def _joined(lines: list[str], i: int, first: str) -> tuple[str, int]:
    text = first
    i += 1
    while text.rstrip().endswith("\\") and i < len(lines):
        text = text.rstrip()[:-1] + " " + lines[i].strip()
        i += 1
    text = REMARK.sub("", text)
    text = re.sub(r"\s+#\s.*$", "", text)
    return text.strip(), i


def all_blocks() -> list[Block]:
    return [b for page in PAGES for b in blocks(page)]


def all_commands() -> list[Command]:
    return [c for b in all_blocks() for c in commands(b)]


# ------------------------------------------------------------------------------------------------- running
def mechsys_executable() -> str:
    exe = Path(sys.executable).with_name("mechsys")
    return str(exe) if exe.exists() else (shutil.which("mechsys") or str(ROOT / ".venv" / "bin" / "mechsys"))


def scratch(folder: Path) -> Path:
    """A working folder that sees the repository's inputs; outputs land in it."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("systems", "tests", "docs"):
        link = folder / name
        if not link.exists():
            link.symlink_to(ROOT / name)
    return folder


def argv(command: Command) -> tuple[list[str], str | None]:
    """The argument list with output files redirected into the scratch folder, and the `> FILE` target."""
    args = shlex.split(command.text)
    redirect = None
    if ">" in args:
        k = args.index(">")
        redirect, args = Path(args[k + 1]).name, args[:k]
    out = []
    for k, a in enumerate(args):
        if k and args[k - 1] in OUTPUT_OPTIONS:
            a = Path(a).name
        elif "=" in a and a.split("=", 1)[0] in OUTPUT_OPTIONS:
            a = a.split("=", 1)[0] + "=" + Path(a.split("=", 1)[1]).name
        out.append(a)
    return [mechsys_executable(), *out[1:]], redirect


def run_in_process(command: Command, folder: Path) -> tuple[int, str, float]:
    """The command through `mechsys.cli.main` in this process (argv, cwd, COLUMNS and the streams set as for a
    subprocess): the same code path as the console script, without loading sympy and the model anew each time."""
    import contextlib
    import io

    from mechsys.cli import main

    args, redirect = argv(command)
    out, err = io.StringIO(), io.StringIO()
    saved = sys.argv, os.getcwd(), {k: os.environ.get(k) for k in ("COLUMNS", "LINES", "NO_COLOR", "TERM")}
    sys.argv = ["mechsys", *args[1:]]
    os.environ.update(COLUMNS="160", LINES="50", NO_COLOR="1", TERM="dumb")
    os.chdir(folder)
    t0 = time.perf_counter()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                main()
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        seconds = time.perf_counter() - t0
        sys.argv = saved[0]
        os.chdir(saved[1])
        for k, v in saved[2].items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        import matplotlib.pyplot as plt

        plt.close("all")
    if redirect:
        (folder / redirect).write_text(out.getvalue())
        return code, err.getvalue(), seconds
    return code, out.getvalue() + err.getvalue(), seconds


def run(command: Command, folder: Path) -> tuple[int, str, float]:
    if os.environ.get("MECHSYS_DOCS_SUBPROCESS") != "1":
        return run_in_process(command, folder)
    args, redirect = argv(command)
    env = dict(os.environ, COLUMNS="160", LINES="50", NO_COLOR="1", TERM="dumb", PYTHONHASHSEED="0")
    t0 = time.perf_counter()
    res = subprocess.run(args, cwd=folder, env=env, capture_output=True, text=True, timeout=600)
    seconds = time.perf_counter() - t0
    if redirect:
        (folder / redirect).write_text(res.stdout)
        return res.returncode, res.stderr, seconds
    return res.returncode, res.stdout + res.stderr, seconds


# ----------------------------------------------------------------------------------------------- comparison
SEPARATORS = re.compile(r"[\s\u2500-\u257f{}\[\],:;\"|*#`]+")
NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?i?$")


def tokens(text: str) -> list[str]:
    return [t for t in SEPARATORS.split(text) if t]


def same(shown: str, printed: str) -> bool:
    if shown == printed:
        return True
    if NUMBER.match(shown) and NUMBER.match(printed) and shown.endswith("i") == printed.endswith("i"):
        a, b = float(shown.rstrip("i")), float(printed.rstrip("i"))
        if abs(a) < 1e-12 and abs(b) < 1e-12:
            return True
        return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-12)
    return False


def find(part: list[str], stream: list[str], start: int) -> int:
    """Index just after the first contiguous occurrence of `part` in `stream` at or after `start`, or -1."""
    n = len(part)
    for k in range(start, len(stream) - n + 1):
        if all(same(a, b) for a, b in zip(part, stream[k:k + n])):
            return k + n
    return -1


def mismatch(shown: list[str], printed: str) -> str:
    """'' when every shown line occurs in the printed output in order, else the first line that does not."""
    stream = tokens(printed)
    pos = 0
    for line in shown:
        if line.strip() in ("", "..."):
            continue
        for part in line.split("..."):
            want = tokens(part)
            if not want:
                continue
            nxt = find(want, stream, pos)
            if nxt < 0:
                return line
            pos = nxt
    return ""


def expected_output(command: Command) -> list[str]:
    if command.shown and any(ln.strip() for ln in command.shown):
        return command.shown
    if re.search(r"(-f|--format)[ =]markdown", command.text) and command.block.commands_in_block == 1:
        return command.block.after
    return []


def run_python(command: Command, folder: Path) -> float:
    script = folder / f"example_{command.block.line}.py"
    script.write_text("\n".join(command.block.lines) + "\n")
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, script.name], cwd=folder, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, f"{command.where}: the python block failed:\n{res.stdout[-2000:]}\n{res.stderr[-3000:]}"
    return time.perf_counter() - t0


def check_command(command: Command, folder: Path) -> float:
    if command.python:
        return run_python(command, folder)
    code, printed, seconds = run(command, folder)
    assert code == command.exit, (f"{command.where}: `{command.text}` exited {code}, the docs show "
                                  f"{command.exit}\n{printed[-3000:]}")
    shown = expected_output(command)
    bad = mismatch(shown, printed)
    assert not bad, (f"{command.where}: `{command.text}`: the docs show\n    {bad}\nwhich the tool does not print. "
                     f"It printed:\n{printed[:6000]}")
    return seconds


# --------------------------------------------------------------------------------------------- YAML blocks
def schema() -> dict:
    from mechsys.model.schema import json_schema

    return json_schema()


def _resolve(node: dict, root: dict) -> dict:
    while "$ref" in node:
        ref = node["$ref"].split("/")[-1]
        node = root["$defs"][ref]
    return node


def _alternatives(node: dict, root: dict, data=None) -> list[dict]:
    node = _resolve(node, root)
    mapping = node.get("discriminator", {}).get("mapping", {})
    if isinstance(data, dict) and data.get("type") in mapping:  # a tagged element: its own schema only
        return [_resolve({"$ref": mapping[data["type"]]}, root)]
    for key in ("anyOf", "oneOf", "allOf"):
        if key in node:
            return [a for alt in node[key] for a in _alternatives(alt, root)]
    return [node]


def unknown_keys(data, node: dict, root: dict, path: str = "") -> list[str]:
    """Key paths of `data` that the JSON schema `node` does not allow (empty: every key exists)."""
    alts = _alternatives(node, root, data)
    if isinstance(data, dict):
        best = None
        for alt in alts:
            if alt.get("type") not in (None, "object") or not ({"properties", "additionalProperties",
                                                                 "patternProperties"} & set(alt)):
                continue
            bad = []
            for key, value in data.items():
                key = str(key)
                pattern = [v for k, v in alt.get("patternProperties", {}).items() if re.match(k, key)]
                if key in alt.get("properties", {}):
                    bad += unknown_keys(value, alt["properties"][key], root, f"{path}.{key}")
                elif pattern:
                    bad += unknown_keys(value, pattern[0], root, f"{path}.{key}")
                elif isinstance(alt.get("additionalProperties"), dict):
                    bad += unknown_keys(value, alt["additionalProperties"], root, f"{path}.{key}")
                elif alt.get("additionalProperties", True) is False:
                    bad.append(f"{path}.{key}")
            if best is None or len(bad) < len(best):
                best = bad
        return best if best is not None else [path or "(top)"]
    if isinstance(data, list):
        for alt in alts:
            if alt.get("type") == "array" and "items" in alt:
                return [p for i, v in enumerate(data) for p in unknown_keys(v, alt["items"], root, f"{path}[{i}]")]
        return [] if any("type" not in alt or alt["type"] == "array" for alt in alts) else [path]
    return []


def fragment_problems(data) -> list[str]:
    """A fragment fits the schema when it fits at the top level or as the content of some definition."""
    root = schema()
    candidates = ([root] + [root["$defs"][k] for k in root.get("$defs", {})]
                  + list(root.get("properties", {}).values()))  # e.g. `arm: {joint: ...}`, the content of links
    best = None
    for node in candidates:
        bad = unknown_keys(data, node, root)
        if best is None or len(bad) < len(best):
            best = bad
        if not bad:
            return []
    return best or []


def yaml_blocks() -> list[Block]:
    return [b for b in all_blocks() if b.lang in ("yaml", "yml")]


def python_blocks() -> list[Block]:
    return [b for b in all_blocks() if b.lang == "python" and b.marker == "run"]


# -------------------------------------------------------------------------------------------------- tests
def _ids(items) -> list[str]:
    return [f"{c.where}:{c.text[:60]}" for c in items]


def _examples(slow: bool) -> list[Command]:
    cmds = all_commands()
    for c in cmds:
        c.block.commands_in_block = sum(1 for d in cmds if d.block is c.block)
    return [c for c in cmds if c.block.marker != "illustrative" and (c.block.marker == "slow-example") == slow]


def _pages(cmds: list[Command]) -> dict[Path, list[Command]]:
    pages: dict[Path, list[Command]] = {}
    for c in cmds:
        pages.setdefault(c.block.page, []).append(c)
    return pages


def _run_pages(cmds: list[Command], tmp_path: Path, limit: float | None) -> None:
    """One scratch folder per page, commands in page order (a later one may read an earlier one's file)."""
    failures, timings, slow = [], [], []
    for page, items in _pages(cmds).items():
        folder = scratch(tmp_path / page.stem)
        for c in items:
            try:
                seconds = check_command(c, folder)
            except AssertionError as exc:
                failures.append(str(exc))
                continue
            timings.append((seconds, c))
            if limit is not None and seconds > limit:
                slow.append(f"{c.where}: `{c.text}` took {seconds:.1f} s: mark the block <!-- slow-example -->")
    print(f"\n{len(timings)} examples ran in {sum(s for s, _ in timings):.1f} s")
    print("\n".join(slow))
    for s, c in sorted(timings, key=lambda x: -x[0])[:5]:
        print(f"  {s:6.1f} s  {c.where}  {c.text[:80]}")
    assert not failures, f"{len(failures)} of {len(cmds)} examples differ from the docs:\n\n" + "\n\n".join(failures)


def _fast_pages() -> list[Path]:
    return sorted(_pages(_examples(slow=False)))


def test_the_docs_have_examples():
    assert len(_examples(slow=False)) > 90, "the extraction of the examples lost them"


@pytest.mark.slow
@pytest.mark.parametrize("page", _fast_pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_shell_examples_of_the_docs_are_what_the_tool_prints(page, tmp_path):
    _run_pages([c for c in _examples(slow=False) if c.block.page == page], tmp_path, TIME_LIMIT)


@pytest.mark.slow
def test_the_slow_shell_examples_of_the_docs_are_what_the_tool_prints(tmp_path):
    _run_pages(_examples(slow=True), tmp_path, None)


def is_model_file(data) -> bool:
    """A block with `name` and `links` at the top level is a whole model file; anything else is a fragment."""
    return isinstance(data, dict) and "name" in data and "links" in data


def yaml_problem(block: Block, folder: Path) -> str:
    """'' when the block is a valid model file (or a fragment whose keys the language has), else why not."""
    import mechsys

    text = "\n".join(block.lines) + "\n"
    from mechsys.model.yamlpos import load_yaml  # the language's own reader: keys stay text (`on:` is a key)

    try:
        data, _ = load_yaml(text, block.where)
    except Exception as exc:  # noqa: BLE001
        return f"not YAML: {exc}"
    if block.marker == "fragment" or not is_model_file(data):
        if not isinstance(data, (dict, list)):
            return "a fragment is a mapping or a list"
        bad = fragment_problems(data)
        return f"keys that the language does not have: {bad}" if bad else ""
    path = folder / "model.yaml"
    path.write_text(text)
    try:
        mechsys.load(path).equations("kane")
    except Exception as exc:  # noqa: BLE001 - the message is the point
        return f"not a valid model file ({exc}); mark a part of a file <!-- fragment -->"
    return ""


@pytest.mark.parametrize("block", yaml_blocks(), ids=[b.where for b in yaml_blocks()])
def test_every_yaml_block_of_the_docs_is_valid(block, tmp_path):
    if block.marker == "illustrative":
        pytest.skip("illustrative")
    problem = yaml_problem(block, tmp_path)
    assert not problem, f"{block.where}: {problem}"


@pytest.mark.slow
def test_the_docs_site_builds_without_warnings(tmp_path):
    """`make docs` builds the MkDocs site with --strict (and link and anchor validation): a warning fails."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    res = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, timeout=600,
                         env=dict(os.environ, NO_MKDOCS_2_WARNING="1"))
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert (tmp_path / "site" / "tutorial" / "index.html").exists()
    assert "additionalProperties" in (tmp_path / "site" / "schema" / "index.html").read_text()


def test_the_example_conventions_catch_a_stale_message():
    """The comparison is strict where it matters (a changed message or figure fails) and lenient on layout."""
    printed = ("┃ # ┃ reason ┃\n│ 1 │ energy argument: strict minimum of the effective potential and no energy input "
               "(Lagrange-Dirichlet): stable; asymptotic stability is not decided by this test │\n")
    assert mismatch(["| 1 | energy argument: strict minimum of the effective potential and no energy input "
                     "(Lagrange-Dirichlet): stable; asymptotic stability is not decided by this test |"], printed) == ""
    assert mismatch(["| 1 | ... (Lagrange-Dirichlet), so stable but not asymptotically |"], printed) != ""
    json_out = json.dumps({"bifurcations": [{"kind": "fold", "value": 36.627474809558734}]}, indent=2)
    assert mismatch(['  {"kind": "fold", "value": 36.6274748}'], json_out) == ""
    assert mismatch(['  {"kind": "fold", "value": 36.7}'], json_out) != ""
    assert mismatch(["1.614541e-20; 2.775558e-17 - 5.710586i"], "3.2e-19; -1.1e-17 - 5.7105861i") == ""


def test_the_extraction_finds_commands_exit_codes_and_remarks(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text\n\n```\n$ mechsys check x.yaml  (trimmed)\n| a | b |\n$ echo $?\n1\n```\n\n"
                    "<!-- illustrative: a sketch -->\n```sh\nmechsys derive a.yaml --set 'der(b)=1' \\\n"
                    "    -o out.json   # a comment\nmechsys info a.yaml\n```\n\n```\nmechsys equilibria FILE [--x]\n```\n")
    found = [c for b in blocks(page) for c in commands(b)]
    assert [(c.text, c.exit, c.block.marker) for c in found] == [
        ("mechsys check x.yaml", 1, ""), ("mechsys derive a.yaml --set 'der(b)=1'  -o out.json", 0, "illustrative"),
        ("mechsys info a.yaml", 0, "illustrative")]
    assert found[0].shown == ["| a | b |"]
    args, _ = argv(found[1])
    assert args[-2:] == ["-o", "out.json"]


if __name__ == "__main__":  # development: list the examples, or run one page's: python tests/test_docs_examples.py PAGE
    cmds = _examples(False) + _examples(True)
    wanted = sys.argv[1:]
    for page, items in _pages(cmds).items():
        if wanted and not any(w in str(page) for w in wanted):
            continue
        folder = scratch(Path("/tmp/docs-examples") / page.stem)
        for c in items:
            try:
                s = check_command(c, folder)
                print(f"ok   {s:6.1f} s {c.where} {c.text}", flush=True)
            except AssertionError as exc:
                print(f"FAIL {c.where} {c.text}\n{str(exc)[:1500]}", flush=True)
