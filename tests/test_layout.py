"""The layers of the house, checked on the source: data flows one way.

    model -> energy -> linalg, sweeps -> statics -> branches -> dynamics -> design -> plot -> paper -> cli

Every import inside `jaxrod/` and `design/` (installed as `jaxrod.design`) is read from the
syntax tree, at module level and inside functions alike, and each must (1) go to the same or
a lower layer, (2) name another subpackage only through its public surface (its `__init__`
or a public module such as `jaxrod.energy.geometry`), never an underscore module or an
underscore name of it, and (3) leave the design package out of the core. The one way up is
not an import statement: the names that moved from `jaxrod.design` to `jaxrod.paper` resolve
through `jaxrod.design.__getattr__` on first use, with a DeprecationWarning (checked below).
"""

import ast
import json
import pathlib
import re
import sys

import pytest

from helpers import parse_source as _parse  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
# the shared base (results, _misc, _compile, _custom_types and the package root's own files) is layer 0
RANK = {"model": 1, "energy": 2, "linalg": 3, "sweeps": 3, "statics": 4, "branches": 5, "dynamics": 6, "design": 7,
        "plot": 8, "paper": 9, "cli": 10}
CORE = {"model", "energy", "linalg", "sweeps", "statics", "branches", "dynamics"}


def _modules():
    for path in sorted((ROOT / "jaxrod").rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        yield path, parts
    for path in sorted((ROOT / "design").rglob("*.py")):
        yield path, ["jaxrod", "design", *path.relative_to(ROOT / "design").with_suffix("").parts]


def _imports(path, parts):
    """(target module, imported names) for every import of jaxrod in the file."""
    pkg = parts[:-1] if parts[-1] != "__init__" else parts[:-1]
    if parts[-1] == "__init__":
        pkg = parts[:-1]
    tree = _parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg[: len(pkg) - (node.level - 1)]
                mod = base + (node.module.split(".") if node.module else [])
            else:
                mod = node.module.split(".")
            if mod[0] != "jaxrod":
                continue
            names = [a.name for a in node.names]
            # `from jaxrod.linalg import kkt` names a module: treat it as importing that module
            yield mod, names
        elif isinstance(node, ast.Import):
            for a in node.names:
                mod = a.name.split(".")
                if mod[0] == "jaxrod":
                    yield mod, []


def _layer(mod):
    return mod[1] if len(mod) > 1 and mod[1] in RANK else None


def _violations():
    out = []
    for path, parts in _modules():
        me = _layer(parts)
        rel = path.relative_to(ROOT)
        for mod, names in _imports(path, parts):
            there = _layer(mod)
            if len(mod) == 1 and me is not None and me not in ("plot", "cli", "design", "paper"):
                out.append(f"{rel}: imports the package root `jaxrod` (a layer must import what it uses directly)")
            if there is None or there == me:
                continue
            if me is not None and RANK[there] > RANK[me]:
                out.append(f"{rel}: layer {me} imports the higher layer {there} ({'.'.join(mod)})")
            if me in CORE and there == "design":
                out.append(f"{rel}: the core imports the design package")
            if any(p.startswith("_") for p in mod[2:]):
                out.append(f"{rel}: imports the private module {'.'.join(mod)} of another subpackage")
            private = [n for n in names if n.startswith("_")]
            if private:
                out.append(f"{rel}: imports private names {private} from {'.'.join(mod)}")
    return out


def test_layers_flow_one_way():
    assert _violations() == []


def _file_of(mod):
    """The file of the jaxrod module `mod` (a list of names), or None where it is not a module."""
    base = ROOT / "design" / pathlib.Path(*mod[2:]) if mod[:2] == ["jaxrod", "design"] else ROOT / pathlib.Path(*mod)
    if base.with_suffix(".py").exists():
        return base.with_suffix(".py")
    return base / "__init__.py" if (base / "__init__.py").exists() else None


def _import_cycles():
    """The sets of jaxrod's modules that import each other, directly or through others, with
    every import counted (those inside functions too); `from pkg import submodule` imports the
    submodule."""
    graph = {}
    for path, parts in _modules():
        edges = set()
        for mod, names in _imports(path, parts):
            target = _file_of(mod)
            if target is None:
                continue
            subs = [_file_of(mod + [n]) for n in names]
            edges.update(f for f in subs if f is not None)
            if not names or not all(subs):
                edges.add(target)
        edges.discard(path)
        graph[path] = edges
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(str(p.relative_to(ROOT)) for p in comp))

    for v in list(graph):
        if v not in index:
            visit(v)
    return cycles


def test_no_import_cycles():
    """No two modules of jaxrod import each other, not even inside a function."""
    assert _import_cycles() == []


def test_layout_check_catches_a_violation(tmp_path, monkeypatch):
    """The check itself can fail: a statics module importing a branches private is caught."""
    fake = tmp_path / "jaxrod" / "statics"
    fake.mkdir(parents=True)
    (tmp_path / "design").mkdir()
    (fake / "_bad.py").write_text("from ..branches._snap import follow_path\nfrom ..branches import _x\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    found = _violations()
    assert any("higher layer branches" in v for v in found)
    assert any("private module jaxrod.branches._snap" in v for v in found)
    assert any("private names ['_x']" in v for v in found)


@pytest.mark.parametrize("name", ["model", "energy", "linalg", "statics", "branches", "dynamics", "plot", "cli",
                                  "design", "paper"])
def test_every_layer_has_a_public_surface_with_a_docstring(name):
    import importlib

    mod = importlib.import_module(f"jaxrod.{name}")
    assert mod.__doc__ and len(mod.__doc__.split()) > 10


def test_top_level_names_unchanged():
    """The names `jaxrod` exported before the layers were introduced still resolve."""
    import jaxrod as jr

    for n in ["RESULTS", "Strip", "Mesh", "Clamps", "Scene", "make_scene", "solve_equilibrium", "Newton",
              "initial_state", "stability", "snap_angles", "snap_angles_extrapolated", "SnapPath", "KIND_NAMES",
              "critical_point", "cusp_point", "termination_gap", "continue_branch", "continue_critical",
              "hysteresis", "HYSTERESIS_BRANCHES", "phase_diagram", "simulate", "snap_dynamics", "snap_speed",
              "brink", "ramp", "Trajectory", "Dissipation", "Protocol", "clearance", "self_intersects",
              "plot_shape", "plot_hysteresis", "plot_phase_diagram", "BorderedTridiagonal", "lagrangian",
              "discretize", "Equilibrium", "ExtrapolatedPath", "refined_scene"]:
        assert hasattr(jr, n), n


def test_dynamics_imported_on_first_use():
    """`import jaxrod` leaves the dynamics (and diffrax) unimported; each dynamics name of the
    top level resolves to `jaxrod.dynamics`' own object on first use and is listed by `dir`;
    an unknown name is an AttributeError."""
    import subprocess

    code = (
        "import sys, jaxrod as jr\n"
        "assert 'jaxrod.dynamics' not in sys.modules and 'diffrax' not in sys.modules\n"
        "import jaxrod.cli._main as m; m._build_parser()\n"
        "assert 'diffrax' not in sys.modules, 'the CLI parser imports the dynamics'\n"
        "import jaxrod.dynamics as d\n"
        "for n in jr._DYNAMICS: assert getattr(jr, n) is getattr(d, n) and n in dir(jr), n\n"
        "try:\n    jr.no_such_name\nexcept AttributeError as e:\n    assert 'no_such_name' in str(e)\n"
        "else:\n    raise AssertionError('no AttributeError')\n"
        "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr
    # every public name of the dynamics' surface that the top level re-exports is in `_DYNAMICS`
    import jaxrod as jr
    import jaxrod.dynamics as d

    tree = _parse((ROOT / "jaxrod" / "__init__.py").read_text())
    lazy = {a.asname or a.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
            and node.module == "dynamics" for a in node.names}
    assert lazy == set(jr._DYNAMICS) and all(hasattr(d, n) for n in lazy)


def test_paper_imported_on_first_use():
    """`import jaxrod` and `import jaxrod.design` leave `jaxrod.paper` unimported (it sits
    above both), and so does building the CLI's parser; `import jaxrod.paper` works on its own."""
    import subprocess

    code = ("import sys, warnings\n"
            "warnings.simplefilter('error', DeprecationWarning)\n"
            "import jaxrod, jaxrod.design\n"
            "from jaxrod.design import *\n"
            "assert 'jaxrod.paper' not in sys.modules, 'jaxrod.design imports jaxrod.paper'\n"
            "import jaxrod.cli._main as m; m._build_parser()\n"
            "assert 'jaxrod.paper' not in sys.modules, 'the CLI parser imports jaxrod.paper'\n"
            "import jaxrod.paper\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


def test_moved_names_resolve_with_a_deprecation_warning():
    """Every name that moved from `jaxrod.design` to `jaxrod.paper` still resolves under its old
    name, to `jaxrod.paper`'s own object, with a DeprecationWarning naming the new place; none
    is exported by `from jaxrod.design import *` or listed by `dir`; an unknown name is an
    AttributeError."""
    import warnings

    import jaxrod.design as ds
    import jaxrod.paper as paper

    moved = ds._MOVED_TO_PAPER
    assert {"snap_angle_study", "snap_speed_study", "fastest_snap_study", "verify_snap_angles", "verify_snap_speed",
            "StudyResult", "SpeedStudyResult", "SpeedVerification", "fig4_study", "FIG4_N", "FIG4_N_CHECK",
            "FIG4_PEAKS", "FIG4_PROGRAMS", "FIG4_V_LAUNCH", "FIG4_V_SPARE", "actuator_study",
            "crease_position_study", "two_crease_study"} <= moved
    for name in sorted(moved):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            value = getattr(ds, name)
        assert value is getattr(paper, name), name
        assert [w.category for w in caught] == [DeprecationWarning], (name, caught)
        assert f"jaxrod.paper.{name}" in str(caught[0].message) and caught[0].filename == __file__, name
        assert name not in vars(ds) and name not in dir(ds), name
    with pytest.warns(DeprecationWarning, match="jaxrod.paper.snap_angle_study"):
        from jaxrod.design import snap_angle_study
    assert snap_angle_study is paper.snap_angle_study
    star = {}
    exec("from jaxrod.design import *", star)
    assert not moved & set(star) and "optimize" in star and "design_program" in star
    with pytest.raises(AttributeError, match="no_such_name"):
        ds.no_such_name


def test_no_deprecated_name_in_use():
    """Nothing in the repository reaches a moved name through `jaxrod.design` (the source, the
    tests, the benchmarks, the docs, the notebooks); the deprecation path is for users' code."""
    import jaxrod.design as ds

    alias = r"(?:jaxrod\.design|\bds|\bjd|\bD|\bdesign)"
    pattern = re.compile(alias + r"\.(" + "|".join(sorted(ds._MOVED_TO_PAPER, key=len, reverse=True)) + r")\b")
    imported = re.compile(r"from jaxrod\.design import ([^\n]*)")
    hits = []
    files = [*(ROOT / "jaxrod").rglob("*.py"), *(ROOT / "design").rglob("*.py"), *(ROOT / "tests").glob("*.py"),
             *(ROOT / "benchmarks").rglob("*.py"), *(ROOT / "docs").rglob("*.md"), ROOT / "README.md",
             *(ROOT / "notebooks").glob("*.ipynb")]
    for f in files:
        if f.name == "test_layout.py" or "changelog" in f.name.lower():
            continue
        text = f.read_text()
        if f.suffix == ".ipynb":  # the code cells' sources
            text = "\n".join("".join(c["source"]) for c in json.loads(text)["cells"] if c["cell_type"] == "code")
        hits += [f"{f.relative_to(ROOT)}: {m.group(0)}" for m in pattern.finditer(text)]
        for m in imported.finditer(text):
            names = set(re.findall(r"\w+", m.group(1)))
            hits += [f"{f.relative_to(ROOT)}: from jaxrod.design import {n}" for n in names & ds._MOVED_TO_PAPER]
    assert not hits, hits


def test_result_code_table_lists_every_code():
    """The result-code table (docs/results.md) has a row for every member of `jaxrod.RESULTS`."""
    import jaxrod as jr

    text = (ROOT / "docs" / "results.md").read_text()
    table = text[text.index("# Result codes"):]
    table = table[:table.index("\n\n", table.index("| code |"))]
    rows = [line for line in table.splitlines() if line.startswith("| `")]
    listed = {name for line in rows for name in re.findall(r"`(\w+)`", line.split("|")[1])}
    assert set(jr.RESULTS._name_to_item) <= listed, sorted(set(jr.RESULTS._name_to_item) - listed)


def test_readme_is_short_and_every_relative_link_resolves():
    """The README stays a user's page (at most 200 lines, the details in docs/), and every
    relative link of the README and of docs/*.md points at a file that exists."""
    readme = ROOT / "README.md"
    assert len(readme.read_text().splitlines()) <= 200
    missing = []
    for f in [readme, *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)\s]+)\)", f.read_text()):
            path = target.split("#")[0]
            if path and not re.match(r"^(https?:|mailto:)", target) and not (f.parent / path).exists():
                missing.append((f.name, target))
    assert not missing, missing


def test_citation_names_the_package_version():
    """CITATION.cff (the software and the paper it reproduces) carries the installed version."""
    import jaxrod as jr

    text = (ROOT / "CITATION.cff").read_text()
    assert re.search(r"^cff-version: 1\.2\.0$", text, re.M)
    assert re.search(r"^version: (\S+)$", text, re.M).group(1) == jr.__version__
    assert "Augmented snap-through instability of folded strips" in text
