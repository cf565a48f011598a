r"""Exported programs for the CLI's fixed queries: trace and lower once, reuse after.

A CLI query such as `jaxrod snap-angles` runs one jitted function of the scene's array
leaves. Tracing and lowering the library to StableHLO takes seconds on every run
(`benchmarks/results/compile.md` times it per entry point), and JAX's persistent
compilation cache only saves the XLA compile that follows, because its key is the lowered
module. So the first run of a query exports the function (`jax.export`: the lowered
module with its input and output structure) to `<cache>/jaxrod/exported/<key>.jaxexport`;
later runs deserialize that file and call it, and the persistent cache supplies the
executable: no library code is traced.

The key is a SHA-256 of the query's name, jaxrod's source (every `.py` file of the
package), the versions of jax and jaxlib, and the scene's structure (static fields, mesh)
and leaf shapes and dtypes: any change of code or environment exports afresh, and a stale
file is never read. A file that cannot be read or called is replaced. Without the cache
(`JAXROD_NO_CACHE=1`) or without `flatbuffers` (needed for serialization) the function is
called directly: the library's own jitted functions inside it (`snap_angles`) are reused
from the process's in-memory cache, the numbers are the same.
"""

from __future__ import annotations

import hashlib
import os

from .._misc import source_digest

EXPORT_SUFFIX = ".jaxexport"


def export_dir() -> str | None:
    """The directory of exported programs, or None where caching is off
    (`JAXROD_NO_CACHE`). Beside JAX's persistent cache: JAX_COMPILATION_CACHE_DIR's
    sibling `exported` if that is set, else ~/.cache/jaxrod/exported."""
    if os.environ.get("JAXROD_NO_CACHE"):
        return None
    xla = os.environ.get("JAX_COMPILATION_CACHE_DIR")
    if xla:
        return os.path.join(os.path.dirname(os.path.abspath(xla)), "exported")
    return os.path.join(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "jaxrod", "exported")


def cache_key(name: str, static, leaves) -> str:
    """SHA-256 of what the exported program depends on (module docstring)."""
    import jax
    import jaxlib

    h = hashlib.sha256()
    for part in (name, jax.__version__, jaxlib.__version__, source_digest(), str(jax.config.jax_enable_x64),
                 repr(static), str(jax.tree.structure(static))):
        h.update(part.encode())
        h.update(b"\0")
    for x in leaves:
        h.update(f"{x.shape}{x.dtype};".encode())
    return h.hexdigest()


def _call(exp, leaves):
    """Run an exported program, compiled with jaxrod's XLA options (`jaxrod._compile.compiler_options`)."""
    import jax

    from .._compile import compiler_options

    return jax.jit(exp.call, compiler_options=compiler_options())(*leaves)


def call(name: str, fn, scene, directory: str | None = None):
    """`fn(scene)` (a pytree of arrays out, e.g. a dict) through an exported program.

    Returns `(out, how)`: `how` is "loaded" (read from the cache, nothing traced),
    "exported" (traced, lowered and written) or "direct" (no cache: `fn(scene)` called).
    `directory` defaults to [`export_dir`][]."""
    import equinox as eqx
    import jax

    arrays, static = eqx.partition(scene, eqx.is_array)
    leaves, treedef = jax.tree.flatten(arrays)

    def flat(*leaves):
        return fn(eqx.combine(jax.tree.unflatten(treedef, leaves), static))

    directory = export_dir() if directory is None else directory
    if directory is None:
        return fn(scene), "direct"
    try:
        from jax import export
        import flatbuffers  # noqa: F401 - needed by Exported.serialize
    except ImportError:
        return fn(scene), "direct"
    path = os.path.join(directory, cache_key(name, static, leaves) + EXPORT_SUFFIX)
    if os.path.exists(path):
        try:
            with open(path, "rb") as f:
                exp = export.deserialize(bytearray(f.read()))
            return _call(exp, leaves), "loaded"
        except Exception:  # noqa: BLE001 - a damaged file is replaced below
            pass
    exp = export.export(jax.jit(flat))(*leaves)
    try:
        os.makedirs(directory, exist_ok=True)
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "wb") as f:
            f.write(exp.serialize())
        os.replace(tmp, path)  # atomic: a concurrent run reads a whole file or none
    except OSError:
        pass  # an unwritable cache only means exporting again next time
    return _call(exp, leaves), "exported"
