"""The CLI's exported programs (`jaxrod.cli._exported`): exported once, loaded after, keyed
by everything they depend on, replaced when damaged, bypassed without a cache; and a
`snap-angles` query that a second process answers from the exported program with the same
JSON as the first and as the library."""

import json
import os
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.cli import _exported


def query(sc):
    return {"x": 2.0 * sc.strip.psi0 + sc.clamps.gap, "n": jnp.sum(jr.discretize(sc).h) * sc.mesh.n}


def scene(n=8, psi0=60.0):
    return jr.make_scene(psi0, 0.5, n=n)


def test_exported_then_loaded(tmp_path):
    sc = scene()
    a, how_a = _exported.call("q", query, sc, directory=str(tmp_path))
    files = os.listdir(tmp_path)
    assert how_a == "exported" and len(files) == 1 and files[0].endswith(_exported.EXPORT_SUFFIX)
    b, how_b = _exported.call("q", query, sc, directory=str(tmp_path))
    assert how_b == "loaded"
    ref = query(sc)
    for k in ref:
        assert float(a[k]) == float(b[k]) == pytest.approx(float(ref[k]), rel=1e-15)
    # other parameter values: the same program (keys depend on shapes, not values)
    c, how_c = _exported.call("q", query, scene(psi0=30.0), directory=str(tmp_path))
    assert how_c == "loaded" and float(c["x"]) == pytest.approx(float(query(scene(psi0=30.0))["x"]))
    assert len(os.listdir(tmp_path)) == 1


def test_key_follows_what_the_program_depends_on(tmp_path):
    import equinox as eqx
    import jax

    def key(name, sc):
        arrays, static = eqx.partition(sc, eqx.is_array)
        return _exported.cache_key(name, static, jax.tree.leaves(arrays))

    base = key("q", scene())
    assert key("q", scene(psi0=10.0)) == base
    assert key("q", scene(n=10)) != base  # mesh size
    assert key("q", jr.make_scene(60.0, 0.5, n=8, refine=2.0)) != base  # mesh grading (same shapes)
    assert key("r", scene()) != base  # query
    assert key("q", jr.make_scene(60.0, 0.5, n=8, stretching=jr.Stretching(100.0))) != base  # structure
    _, how = _exported.call("q", query, scene(n=10), directory=str(tmp_path))
    assert how == "exported" and len(os.listdir(tmp_path)) == 1


def test_damaged_file_is_replaced(tmp_path):
    sc = scene()
    _exported.call("q", query, sc, directory=str(tmp_path))
    (path,) = [tmp_path / f for f in os.listdir(tmp_path)]
    path.write_bytes(b"not a program")
    out, how = _exported.call("q", query, sc, directory=str(tmp_path))
    assert how == "exported" and float(out["x"]) == pytest.approx(float(query(sc)["x"]))
    assert _exported.call("q", query, sc, directory=str(tmp_path))[1] == "loaded"


def test_no_cache_calls_directly(monkeypatch):
    monkeypatch.setenv("JAXROD_NO_CACHE", "1")
    assert _exported.export_dir() is None
    out, how = _exported.call("q", query, scene())
    assert how == "direct" and float(out["x"]) == pytest.approx(float(query(scene())["x"]))


@pytest.mark.slow  # 42 s on 2 cores (four CLI processes, two of them cold); CI checks the export and the load in process
def test_cli_query_answered_from_the_exported_program(tmp_path):
    """Two `jaxrod snap-angles` processes on one fresh cache: the first exports the query's
    program, the second loads it; both print the library's numbers."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAXROD_NO_CACHE", "JAX_COMPILATION_CACHE_DIR")}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    args = [sys.executable, "-m", "jaxrod", "snap-angles", "--psi0", "60", "--gap", "0.5", "--n", "12",
            "--no-extrapolate", "--json"]
    runs = [subprocess.run(args, capture_output=True, text=True, env=env, timeout=600) for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr
    first, second = (json.loads(r.stdout) for r in runs)
    assert first == second
    exported = os.listdir(tmp_path / "jaxrod" / "exported")
    assert len(exported) == 1
    ref = jr.snap_angles(jr.make_scene(60.0, 0.5, n=12))
    for name in ("up", "down"):
        assert first[f"alpha_c_{name}_deg"] == pytest.approx(np.degrees(float(getattr(ref, name).alpha_c)), abs=1e-9)
    # extrapolated (the default): one program per mesh, run concurrently; the coarse mesh's is
    # the query above (the same program, so the same file: it is loaded, not exported again), the
    # fine mesh's is new; the second process loads both, and both print
    # `snap_angles_extrapolated`'s numbers
    runs = [subprocess.run(args[:-2] + ["--json"], capture_output=True, text=True, env=env, timeout=600)
            for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr
    first, second = (json.loads(r.stdout) for r in runs)
    assert first == second
    now = os.listdir(tmp_path / "jaxrod" / "exported")
    assert len(now) == 2 and set(exported) < set(now)
    ref = jr.snap_angles_extrapolated(jr.make_scene(60.0, 0.5, n=12))
    for name in ("up", "down"):
        e = getattr(ref, name)
        assert first[f"alpha_c_{name}_deg"] == pytest.approx(np.degrees(float(e.alpha_c)), abs=1e-9)
        assert first[f"alpha_c_{name}_deg_n_fine"] == pytest.approx(np.degrees(float(e.alpha_c_fine)), abs=1e-9)
        assert first[f"error_estimate_{name}_deg"] == pytest.approx(np.degrees(float(e.error)), abs=1e-9)
        assert first[f"result_{name}"] == jr.result_name(e.result)
