"""Test configuration: float64 everywhere (set before any array is created), one persistent
XLA compilation cache for the run, and the slowest modules first.

Persistent cache: on by default (JAXROD_TEST_XLA_CACHE=0 turns it off), in the checkout's
`.xla_cache/xla` (git-ignored; JAX_COMPILATION_CACHE_DIR picks another): the xdist workers, the
notebook kernels and the CLI subprocesses of one run share every compiled program, so a
program that several test modules build (snap_angles at a given N and settings, the
dynamics of a scene) is compiled once per run instead of once per module and worker. A fresh
clone starts with it empty, so CI's time counts every compile once. Reading cached programs
at a process's mapping limit segfaults like compiling does; the release below keeps the
workers far from it.
The environment variables are set before jax and equinox are imported so that child
processes inherit them.

Compiled programs are released between modules once a worker holds many: every XLA:CPU
executable keeps about ten memory mappings (its code and data sections) for as long as
JAX's caches hold it, and a worker that runs a few thousand programs nears the kernel's
per-process limit (`vm.max_map_count`, 65530 by default). Past it XLA logs "LLVM
compilation error: Cannot allocate memory" and the worker dies of a segfault, in
`backend_compile_and_load` or, reading the persistent cache, in `get_executable_and_time`
(both reproduced here with the limit lowered). Two CI runs died in exactly those frames,
the second 99 % through the suite. A fresh-clone run without the release peaked at 56,422 mappings in one worker;
with it, at 29,976. `_release_compiled_programs` calls `jaxrod.clear_caches()` after any module
that leaves the worker above a third of the limit (`JAXROD_TEST_MAP_LOG=FILE` logs the
count before and after each module; the largest single module, test_snap, adds ~12,000).

The slowest modules are scheduled first (`pytest_collection_modifyitems`), so that under
`-n 2` the two workers finish at about the same time instead of one running a long module
alone at the end."""

import gc
import os

XLA_CACHE = os.environ.get("JAXROD_TEST_XLA_CACHE", "1") == "1"
if XLA_CACHE:
    _root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.join(_root, ".xla_cache", "xla"))
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.3")
    os.makedirs(os.environ["JAX_COMPILATION_CACHE_DIR"], exist_ok=True)
else:
    os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)  # child processes read it too
# The CLI's exported programs stay off either way (their key does not see a monkeypatched
# library function; `test_exported.py` turns them on in its own directory). The CLI
# subprocesses still share the XLA cache: JAX reads JAX_COMPILATION_CACHE_DIR itself.
os.environ["JAXROD_NO_CACHE"] = "1"
# JAX does not persist a program with host callbacks, and equinox's runtime checks
# (`eqx.error_if`, raised through a callback by default) are callbacks: diffrax checks its
# save times that way, which kept every `jaxrod.simulate` program out of the cache. Those
# checks concern times jaxrod builds itself (`linspace` grids); with EQX_ON_ERROR=nan a
# failed check returns NaN instead (no callback), so the suite can share those programs.
# Set either way, so that a run with the cache runs the same programs as one without.
os.environ.setdefault("EQX_ON_ERROR", "nan")
# XLA's LLVM back end at -O0 for the suite: compiling is most of the suite's time and -O0
# compiles ~40 % faster (snap_angles at N = 40: 12 s instead of 21 s) for ~50 % slower
# compiled code, which the tests barely run (test_snap.py + test_rattle.py: 176 s of CPU
# instead of 206 s). At -O0 XLA's older loop emitters (`xla_cpu_use_fusion_emitters=false`)
# compile ~40 % faster again than its MLIR fusion emitters, whose own lowering pipeline
# runs at every level (measured on 2 cores: snap_angles at N = 24, 3.4-4.9 s instead of
# 6.1-7.3 s; the gradient of snap_speed at N = 16, 9.5-9.8 s instead of 15.8-16.8 s; the same
# results to the last bit). No fast-math either way, so the arithmetic is the same IEEE
# operations; benchmarks and users run at XLA's default level.
_flags = os.environ.get("XLA_FLAGS", "")
if "xla_backend_optimization_level" not in _flags:
    _flags += " --xla_backend_optimization_level=0"
if "xla_cpu_use_fusion_emitters" not in _flags:
    _flags += " --xla_cpu_use_fusion_emitters=false"
os.environ["XLA_FLAGS"] = _flags.strip()
# The suite runs jaxrod's default compile mode ("auto", `jaxrod._compile`), the user's path:
# with the flags above its optimized variant is compiled at -O0 too, so a signature whose
# calls switch to it costs one more compile at the same level (tests/test_jit.py sets the
# modes it tests itself).

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)
if XLA_CACHE:
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs",
                      float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))


def map_count():
    """Memory mappings of this process (lines of /proc/self/maps); None off Linux."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return None


def map_limit():
    """The kernel's per-process mapping limit (vm.max_map_count), 65530 where unreadable."""
    try:
        with open("/proc/sys/vm/max_map_count") as f:
            return int(f.read())
    except (OSError, ValueError):
        return 65530


def release_compiled_programs(threshold):
    """`jaxrod.clear_caches()` (its programs and JAX's caches) when this process holds more
    than `threshold` mappings; returns (mappings before, mappings after), or None when
    nothing was released."""
    import jaxrod

    before = map_count()
    if before is None or before <= threshold:
        return None
    jaxrod.clear_caches()
    gc.collect()
    return before, map_count()


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs(request):
    log = os.environ.get("JAXROD_TEST_MAP_LOG")  # one line per module: for diagnosis
    start = map_count() if log else None
    yield
    end = map_count() if log else None  # release_compiled_programs counts for itself
    released = release_compiled_programs(map_limit() // 3)
    if log:
        with open(log, "a") as f:
            f.write(f"{os.getpid()} {request.module.__name__} {start} {end} {released}\n")


def pytest_configure(config):
    # Under `pytest -n 2` keep each test module on one xdist worker: the modules share
    # jitted functions and states through module-scoped fixtures, and compiling is what
    # costs time (seconds per function), so splitting a module would compile twice.
    if getattr(config.option, "dist", "no") == "load":
        config.option.dist = "loadfile"
    # xdist would otherwise reorder the files by their number of tests (many-test files
    # first), which put the one-test notebook files, the slowest, at the end
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False
    # A worker that dies (a segfault in native code) is not replaced: under `loadfile`,
    # pytest-xdist <= 3.8 puts the dead worker's finished tests back on the queue and the
    # replacement waits forever (pytest-xdist#1323); one CI run hung that way for the whole
    # of its time limit. With no restart the run stops at once and names the test.
    if hasattr(config.option, "maxworkerrestart") and config.option.maxworkerrestart is None:
        config.option.maxworkerrestart = 0


# Modules by measured cost (seconds on 2 cores, cold cache), slowest first; the rest keep
# their order after these.
# test_design_speed runs study (c) at the notebook's quick-mode mesh (N = 16): scheduled after
# notebook 03 has compiled those programs into the shared persistent cache, not beside it
# (both compiling them at once cost ~60 s more).
HEAVY_FIRST = ("test_notebook_03_snap_speed_design", "test_notebook_02_snap_angle_design",
               "test_notebook_05_paper_figures", "test_snap_physics", "test_contact_paths", "test_verdicts", "test_long_horizon",
               "test_extrapolate", "test_resume", "test_properties",
               "test_notebook_01_getting_started", "test_design_speed", "test_notebook_04_programmable_actuator",
               "test_sweeps", "test_self_contact", "test_design", "test_cli", "test_snap", "test_dynamics_physics", "test_actuator", "test_hysteresis",
               "test_dynamics", "test_extremes", "test_reproduce", "test_rattle", "test_critical")


def pytest_collection_modifyitems(session, config, items):
    rank = {m: i for i, m in enumerate(HEAVY_FIRST)}
    items.sort(key=lambda it: rank.get(it.module.__name__.rsplit(".", 1)[-1], len(rank)))
