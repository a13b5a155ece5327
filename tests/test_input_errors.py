"""The input-error contract: any invalid model makes `mechsys derive|info FILE` exit 2 with ONE stderr line
``FILE:LINE:COL: key.path: message`` (did-you-mean hints for misspellings), no traceback, nothing on stdout.

Each case mutates a small valid model (the centrifuge of systems/centrifuge.yaml plus a spring and named
points) and states where the error must be reported. Positions are given as anchors (a text that occurs once
in the mutated file, its line is the expected LINE; an optional second text on that line gives COL) so the
table stays readable. The bulk runs in-process through typer's CliRunner; a few real subprocess runs prove the
end-to-end no-traceback guarantee.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Union

import pytest
from typer.testing import CliRunner

from mechsys.cli import app

ROOT = Path(__file__).resolve().parents[1]

BASE = """\
name: centrifuge_test
description: Column driven by a DC motor carrying a hinged arm, with a spring
parameters:
  I1: 2.5
  m: 8
  I2x: 2.0
  I2y: 2.0
  I2z: 0.2
  a: 0.3
  l: 0.5
  g: 9.81
  k: 100
  Mo: 50
  dM: Mo/7
coordinates:
  alpha:
    initial: 0
    rate: 0
  beta:
    initial: 0
    rate: -2.5
ground:
  points:
    anchor: [0, 0, -1]
    other: [1, 0, 0]
links:
  column:
    joint:
      type: revolute
      parent: ground
      axis: z
      coordinate: alpha
    inertia:
      zz: I1
  arm:
    joint:
      type: revolute
      parent: column
      axis: x
      coordinate: beta
      origin: [0, a, 0]
    mass: m
    center_of_mass: [0, 0, -l]
    inertia:
      xx: I2x
      yy: I2y
      zz: I2z
    points:
      tip: [0, 0, -2*l]
forces:
  - type: gravity
    acceleration: [0, 0, -g]
  - type: torque
    on: column
    axis: z
    value: Mo - dM*der(alpha)
  - type: spring
    between: [arm.tip, ground.anchor]
    stiffness: k
"""

ARM_JOINT = """\
    joint:
      type: revolute
      parent: column
      axis: x
      coordinate: beta
      origin: [0, a, 0]
"""
MARKER_NAME = "pwned_marker"
LINE_RE = re.compile(r"^(?P<file>.+?):(?P<line>\d+):(?P<col>\d+): (?P<rest>.*)$")


# ----------------------------------------------------------------------------------------- mutations
Mutation = Callable[[str], str]


def sub(old: str, new: str) -> Mutation:
    """Replace the single occurrence of ``old`` in the base text by ``new``."""

    def apply(text: str) -> str:
        assert text.count(old) == 1, f"test bug: {old!r} occurs {text.count(old)} times"
        return text.replace(old, new)

    return apply


def subs(*pairs: tuple[str, str]) -> Mutation:
    def apply(text: str) -> str:
        for old, new in pairs:
            text = sub(old, new)(text)
        return text

    return apply


def append(extra: str) -> Mutation:
    return lambda text: text + extra


def whole(new_text: str) -> Mutation:
    return lambda _text: new_text


@dataclass(frozen=True)
class Nth:
    """The n-th (1-based) line containing ``text``, for texts that occur more than once."""

    text: str
    n: int


Anchor = Union[str, int, Nth]


@dataclass
class Case:
    id: str
    mutate: Mutation
    line: Union[Anchor, tuple[Anchor, ...]]  # anchor text (its line) or a line number; a tuple: any of them
    col: Optional[Anchor]  # text on the expected line whose start is COL, a column number, or None (unchecked)
    path: Optional[str]  # expected key path; None: the message follows LINE:COL directly (no key applies)
    fragment: Union[str, tuple[str, ...]]  # must occur in the message (case-insensitive); a tuple: any of them

    def text(self, marker: Path) -> str:
        return self.mutate(BASE).replace("MARKER", str(marker))


def _line_of(text: str, anchor: Anchor) -> int:
    if isinstance(anchor, int):
        return anchor
    if isinstance(anchor, Nth):
        hits = [i for i, line in enumerate(text.splitlines(), 1) if anchor.text in line]
        return hits[anchor.n - 1]
    hits = [i for i, line in enumerate(text.splitlines(), 1) if anchor in line]
    assert len(hits) == 1, f"test bug: anchor {anchor!r} is on lines {hits}"
    return hits[0]


def expected_position(case: Case, text: str) -> tuple[set[int], Optional[int]]:
    anchors = case.line if isinstance(case.line, tuple) else (case.line,)
    lines = {_line_of(text, a) for a in anchors}
    col = None
    if isinstance(case.col, int):
        col = case.col
    elif isinstance(case.col, str):
        assert len(lines) == 1 and not isinstance(anchors[0], int), "test bug: a text COL needs one line anchor"
        line_text = text.splitlines()[min(lines) - 1]
        assert line_text.count(case.col) >= 1, f"test bug: {case.col!r} not on line {line_text!r}"
        col = line_text.index(case.col) + 1
    return lines, col


SECURITY = "__import__('os').system('touch MARKER')"
DEEP = "(" * 300 + "1" + ")" * 300
LAUGHS = "name: bomb\nlinks: {}\nx0: &a0 [v, v, v, v, v, v, v, v, v, v]\n" + "".join(
    f"x{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]\n" for i in range(1, 9))

CASES: list[Case] = [
    # ------------------------------------------------------------------ YAML syntax and document shape
    Case("yaml-bad-indentation-mapping-value", sub("description: Column", "  description: Column"),
         "description: Column", None, None, "YAML syntax error"),
    Case("yaml-bad-indentation-dedent", sub("    mass: m\n", "     mass: m\n"),
         "     mass: m", None, None, "YAML syntax error"),
    Case("yaml-unclosed-bracket", sub("center_of_mass: [0, 0, -l]", "center_of_mass: [0, 0, -l"),
         ("center_of_mass: [0, 0, -l", Nth("    inertia:", 2), "xx: I2x"), None, None,
         "YAML syntax error"),
    Case("yaml-unclosed-brace", sub("  - type: gravity\n    acceleration: [0, 0, -g]",
                                    "  - {type: gravity, acceleration: [0, 0, -g]"),
         ("{type: gravity", "type: torque"), None, None, "YAML syntax error"),
    Case("yaml-tab-indent", sub("    mass: m\n", "\tmass: m\n"), "\tmass: m", None, None, "YAML syntax error"),
    Case("yaml-unclosed-quote", sub("value: Mo - dM*der(alpha)", "value: \"Mo - dM*der(alpha)"),
         'value: "Mo', None, None, "YAML syntax error"),
    Case("empty-file", whole(""), 1, 1, None, "empty"),
    Case("only-comments", whole("# nothing here\n\n"), 1, 1, None, "empty"),
    Case("top-level-list", whole("- name: x\n- links: {}\n"), 1, 1, None, "must be a mapping"),
    Case("top-level-scalar", whole("just some text\n"), 1, 1, None, "must be a mapping"),
    Case("duplicate-parameter", sub("  m: 8\n", "  m: 8\n  m: 9\n"), "m: 9", "m: 9", "parameters.m",
         "duplicate key 'm'"),
    Case("duplicate-top-level-key", sub("description: Column", "name: again\ndescription: Column"),
         "name: again", 1, "name", "duplicate key 'name'"),
    Case("yaml-python-tag-scalar", sub("    mass: m\n", "    mass: !!python/object/apply:os.system 'touch MARKER'\n"),
         "!!python", None, None, "YAML"),
    Case("yaml-python-tag-sequence", sub("    mass: m\n", "    mass: !!python/object/apply:os.system ['touch MARKER']\n"),
         "!!python", None, "links.arm.mass", "expression"),
    Case("yaml-python-name-tag", sub("    mass: m\n", "    mass: !!python/name:os.system\n"),
         "!!python", None, None, "YAML"),
    Case("yaml-billion-laughs", whole(LAUGHS), None, None, None, "too large"),
    Case("yaml-non-scalar-key", sub("  m: 8\n", "  [m, n]: 8\n"), "[m, n]: 8", "[m, n]", "parameters",
         "plain names"),
    Case("yaml-date-value", sub("description: Column driven by a DC motor carrying a hinged arm, with a spring",
                                "description: 2020-01-01"), "description: 2020", "2020", "description",
         "unsupported YAML value"),
    # ------------------------------------------------------------------ unknown keys (did you mean)
    Case("unknown-top-level-paramters", sub("parameters:", "paramters:"), "paramters:", 1, "paramters",
         "did you mean 'parameters'"),
    Case("unknown-spring-key-stifness", sub("stiffness: k", "stifness: k"), "stifness: k", "stifness",
         "forces[2].stifness", "did you mean 'stiffness'"),
    Case("unknown-link-key-masss", sub("    mass: m\n", "    masss: m\n"), "masss: m", "masss", "links.arm.masss",
         "did you mean 'mass'"),
    Case("unknown-joint-key-axs", sub("      axis: x\n", "      axs: x\n"), "axs: x", "axs",
         "links.arm.joint.axs", "did you mean 'axis'"),
    Case("unknown-coordinate-key-inital", sub("    rate: -2.5", "    inital: 1\n    rate: -2.5"), "inital: 1",
         "inital", "coordinates.beta.inital", "did you mean 'initial'"),
    Case("unknown-key-with-carriage-return", sub("    mass: m\n", "    \"ma\\rss\": m\n"), "ma\\rss", None, None,
         "unknown key"),
    Case("unknown-key-with-line-separator", sub("    mass: m\n", "    \"ma\\Lss\": m\n"), "ma\\Lss", None, None,
         "unknown key"),
    Case("unknown-inertia-key-xxx", sub("      xx: I2x", "      xxx: I2x"), "xxx: I2x", "xxx",
         "links.arm.inertia.xxx", "unknown key 'xxx'"),
    # ------------------------------------------------------------------ wrong types
    Case("mass-as-list", sub("    mass: m\n", "    mass: [1, 2]\n"), "mass: [1, 2]", "[1, 2]", "links.arm.mass",
         "number or an expression"),
    Case("mass-null", sub("    mass: m\n", "    mass:\n"), "    mass:", None, "links.arm.mass",
         "number or an expression"),
    Case("mass-boolean", sub("    mass: m\n", "    mass: true\n"), "mass: true", "true", "links.arm.mass",
         "boolean"),
    Case("links-as-list", lambda t: t[:t.index("links:")] + "links:\n  - column\n  - arm\n" + t[t.index("forces:"):],
         "  - column", None, "links", "expected a mapping"),
    Case("coordinate-initial-as-mapping", sub("    initial: 0\n    rate: -2.5", "    initial: {x: 1}\n    rate: -2.5"),
         "initial: {x: 1}", "{x: 1}", "coordinates.beta.initial", "number or an expression"),
    Case("name-as-list", sub("name: centrifuge_test", "name: [a, b]"), "name: [a, b]", "[a, b]", "name",
         ("string", "text")),
    Case("yaml-binary-value", sub("description: Column driven by a DC motor carrying a hinged arm, with a spring",
                                  "description: !!binary aGVsbG8="), "!!binary", None, "description",
         "unsupported YAML value"),
    Case("particle-not-boolean", sub("    mass: m\n", "    mass: m\n    particle: maybe\n"), "particle: maybe",
         "maybe", "links.arm.particle", "true or false"),
    Case("joint-as-string", sub(ARM_JOINT, "    joint: revolute\n"),
         "joint: revolute", "revolute", "links.arm.joint", "expected a mapping"),
    Case("bad-link-name", sub("  arm:\n", "  my-arm:\n"), "my-arm:", "my-arm", "links.my-arm", ("name", "pattern")),
    Case("bad-parameter-name", sub("  k: 100\n", "  2k: 100\n"), "2k: 100", "2k", "parameters.2k", ("name", "pattern")),
    # ------------------------------------------------------------------ unknown discriminator values
    Case("unknown-joint-type-revolut", sub("      type: revolute\n      parent: column",
                                           "      type: revolut   # misspelt\n      parent: column"),
         "revolut   #", "revolut", "links.arm.joint.type", "did you mean 'revolute'"),
    Case("unknown-force-type-gravty", sub("type: gravity", "type: gravty"), "type: gravty", "gravty",
         "forces[0].type", "did you mean 'gravity'"),
    Case("force-without-type", sub("  - type: gravity\n    acceleration", "  - acceleration"),
         "  - acceleration", None, "forces[0]", "'gravity'"),  # the message lists the allowed types
    Case("unknown-axis-name", sub("      axis: x\n", "      axis: w\n"), "axis: w", "w", "links.arm.joint.axis",
         "expected"),
    # ------------------------------------------------------------------ missing required keys
    Case("missing-joint-parent", sub("      parent: column\n", ""),
         (Nth("    joint:", 2), Nth("type: revolute", 2)), None, "links.arm.joint.parent",
         "missing required key 'parent'"),
    Case("missing-joint-coordinate", sub("      coordinate: beta\n", ""),
         (Nth("    joint:", 2), Nth("type: revolute", 2)), None,
         "links.arm.joint.coordinate", "missing required key 'coordinate'"),
    Case("missing-name", sub("name: centrifuge_test\n", ""), 1, None, "name", "missing required key 'name'"),
    Case("missing-links", lambda t: t[:t.index("links:")] + t[t.index("forces:"):], 1, None, "links",
         "missing required key 'links'"),
    Case("missing-spring-stiffness", sub("    stiffness: k\n", ""), "type: spring", None, "forces[2].stiffness",
         "missing required key 'stiffness'"),
    # ------------------------------------------------------------------ 3-vectors
    Case("center-of-mass-2-entries", sub("center_of_mass: [0, 0, -l]", "center_of_mass: [0, -l]"),
         "center_of_mass: [0, -l]", "[0, -l]", "links.arm.center_of_mass", "3"),
    Case("center-of-mass-4-entries", sub("center_of_mass: [0, 0, -l]", "center_of_mass: [0, 0, -l, 1]"),
         "center_of_mass: [0, 0, -l, 1]", "[0, 0, -l, 1]", "links.arm.center_of_mass", "3"),
    Case("gravity-2-entries", sub("acceleration: [0, 0, -g]", "acceleration: [0, -g]"),
         "acceleration: [0, -g]", "[0, -g]", "forces[0].acceleration", "3"),
    Case("point-4-entries", sub("tip: [0, 0, -2*l]", "tip: [0, 0, -2*l, 0]"),
         "tip: [0, 0, -2*l, 0]", "[0, 0", "links.arm.points.tip", "3"),
    Case("origin-2-entries", sub("origin: [0, a, 0]", "origin: [0, a]"), "origin: [0, a]", "[0, a]",
         "links.arm.joint.origin", "3"),
    # ------------------------------------------------------------------ expressions
    Case("unknown-name-gg", sub("    mass: m\n", "    mass: m*gg\n"), "mass: m*gg", "gg", "links.arm.mass",
         "unknown name 'gg' (did you mean 'g'?)"),
    Case("unknown-name-quoted", sub("    mass: m\n", "    mass: \"m*gg\"\n"), "mass: \"m*gg\"", "gg",
         "links.arm.mass", "unknown name 'gg'"),
    Case("unknown-function-sinn", sub("value: Mo - dM*der(alpha)", "value: Mo*sinn(beta)"),
         "value: Mo*sinn(beta)", "sinn", "forces[1].value", "unknown function 'sinn' (did you mean 'sin'?)"),
    Case("syntax-trailing-operator", sub("    mass: m\n", "    mass: m*\n"), "mass: m*", None, "links.arm.mass",
         "expected a number, name or '('"),
    Case("syntax-unclosed-paren", sub("    mass: m\n", "    mass: (a+l\n"), "mass: (a+l", None, "links.arm.mass",
         "expected ')'"),
    Case("syntax-juxtaposition", sub("    mass: m\n", "    mass: a l\n"), "mass: a l", "l", "links.arm.mass",
         "unexpected 'l'"),
    Case("syntax-dangling-power", sub("    mass: m\n", "    mass: 2**\n"), "mass: 2**", None, "links.arm.mass",
         "expected a number, name or '('"),
    Case("syntax-bad-character", sub("    mass: m\n", "    mass: m % 2\n"), "mass: m % 2", "%", "links.arm.mass",
         "unexpected character '%'"),
    Case("empty-expression", sub("    mass: m\n", "    mass: ''\n"), "mass: ''", None, "links.arm.mass", "empty"),
    Case("function-without-arguments", sub("    mass: m\n", "    mass: m*sin\n"), "mass: m*sin", "sin",
         "links.arm.mass", "needs arguments"),
    Case("function-wrong-arity", sub("    mass: m\n", "    mass: atan2(m)\n"), "mass: atan2(m)", None,
         "links.arm.mass", "atan2() takes 2"),
    Case("parameter-called-as-function", sub("    mass: m\n", "    mass: m(2)\n"), "mass: m(2)", None,
         "links.arm.mass", "'m' is not a function"),
    Case("der-of-unknown-coordinate", sub("value: Mo - dM*der(alpha)", "value: Mo - dM*der(alph)"),
         "der(alph)", "alph)", "forces[1].value", "der() of unknown coordinate 'alph' (did you mean 'alpha'?)"),
    Case("der-in-parameter", sub("  dM: Mo/7\n", "  dM: Mo/7*der(alpha)\n"), "dM: Mo/7*der(alpha)", None,
         "parameters.dM", "der() is not allowed here"),
    Case("der-in-initial", sub("    initial: 0\n    rate: -2.5", "    initial: der(alpha)\n    rate: -2.5"),
         "initial: der(alpha)", None, "coordinates.beta.initial", "der() is not allowed here"),
    Case("coordinate-in-parameter", sub("  dM: Mo/7\n", "  dM: Mo/7*alpha\n"), "dM: Mo/7*alpha", "alpha",
         "parameters.dM", "unknown name 'alpha'"),
    Case("t-in-mass", sub("    mass: m\n", "    mass: m*t\n"), "mass: m*t", "t", "links.arm.mass",
         "unknown name 't'"),
    Case("coordinate-in-mass", sub("    mass: m\n", "    mass: m*beta\n"), "mass: m*beta", "beta",
         "links.arm.mass", "unknown name 'beta'"),
    Case("division-by-zero-literal", sub("    mass: m\n", "    mass: 1/0\n"), "mass: 1/0", None, "links.arm.mass",
         "division by zero"),
    Case("parameter-not-finite", sub("  k: 100\n", "  k: log(0)\n"), "k: log(0)", None, "parameters.k",
         "finite"),
    Case("parameter-complex", sub("  k: 100\n", "  k: sqrt(-1)\n"), "k: sqrt(-1)", None, "parameters.k",
         "real"),
    Case("parameter-yaml-infinity", sub("  k: 100\n", "  k: .inf\n"), "k: .inf", None, "parameters.k", "finite"),
    Case("expression-nested-too-deeply", sub("    mass: m\n", f"    mass: {DEEP}\n"), "mass: ((", None,
         "links.arm.mass", "nested too deeply"),
    Case("expression-too-long", sub("    mass: m\n", "    mass: " + "+".join(["m"] * 2100) + "\n"), "mass: m+m",
         None, "links.arm.mass", "longer than"),
    # ------------------------------------------------------------------ names
    Case("parameter-cycle", subs(("  a: 0.3\n", "  a: l\n"), ("  l: 0.5\n", "  l: a\n")), "a: l", "l", "parameters.a",
         "cycle"),
    Case("reserved-parameter-pi", sub("  k: 100\n", "  pi: 3\n"), "pi: 3", "pi", "parameters.pi", "reserved"),
    Case("reserved-parameter-t", sub("  k: 100\n", "  t: 3\n"), "t: 3", "t", "parameters.t", "reserved"),
    Case("reserved-parameter-sin", sub("  k: 100\n", "  sin: 3\n"), "sin: 3", "sin", "parameters.sin", "reserved"),
    Case("reserved-coordinate-der", sub("  beta:\n", "  der:\n"), "  der:", "der", "coordinates.der", "reserved"),
    Case("parameter-and-coordinate", sub("  k: 100\n", "  k: 100\n  beta: 1\n"), Nth("  beta:", 2), "beta",
         "coordinates.beta", "both a parameter and a coordinate"),
    # ------------------------------------------------------------------ link tree and joints
    Case("parent-does-not-exist", sub("parent: column", "parent: colum"), "parent: colum", None,
         "links.arm.joint.parent", "did you mean 'column'"),
    Case("links-form-a-cycle", sub("parent: ground", "parent: arm"), "parent: arm", "arm",
         "links.column.joint.parent", "cycle"),
    Case("link-is-its-own-parent", sub("parent: column", "parent: arm"), "parent: arm", None,
         "links.arm.joint.parent", "own parent"),
    Case("link-named-ground", sub("  column:\n", "  ground:\n"), "  ground:", "ground", "links.ground", "reserved"),
    Case("coordinate-used-by-two-joints", sub("coordinate: beta", "coordinate: alpha"),
         Nth("coordinate: alpha", 2), "alpha", "links.arm.joint.coordinate", "already used"),
    Case("unknown-coordinate-in-joint", sub("coordinate: beta", "coordinate: bet"), "coordinate: bet", None,
         "links.arm.joint.coordinate", "unknown coordinate 'bet' (did you mean 'beta'?)"),
    Case("unknown-point-arm-tipp", sub("between: [arm.tip,", "between: [arm.tipp,"), "arm.tipp", None,
         "forces[2].between[0]", "unknown point 'tipp'"),
    Case("unknown-link-in-point", sub("between: [arm.tip,", "between: [armm.tip,"), "armm.tip", None,
         "forces[2].between[0]", "unknown link 'armm' (did you mean 'arm'?)"),
    Case("unknown-ground-point", sub("ground.anchor]", "ground.anchr]"), "ground.anchr", None,
         "forces[2].between[1]", "did you mean 'anchor'"),
    Case("torque-on-unknown-link", sub("    on: column\n", "    on: colunm\n"), "on: colunm", None,
         "forces[1].on", "did you mean 'column'"),
    Case("scalar-torque-without-axis", sub("    axis: z\n    value: Mo", "    value: Mo"), "value: Mo - dM", None,
         "forces[1].value", "axis"),
    Case("zero-axis-vector", sub("      axis: x\n", "      axis: [0, 0, 0]\n"), "axis: [0, 0, 0]", None,
         "links.arm.joint.axis", "zero vector"),
    Case("torsional-spring-unknown-coordinate",
         append("  - type: torsional_spring\n    coordinate: gama\n    stiffness: k\n"), "coordinate: gama", None,
         "forces[3].coordinate", "unknown coordinate 'gama'"),
    # ------------------------------------------------------------------ constraints
    Case("holonomic-identically-zero", append("constraints:\n  - type: holonomic\n    expression: a - a\n"),
         ("  - type: holonomic", "expression: a - a"), None, "constraints[0]", "identically satisfied"),
    Case("point-on-point-two-ground-points",
         append("constraints:\n  - type: point_on_point\n    points: [ground.anchor, ground.other]\n"),
         ("  - type: point_on_point", "points: [ground.anchor"), None, "constraints[0]", "identically satisfied"),
    Case("nonholonomic-not-linear-in-rates",
         append("constraints:\n  - type: nonholonomic\n    expression: der(beta)**2\n"), "der(beta)**2", None,
         "constraints[0].expression", "linear in the rates"),
    Case("constraint-unknown-type", append("constraints:\n  - type: holonomc\n    expression: beta\n"),
         "type: holonomc", "holonomc", "constraints[0].type", "did you mean 'holonomic'"),
    Case("constraint-not-a-mapping", append("constraints:\n  - beta = 0\n"), "  - beta = 0", None,
         "constraints[0]", "expected a mapping"),
    # ------------------------------------------------------------------ bodies
    Case("particle-with-inertia", sub("    mass: m\n", "    mass: m\n    particle: true\n"),
         (Nth("    inertia:", 2), "xx: I2x"), None, "links.arm.inertia", "particle"),
    Case("shape-and-inertia", sub("    mass: m\n", "    mass: m\n    shape: {rod: {length: l}}\n"),
         "shape: {rod", "{rod", "links.arm.shape", "not both"),
    Case("two-shapes", sub("    inertia:\n      zz: I1\n", "    shape: {rod: {length: 1}, disk: {radius: 1}}\n"),
         "shape: {rod", "{rod", "links.column.shape", "exactly one shape"),
    # ------------------------------------------------------------------ unsafe expressions (never executed)
    # the tokenizer rejects the quote before anything is parsed, let alone called
    Case("security-import-os-system", sub("    mass: m\n", f"    mass: \"{SECURITY}\"\n"), "mass: \"__import__",
         "'os'", "links.arm.mass", "unexpected character \"'\""),
    Case("security-import-in-parameter", sub("  k: 100\n", f"  k: \"{SECURITY}\"\n"), "k: \"__import__",
         "'os'", "parameters.k", "unexpected character"),
    Case("security-import-in-force", sub("value: Mo - dM*der(alpha)", f"value: \"{SECURITY}\""),
         "value: \"__import__", "'os'", "forces[1].value", "unexpected character"),
    Case("security-import-no-quotes", sub("    mass: m\n", "    mass: __import__(os)\n"),
         "mass: __import__", "__import__", "links.arm.mass", "unknown function '__import__'"),
    Case("security-class-attribute", sub("    mass: m\n", "    mass: ().__class__\n"), "mass: ().__class__", ".",
         "links.arm.mass", "unexpected character '.'"),
    Case("security-attribute-access", sub("    mass: m\n", "    mass: m.__class__\n"), "mass: m.__class__", ".__",
         "links.arm.mass", "unexpected character '.'"),
    Case("security-lambda", sub("    mass: m\n", "    mass: 'lambda: 1'\n"), "mass: 'lambda: 1'", ": 1",
         "links.arm.mass", "unexpected character ':'"),
    Case("security-open", sub("    mass: m\n", "    mass: open('x')\n"), "mass: open('x')", "'x'",
         "links.arm.mass", "unexpected character"),
    Case("security-open-name", sub("    mass: m\n", "    mass: open(m)\n"), "mass: open(m)", "open",
         "links.arm.mass", "unknown function 'open'"),
    Case("security-eval-string", sub("    mass: m\n", "    mass: \"eval('1')\"\n"), "mass: \"eval", "'1'",
         "links.arm.mass", "unexpected character"),
    Case("security-eval-name", sub("    mass: m\n", "    mass: eval(m)\n"), "mass: eval(m)", "eval",
         "links.arm.mass", "unknown function 'eval'"),
    Case("security-dunder-builtins", sub("    mass: m\n", "    mass: __builtins__\n"), "mass: __builtins__",
         "__builtins__", "links.arm.mass", "unknown name '__builtins__'"),
    Case("security-subscript", sub("    mass: m\n", "    mass: m[0]\n"), "mass: m[0]", None, "links.arm.mass",
         "unexpected character '['"),
    # ------------------------------------------------------------------ values that are not finite real numbers
    Case("yaml-integer-5000-digits-parameter", sub("  k: 100\n", f"  k: {'9' * 5000}\n"), "k: 999", None,
         "parameters.k", ("too large", "digits", "finite")),
    Case("yaml-integer-5000-digits-mass", sub("    mass: m\n", f"    mass: {'9' * 5000}\n"), "mass: 999", None,
         "links.arm.mass", ("too large", "digits", "finite")),
    Case("mass-log-zero", sub("    mass: m\n", "    mass: log(0)\n"), "mass: log(0)", None, "links.arm.mass",
         ("finite", "real", "infinit")),
    Case("mass-zero-to-negative-power", sub("    mass: m\n", "    mass: 0**-1\n"), "mass: 0**-1", None,
         "links.arm.mass", ("finite", "real", "infinit", "division by zero")),
    Case("mass-complex", sub("    mass: m\n", "    mass: (-8)**(1/3)\n"), "mass: (-8)", None, "links.arm.mass",
         ("real", "complex")),
    Case("joint-axis-zero-after-parameters", sub("      axis: x\n", "      axis: [a - 0.3, 0, 0]\n"),
         "axis: [a - 0.3", None, "links.arm.joint.axis", "zero"),
    Case("joint-axis-complex", sub("      axis: x\n", "      axis: [sqrt(-1), 0, 1]\n"), "axis: [sqrt(-1)", None,
         "links.arm.joint.axis", ("real", "complex")),
    Case("line-direction-zero-after-parameters",
         append("constraints:\n  - type: point_on_line\n    point: arm.tip\n    through: ground\n"
                "    direction: [a - 0.3, 0, 0]\n"), "direction: [a - 0.3", None, "constraints[0].direction", "zero"),
    Case("line-direction-complex",
         append("constraints:\n  - type: point_on_line\n    point: arm.tip\n    through: ground\n"
                "    direction: [sqrt(-1), 0, 1]\n"), "direction: [sqrt(-1)", None, "constraints[0].direction",
         ("real", "complex")),
    # a product of inertia that makes T negative about an axis the arm turns about (x, and z with the column)
    Case("inertia-negative-kinetic-energy", sub("      zz: I2z\n", "      zz: I2z\n      xz: 5\n"), "xx: I2x", None,
         "links.arm.inertia", "kinetic energy would be negative"),
    Case("constraint-name-twice",
         append("constraints:\n  - {type: holonomic, name: k, expression: beta - 0.1}\n"
                "  - {type: holonomic, name: k, expression: alpha - 0.2}\n"), Nth("name: k", 2), None,
         "constraints[1].name", "duplicate constraint name"),
]


IDS = [c.id for c in CASES]
assert len(set(IDS)) == len(IDS), "duplicate case ids"


# ----------------------------------------------------------------------------------------- running
@pytest.fixture(scope="module")
def runner() -> CliRunner:
    return CliRunner(env={"MECHSYS_DEBUG": None})


def invoke(runner: CliRunner, args: list[str]):
    result = runner.invoke(app, args)
    # An exception that escaped the CLI would be recorded here (CliRunner swallows it): it must not happen.
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"uncaught {type(result.exception).__name__}: {result.exception!r}\nstderr: {result.stderr!r}")
    return result


def assert_one_line_error(result, *, stdout: str | None = None, stderr: str | None = None, code: int | None = None):
    out = result.stdout if stdout is None else stdout
    err = result.stderr if stderr is None else stderr
    exit_code = result.exit_code if code is None else code
    detail = f"exit={exit_code} stdout={out!r} stderr={err!r}"
    assert exit_code == 2, detail
    assert "Traceback" not in out + err, detail
    assert out == "", detail
    assert err.endswith("\n") and len(err.splitlines()) == 1, detail  # no \r, \x85, \u2028 inside either
    return err.rstrip("\n")


def check_positioned(case: Case, path: Path, text: str, line_out: str) -> None:
    detail = f"stderr line: {line_out!r}"
    m = LINE_RE.match(line_out)
    assert m, f"not FILE:LINE:COL: ... -- {detail}"
    assert m["file"] == str(path), detail
    if case.line is not None:
        lines, col = expected_position(case, text)
        assert int(m["line"]) in lines, f"expected line in {sorted(lines)} -- {detail}"
        if col is not None:
            assert int(m["col"]) == col, f"expected col {col} -- {detail}"
    rest = m["rest"]
    if case.path is not None:
        assert rest.startswith(case.path + ": "), f"expected key path {case.path!r} -- {detail}"
        message = rest[len(case.path) + 2:]
    else:
        message = rest
    fragments = case.fragment if isinstance(case.fragment, tuple) else (case.fragment,)
    assert any(f.lower() in message.lower() for f in fragments), (
        f"expected {' or '.join(map(repr, fragments))} in the message -- {detail}")
    if any("did you mean" in f for f in fragments):
        assert message.count("did you mean") == 1, detail


@pytest.mark.parametrize("command", ["derive", "info"])
@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_invalid_model(case: Case, command: str, tmp_path: Path, runner: CliRunner) -> None:
    marker = tmp_path / MARKER_NAME
    text = case.text(marker)
    path = tmp_path / "model.yaml"
    path.write_text(text, encoding="utf-8")
    result = invoke(runner, [command, str(path)])
    line_out = assert_one_line_error(result)
    check_positioned(case, path, text, line_out)
    assert not marker.exists(), "an expression was executed"


def test_base_model_is_valid(tmp_path: Path, runner: CliRunner) -> None:
    """The cases only make sense if the unmutated base model derives cleanly."""
    path = tmp_path / "model.yaml"
    path.write_text(BASE, encoding="utf-8")
    result = invoke(runner, ["derive", str(path)])
    assert result.exit_code == 0, result.stderr
    assert result.stderr == ""
    assert "centrifuge_test" in result.stdout


# ----------------------------------------------------------------------------------------- files
@pytest.mark.parametrize("command", ["derive", "info"])
def test_missing_file(command: str, tmp_path: Path, runner: CliRunner) -> None:
    path = tmp_path / "nosuch.yaml"
    line_out = assert_one_line_error(invoke(runner, [command, str(path)]))
    assert str(path) in line_out and "no such file" in line_out


@pytest.mark.parametrize("command", ["derive", "info"])
def test_directory_instead_of_file(command: str, tmp_path: Path, runner: CliRunner) -> None:
    line_out = assert_one_line_error(invoke(runner, [command, str(tmp_path)]))
    assert str(tmp_path) in line_out and "directory" in line_out


@pytest.mark.parametrize("command", ["derive", "info"])
def test_non_utf8_file(command: str, tmp_path: Path, runner: CliRunner) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes(BASE.replace("Column driven", "Colonne entra\xeen\xe9e").encode("latin-1"))
    line_out = assert_one_line_error(invoke(runner, [command, str(path)]))
    m = LINE_RE.match(line_out)
    assert m and m["file"] == str(path), line_out
    assert "UTF-8" in line_out


# ----------------------------------------------------------------------------------------- --set
SET_CASES = [
    ("unknown-name", ["nosuch=1"], "unknown parameter or coordinate"),
    ("misspelt-name", ["mm=1"], "did you mean 'm'"),
    ("no-equals", ["m"], "expected NAME=VALUE"),
    ("empty-value", ["m="], "expected NAME=VALUE"),
    ("empty-name", ["=1"], "expected NAME=VALUE"),
    ("bad-name", ["1x=2"], "expected NAME=VALUE"),
    ("der-unknown-coordinate", ["der(nosuch)=0"], "unknown coordinate"),
    ("der-misspelt-coordinate", ["der(bet)=0"], "did you mean 'beta'"),
    ("der-of-parameter", ["der(m)=0"], "unknown coordinate"),
    ("value-unknown-name", ["m=foo"], "unknown name 'foo'"),
    ("value-syntax-error", ["m=2*"], "expected a number, name or '('"),
    ("value-division-by-zero", ["m=1/0"], "division by zero"),
    ("coordinate-value-uses-coordinate", ["beta=alpha"], "unknown name 'alpha'"),
    ("rate-value-unknown-name", ["der(beta)=omega"], "unknown name 'omega'"),
    ("value-security", [f"m={SECURITY}"], "unexpected character"),
    ("value-security-unquoted", ["m=__import__(os)"], "unknown function '__import__'"),
    ("value-security-attribute", ["m=m.__class__"], "unexpected character '.'"),
    ("second-of-two-bad", ["m=2", "nosuch=1"], "nosuch"),
]


@pytest.mark.parametrize("command", ["derive", "info"])
@pytest.mark.parametrize("args,fragment", [c[1:] for c in SET_CASES], ids=[c[0] for c in SET_CASES])
def test_invalid_set(args: list[str], fragment: str, command: str, tmp_path: Path, runner: CliRunner) -> None:
    marker = tmp_path / MARKER_NAME
    path = tmp_path / "model.yaml"
    path.write_text(BASE, encoding="utf-8")
    argv = [command, str(path)]
    for item in args:
        argv += ["--set", item.replace("MARKER", str(marker))]
    line_out = assert_one_line_error(invoke(runner, argv))
    assert line_out.startswith("mechsys: --set") or LINE_RE.match(line_out), line_out
    assert fragment in line_out, line_out
    assert not marker.exists()


def test_valid_set_is_accepted(tmp_path: Path, runner: CliRunner) -> None:
    path = tmp_path / "model.yaml"
    path.write_text(BASE, encoding="utf-8")
    result = invoke(runner, ["derive", str(path), "--set", "m=2*a", "--set", "der(beta)=1", "--set", "alpha=0.1"])
    assert result.exit_code == 0, result.stderr


# ----------------------------------------------------------------------------------------- real processes
def run_cli(args: list[str], cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "MECHSYS_DEBUG"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-m", "mechsys", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


SUBPROCESS_CASES = ["yaml-tab-indent", "unknown-top-level-paramters", "security-import-os-system",
                    "unknown-name-gg"]


@pytest.mark.parametrize("case_id", SUBPROCESS_CASES)
def test_subprocess_no_traceback(case_id: str, tmp_path: Path) -> None:
    case = next(c for c in CASES if c.id == case_id)
    marker = tmp_path / MARKER_NAME
    text = case.text(marker)
    path = tmp_path / "model.yaml"
    path.write_text(text, encoding="utf-8")
    proc = run_cli(["derive", str(path)], tmp_path)
    line_out = assert_one_line_error(None, stdout=proc.stdout, stderr=proc.stderr, code=proc.returncode)
    check_positioned(case, path, text, line_out)
    assert not marker.exists()


HUGE = [
    ("power-tower-in-mass", "    mass: m\n", "    mass: 9**9**9\n", "links.arm.mass"),
    ("power-tower-caret-in-parameter", "  k: 100\n", "  k: 10^10^10\n", "parameters.k"),
    ("nested-exp-in-parameter", "  k: 100\n", "  k: exp(exp(exp(100)))\n", "parameters.k"),
]
HUGE_TIMEOUT = 8


@pytest.mark.parametrize("old,new,key", [h[1:] for h in HUGE], ids=[h[0] for h in HUGE])
def test_subprocess_huge_numbers_fail_fast(old: str, new: str, key: str, tmp_path: Path) -> None:
    """Absurdly large numbers are invalid input: exit 2 promptly, not a hang computing a 10**9-digit integer."""
    path = tmp_path / "model.yaml"
    path.write_text(sub(old, new)(BASE), encoding="utf-8")
    try:
        proc = run_cli(["derive", str(path)], tmp_path, timeout=HUGE_TIMEOUT)
    except subprocess.TimeoutExpired:
        pytest.fail(f"`mechsys derive` did not finish within {HUGE_TIMEOUT} s for {new.strip()!r}")
    line_out = assert_one_line_error(None, stdout=proc.stdout, stderr=proc.stderr, code=proc.returncode)
    assert f": {key}: " in line_out, line_out


def test_subprocess_tmp_pwned_not_created(tmp_path: Path) -> None:
    """The literal payload of the brief: `touch /tmp/pwned` inside an expression is never run."""
    pwned = Path("/tmp/pwned")
    existed = pwned.exists()
    path = tmp_path / "model.yaml"
    path.write_text(sub("    mass: m\n", "    mass: \"__import__('os').system('touch /tmp/pwned')\"\n")(BASE),
                    encoding="utf-8")
    proc = run_cli(["info", str(path)], tmp_path)
    assert_one_line_error(None, stdout=proc.stdout, stderr=proc.stderr, code=proc.returncode)
    if not existed:
        assert not pwned.exists(), "the expression was executed"


def test_subprocess_set_and_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "model.yaml"
    path.write_text(BASE, encoding="utf-8")
    proc = run_cli(["derive", str(path), "--set", "nosuch=1"], tmp_path)
    line_out = assert_one_line_error(None, stdout=proc.stdout, stderr=proc.stderr, code=proc.returncode)
    assert line_out.startswith("mechsys: --set nosuch")
    proc = run_cli(["derive", str(tmp_path / "missing.yaml")], tmp_path)
    line_out = assert_one_line_error(None, stdout=proc.stdout, stderr=proc.stderr, code=proc.returncode)
    assert "no such file" in line_out
