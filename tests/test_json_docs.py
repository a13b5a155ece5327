"""docs/json.md documents every JSON output (issue 15): each table of keys there is compared with what the command
prints on bundled models, so an undocumented new key, a documented key that no longer appears, a missing `always`
key or a value of another type fails."""
from __future__ import annotations

import enum
import json
import re
import typing
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "json.md"
SYSTEMS = ROOT / "systems"
DATA = ROOT / "tests" / "data"
MARKER = re.compile(r"^<!--\s*json-keys:\s*([\w-]+)\s*-->\s*$")
BASES = {"string", "number", "integer", "boolean", "null", "object"}
STDOUT = "stdout"

# section of docs/json.md -> the runs that produce it: (arguments, where the JSON is: stdout or a file in the scratch
# folder); "{tmp}/" is the scratch folder. Together a section's runs must print every documented key.
RUNS: dict[str, list[tuple[tuple[str, ...], str]]] = {
    "derive": [(("derive", f"{SYSTEMS}/centrifuge.yaml", "-f", "json"), STDOUT),
               (("derive", f"{SYSTEMS}/slider_crank.yaml", "--check", "-f", "json"), STDOUT),
               (("derive", f"{SYSTEMS}/four_bar.yaml", "--subexpressions", "named", "-f", "json"), STDOUT)],
    "info": [(("info", f"{SYSTEMS}/centrifuge.yaml", "-f", "json"), STDOUT),
             (("info", f"{SYSTEMS}/slider_crank.yaml", "-f", "json"), STDOUT)],
    "equilibria": [(("equilibria", f"{SYSTEMS}/centrifuge.yaml", "-f", "json"), STDOUT),
                   (("equilibria", f"{SYSTEMS}/centrifuge.yaml", "--exhaustive", "-f", "json"), STDOUT),
                   (("equilibria", f"{SYSTEMS}/centrifuge.yaml", "--set", "dM=7.142857142857143", "--sweep",
                     "Mo=30:40:3", "-f", "json"), STDOUT),
                   (("equilibria", f"{SYSTEMS}/double_pendulum.yaml", "--verify", "-f", "json"), STDOUT),
                   (("equilibria", f"{SYSTEMS}/rolling_disk.yaml", "-f", "json"), STDOUT)],
    "modes": [(("modes", f"{SYSTEMS}/cart_pendulum.yaml", "--frf", "0:10:3", "--state-space", "--transfer", "-f",
                "json"), STDOUT),
              (("modes", f"{DATA}/hilltop_block.yaml", "-f", "json"), STDOUT),
              (("modes", f"{SYSTEMS}/motor_arm.yaml", "-f", "json"), STDOUT)],
    "simulate": [(("simulate", f"{SYSTEMS}/double_pendulum.yaml", "--t-end", "1", "-f", "json", "-o", "{tmp}/dp.json"),
                  STDOUT)],
    "simulate-result": [(("simulate", f"{SYSTEMS}/double_pendulum.yaml", "--t-end", "1", "-f", "json", "-o",
                          "{tmp}/dp.json"), "dp.json"),
                        (("export", "{tmp}/dp.json", "-o", "{tmp}/exported.json"), "exported.json")],
    "simulate-events": [(("simulate", f"{DATA}/falling_events.yaml", "--t-end", "2", "--events", "{tmp}/events.json"),
                         "events.json")],
    "simulate-impacts": [(("simulate", f"{SYSTEMS}/bouncing_ball.yaml", "--t-end", "1", "--impacts",
                           "{tmp}/impacts.json"), "impacts.json")],
    "bench": [(("bench", f"{SYSTEMS}/double_pendulum.yaml", "--t-end", "0.5", "--methods", "native", "--rtols",
                "1e-6", "-f", "json"), STDOUT)],
    "collide": [(("collide", f"{SYSTEMS}/bullet_pendulum.yaml", "-f", "json"), STDOUT),
                (("collide", f"{SYSTEMS}/carriages.yaml", "-f", "json"), STDOUT)],  # two contacts: lists
    "collide-percussion": [(("collide", f"{SYSTEMS}/bullet_pendulum.yaml", "--percussion", "-f", "json"), STDOUT)],
    "inverse": [(("inverse", f"{DATA}/slider_crank_driven.yaml", "-f", "json"), STDOUT)],
    "check": [(("check", f"{SYSTEMS}/bullet_pendulum.yaml", "-j", "1", "-f", "json"), STDOUT)],
    "sweep": [(("sweep", f"{SYSTEMS}/double_pendulum.yaml", "-p", "m1=1:2:2", "-r", "info", "-j", "1", "-q", "-f",
                "json", "-o", "{tmp}/sweep.csv"), STDOUT)],
    "schema": [(("schema",), STDOUT)],
}

#: documented keys the runs above do not print, with the reason; each is checked by a test of its own below
NOT_RUN = {"equilibria": {"search.eliminated": "needs a nonholonomic model with holonomic rows (the bicycle: 30 s)"}}


# ------------------------------------------------------------------------------------------ the documented keys
@dataclass(frozen=True)
class Key:
    path: str  # `a.b`: key b of the object under a; `a[].b`: of each object in the array a; `[].b`: top-level array
    type: tuple  # parsed by parse_type
    always: bool


def parse_type(text: str) -> tuple:
    """`array of number or null` -> (("array", ("number",)), "null"); parentheses group: `array of (string or
    null)`. Alternatives are base names or ("array"|"map", inner alternatives)."""
    tokens = re.findall(r"\(|\)|[A-Za-z]+", text)
    alts, i = _union(tokens, 0, text)
    if i != len(tokens):
        raise ValueError(f"type {text!r}: unexpected {tokens[i]!r}")
    return alts


def _union(tokens: list[str], i: int, text: str) -> tuple[tuple, int]:
    alts: tuple = ()
    while True:
        alt, i = _alternative(tokens, i, text)
        alts += alt
        if i < len(tokens) and tokens[i] == "or":
            i += 1
            continue
        return alts, i


def _alternative(tokens: list[str], i: int, text: str) -> tuple[tuple, int]:
    tok = tokens[i] if i < len(tokens) else "(end)"
    if tok in ("array", "map") and tokens[i + 1:i + 2] == ["of"]:
        inner, i = _alternative(tokens, i + 2, text)
        return ((tok, inner),), i
    if tok == "(":
        inner, i = _union(tokens, i + 1, text)
        if tokens[i:i + 1] != [")"]:
            raise ValueError(f"type {text!r}: unclosed parenthesis")
        return inner, i + 1
    if tok in BASES:
        return (tok,), i + 1
    raise ValueError(f"type {text!r}: unknown {tok!r} (types: {', '.join(sorted(BASES))}, array of X, map of X)")


def _cells(line: str) -> list[str]:
    """The cells of a Markdown table row (`\\|` is a pipe inside a cell)."""
    inner = line.strip()[1:-1]
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", inner)]


def parse_doc(text: str) -> dict[str, dict[str, Key]]:
    """Section id -> key path -> Key, from the table after each `<!-- json-keys: ID -->` marker."""
    lines = text.splitlines()
    sections: dict[str, dict[str, Key]] = {}
    for n, line in enumerate(lines):
        m = MARKER.match(line)
        if not m:
            continue
        assert m.group(1) not in sections, f"docs/json.md:{n + 1}: section {m.group(1)!r} twice"
        rows = [ln for ln in _table_after(lines, n + 1)]
        assert rows and _cells(rows[0])[:3] == ["key", "type", "present"], f"docs/json.md:{n + 1}: no key table"
        keys: dict[str, Key] = {}
        for row in rows[2:]:
            cells = _cells(row)
            path = cells[0].strip("`")
            assert path not in keys, f"docs/json.md: {m.group(1)}: key {path!r} twice"
            keys[path] = Key(path, parse_type(cells[1]), cells[2] == "always")
        sections[m.group(1)] = keys
    return sections


def _table_after(lines: list[str], start: int) -> list[str]:
    i = start
    while i < len(lines) and not lines[i].strip():
        i += 1
    out = []
    while i < len(lines) and lines[i].startswith("|"):
        out.append(lines[i])
        i += 1
    return out


# --------------------------------------------------------------------------------------------- the checker
@dataclass
class Walk:
    """Compares one JSON document with the documented keys: `found` collects the paths seen, `problems` the keys
    that are not documented, missing `always` keys and values of another type."""

    keys: dict[str, Key]
    found: set[str] = field(default_factory=set)
    problems: list[str] = field(default_factory=list)

    def document(self, value) -> None:
        array_root = any(k.startswith("[]") for k in self.keys)
        self.value(value, (("array", ("object",)),) if array_root else ("object",), "")

    def value(self, value, alternatives: tuple, path: str) -> None:
        """The first alternative that fits without a problem wins; otherwise report the first one of the value's
        kind (its inner problems say more), or the mismatch."""
        first: Walk | None = None
        for alt in alternatives:
            sub = Walk(self.keys)
            if not sub.fits(value, alt, path):
                continue
            if not sub.problems:
                self.found |= sub.found
                return
            first = first or sub
        if first is not None:
            self.found |= first.found
            self.problems += first.problems
        else:
            self.problems.append(f"{path or '(top)'}: {json.dumps(value)[:80]} is not {alternatives}")

    def fits(self, value, alt, path: str) -> bool:
        """Whether ``value`` is of the kind ``alt``; if so its content is walked (problems recorded here)."""
        if isinstance(alt, tuple):
            kind, inner = alt
            if kind == "array" and isinstance(value, list):
                for item in value:
                    self.value(item, inner, f"{path}[]")
                return True
            if kind == "map" and isinstance(value, dict):
                for k, v in value.items():
                    self.value(v, inner, f"{path}.*")  # keys are names of the model: not documented one by one
                return True
            return False
        if alt == "object":
            if isinstance(value, dict) and not path.endswith(".*"):
                self.object(value, path)
            return isinstance(value, dict)  # a map's objects are opaque: their keys are documented elsewhere
        return {"string": isinstance(value, str), "boolean": isinstance(value, bool), "null": value is None,
                "number": isinstance(value, (int, float)) and not isinstance(value, bool),
                "integer": isinstance(value, int) and not isinstance(value, bool)}[alt]

    def object(self, obj: dict, path: str) -> None:
        prefix = f"{path}." if path else ""
        for name, item in obj.items():
            child = prefix + name
            if child not in self.keys:
                self.problems.append(f"{child}: printed but not documented")
                continue
            self.found.add(child)
            self.value(item, self.keys[child].type, child)
        for key in self.keys.values():
            rest = key.path[len(prefix):]
            if key.path.startswith(prefix) and "." not in rest and "[]" not in rest and key.always \
                    and rest not in obj:
                self.problems.append(f"{key.path}: documented as always present, missing")


# ----------------------------------------------------------------------------------------------- running
@pytest.fixture(scope="module")
def documented() -> dict[str, dict[str, Key]]:
    return parse_doc(DOC.read_text())


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """Runs each command once (in this process) and returns the JSON of (arguments, source)."""
    folder = tmp_path_factory.mktemp("json_docs")
    done: dict[tuple[str, ...], str] = {}

    def get(args: tuple[str, ...], source: str):
        if args not in done:
            argv = [a.replace("{tmp}", str(folder)) for a in args]
            result = CliRunner().invoke(app, argv)
            assert result.exit_code == 0, f"mechsys {' '.join(args)}: exit {result.exit_code}\n{result.output}"
            done[args] = result.stdout
        return json.loads(done[args] if source == STDOUT else (folder / source).read_text())

    return get


def test_every_documented_output_is_run_and_every_run_is_documented(documented):
    assert set(documented) == set(RUNS)
    for section, keys in NOT_RUN.items():
        for path in keys:
            assert path in documented[section] and not documented[section][path].always


def _json_choice(hint) -> bool:
    """An option typed by an Enum (possibly Optional) with a `json` member: a --format option."""
    candidates = typing.get_args(hint) or (hint,)
    return any(isinstance(c, type) and issubclass(c, enum.Enum) and "json" in c.__members__ for c in candidates)


def test_every_command_with_a_json_format_has_a_section(documented):
    with_json = {info.name or info.callback.__name__.replace("_", "-") for info in app.registered_commands
                 if any(_json_choice(hint) for hint in typing.get_type_hints(info.callback).values())}
    assert {"derive", "info", "equilibria", "modes", "simulate", "bench", "collide", "check", "sweep"} <= with_json
    assert with_json <= set(documented), f"commands printing JSON without a section in docs/json.md: " \
                                         f"{sorted(with_json - set(documented))}"


@pytest.mark.parametrize("section", sorted(RUNS))
def test_the_printed_keys_are_the_documented_keys(section, documented, outputs):
    keys = documented[section]
    walk = Walk(keys)
    for args, source in RUNS[section]:
        sub = Walk(keys)
        sub.document(outputs(args, source))
        walk.found |= sub.found
        walk.problems += [f"mechsys {' '.join(args[:2])} ...: {p}" for p in sub.problems]
    assert not walk.problems, "\n".join(dict.fromkeys(walk.problems))
    never = set(keys) - walk.found - set(NOT_RUN.get(section, {}))
    assert not never, f"documented in docs/json.md ({section}) but never printed: {sorted(never)}"


def test_the_search_report_prints_eliminated_as_documented(documented):
    """The one documented key no run above prints (NOT_RUN): the search report with eliminated coordinates."""
    from mechsys.analysis.equilibrium.equilibria import SearchReport

    report = SearchReport(26, {"lean": (-3.14, 3.14), "pitch": (-3.14, 3.14)}, [], [], [], eliminated=["pitch"])
    walk = Walk(documented["equilibria"])
    walk.value(report.to_dict(), documented["equilibria"]["search"].type, "search")
    assert not walk.problems and "search.eliminated" in walk.found


def test_the_checker_reports_undocumented_missing_and_mistyped_keys():
    keys = parse_doc("<!-- json-keys: x -->\n| key | type | present | meaning |\n|---|---|---|---|\n"
                     "| `a` | integer | always | |\n| `b` | array of object | always | |\n"
                     "| `b[].c` | string or null | always | |\n| `d` | map of array of number | with --d | |\n")["x"]
    assert keys["b[].c"].type == ("string", "null") and keys["d"].type == (("map", (("array", ("number",)),)),)
    good = Walk(keys)
    good.document({"a": 1, "b": [{"c": None}], "d": {"x": [1.5, 2]}})
    assert not good.problems and good.found == {"a", "b", "b[].c", "d"}
    bad = Walk(keys)
    bad.document({"a": 1.5, "b": [{"c": 3, "e": 1}, {}], "f": 0, "d": {"x": [True]}})
    assert sorted(bad.problems) == sorted([
        "a: 1.5 is not ('integer',)", "b[].c: 3 is not ('string', 'null')", "b[].e: printed but not documented",
        "b[].c: documented as always present, missing", "f: printed but not documented",
        "d.*[]: true is not ('number',)"])
    with pytest.raises(ValueError, match="unknown 'list'"):
        parse_type("list of number")


def test_json_md_is_in_the_site_navigation():
    nav = (ROOT / "mkdocs.yml").read_text().split("\nnav:", 1)[1]
    assert re.search(r"^\s+- [^:\n]+: json\.md\s*$", nav, re.M)
