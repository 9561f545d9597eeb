"""Fuzzing the case files: mutants of every shipped case run through ``--validate`` in-process.

Each mutant changes one thing of a shipped case: a number made negative, zero, NaN, infinite, a
word or a list; a key misspelt or removed; the YAML broken; the file replaced by binary bytes.
Every mutant must either still be a valid case or be refused with exit code 2 and one line that
names the file and the key — never a traceback. Every leaf and key of every case is mutated,
the kind of mutation cycling over the leaves so that the suite stays under a minute.
Then short runs of geometrically wrong cases check that the pre-run checks fire.
"""
from __future__ import annotations

import copy
import re
import shutil
from pathlib import Path

import pytest
import yaml

from fcm_fsi.cli import main
from tests.conftest import ROOT, run_cli

CASES = sorted((ROOT / "cases").glob("*.yaml"))
NUMBER_MUTATIONS = ("negative", "zero", "nan", "inf", "word", "list")


def leaves(node, path=()):
    """(path, value) of every number in a case mapping; a path is a tuple of keys and indices."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from leaves(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from leaves(v, path + (i,))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield path, node


def keys(node, path=()):
    """The path of every mapping key of a case."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield path + (k,)
            yield from keys(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from keys(v, path + (i,))


def dotted(path) -> str:
    """('dem', 'blocks', 0, 'radius') → 'dem.blocks[0].radius', as the loader names keys."""
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out


def parent(data, path):
    node = data
    for p in path[:-1]:
        node = node[p]
    return node


def mutated_number(value, kind: str):
    return {"negative": -abs(value) if value else -1, "zero": 0, "nan": float("nan"), "inf": float("inf"),
            "word": "fast", "list": [value, value]}[kind]


def misspelt(key: str) -> str:
    return key[:-1] + key[-1] * 2 + "x" if key else "x"


def mutants(case: Path):
    """(label, key path the error must name or None, YAML text) for one case file."""
    data = yaml.safe_load(case.read_text())
    for i, (path, value) in enumerate(leaves(data)):
        kind = NUMBER_MUTATIONS[i % len(NUMBER_MUTATIONS)]
        m = copy.deepcopy(data)
        parent(m, path)[path[-1]] = mutated_number(value, kind)
        yield f"{dotted(path)} {kind}", path, yaml.safe_dump(m, sort_keys=False)
    for i, path in enumerate(keys(data)):
        m = copy.deepcopy(data)
        node = parent(m, path)
        value = node.pop(path[-1])
        if i % 2 == 0:
            node[misspelt(str(path[-1]))] = value
            yield f"{dotted(path)} misspelt", path[:-1] + (misspelt(str(path[-1])),), yaml.safe_dump(m, sort_keys=False)
        else:
            yield f"{dotted(path)} removed", None, yaml.safe_dump(m, sort_keys=False)


def names_key(message: str, path) -> bool:
    """The message names the mutated key: its dotted path, an enclosing entry (e.g.
    ``dem.walls[2]`` for a wall's point, or the section of a cross-field rule), or the key's own
    name; for a removed key (``path`` None) whichever key the case now lacks or breaks."""
    if path is None:
        return bool(re.search(r"keys? '[^']+'", message))
    paths = [path] + ([path[2:]] if path[:1] == ("resolutions",) and len(path) > 2 else [])
    names = {dotted(p[:n]) for p in paths for n in range(2, len(p) + 1)}
    leaf = [p for p in path if not isinstance(p, int)][-1]
    return any(f"'{n}" in message or f"{n}'" in message or f" {n}" in message for n in names) \
        or f"'{leaf}'" in message or f".{leaf}" in message


def validate(path: Path, capsys) -> tuple[int, str]:
    code = main([str(path), "--validate", "--log-level", "ERROR"])
    captured = capsys.readouterr()
    return code, captured.err + captured.out


@pytest.mark.parametrize("case", CASES, ids=[c.stem for c in CASES])
def test_mutants_are_refused_with_one_line_naming_the_key(case, tmp_path, capsys):
    target = tmp_path / case.name
    shutil.copytree(ROOT / "cases" / "geometry", tmp_path / "geometry")     # the CAD files the cases read
    refused = 0
    failures = []
    for label, path, text in mutants(case):
        target.write_text(text)
        code, out = validate(target, capsys)
        if code == 0:
            continue
        refused += 1
        lines = out.strip().splitlines()
        if code != 2 or "Traceback" in out or len(lines) != 1 or str(target) not in lines[0] \
                or not names_key(lines[0], path):
            failures.append(f"{label}: exit {code}: {out.strip()[-400:]}")
    assert not failures, "\n".join(failures[:10])
    assert refused > 0


@pytest.mark.parametrize("case", CASES[::3], ids=[c.stem for c in CASES[::3]])
def test_broken_yaml_and_binary_bytes_are_one_line(case, tmp_path, capsys):
    text = case.read_text()
    bad = {
        "truncated": text[: len(text) // 2] + "\n  - {a: [1, 2\n",
        "tab_indent": text.replace("\n  ", "\n\t", 1),
        "binary": bytes(range(256)) * 4,
        "latin1": text.replace("name:", "# Größe\nname:", 1).encode("latin-1", "replace"),
        "empty": b"",
        "list": b"- name: a\n- name: b\n",
        "scalar": b"just some words\n",
        "duplicate": text + "\nname: again\n",
    }
    for label, content in bad.items():
        target = tmp_path / f"{label}.yaml"
        (target.write_bytes if isinstance(content, bytes) else target.write_text)(content)
        code, out = validate(target, capsys)
        lines = out.strip().splitlines()
        assert code == 2 and len(lines) == 1 and "Traceback" not in out and str(target) in lines[0], (label, out)


@pytest.mark.parametrize("case, overrides, expected", [
    ("floating_box", ["dem.blocks=[{shape: box, material: wood, position: [50.0, 0.275, 0.0], size: [0.2, 0.1, 0.1], "
                      "radius: 0.01}]"], "key 'dem.blocks[0].position': block 0 spans [49.9, 0.225]..[50.1, 0.325] m, "
                                         "wholly outside the fluid mesh"),
    ("floating_box", ["mesh.cells=[20000, 20000]"], "key 'mesh.cells': = [20000, 20000]: ≈ 8e+08 cells"),
    ("dam_break", ["phase_field.initial.lower=[1.0, 1.0]", "phase_field.initial.upper=[2.0, 2.0]"],
     "key 'phase_field.initial': the liquid region (box) does not overlap the mesh"),
])
def test_runs_of_geometrically_wrong_cases_stop_before_anything_is_built(tmp_path, case, overrides, expected):
    """Not --validate: a real run, which must stop at the pre-run checks with exit code 2 and
    one line, before it writes anything (the output folder is not even created)."""
    out = tmp_path / "out"
    args = [str(ROOT / "cases" / f"{case}.yaml"), "--output", str(out), "--log-level", "WARNING"]
    for o in overrides:
        args += ["--set", o]
    res = run_cli(args, timeout=120)
    assert res.returncode == 2, res.stderr[-2000:]
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0] and "Traceback" not in res.stderr + res.stdout, res.stderr
    assert not out.exists()
