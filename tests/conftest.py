"""Test configuration: every test runs in float64 (gradient and conservation checks), and
compiled programs are kept in a persistent cache shared by the test workers and every
process they start (CLI runs, notebook kernels), so a program compiled once in a run is
not compiled again.  The tests compile with XLA:CPU's loop emitters instead of its newer
fusion emitters (see TEST_XLA_FLAGS below)."""

import collections
import gc
import json
import os
import subprocess
import sys
import time
import warnings
from importlib.metadata import version
from pathlib import Path

# XLA:CPU compiles a program about a third faster with its loop emitters than with its
# fusion emitters (the default since jaxlib 0.10), and the compiled steps run 4-14 %
# slower (docs/performance.md, "The test suite").  Three quarters of the suite's time is
# compiling, so the tests take the faster compiler; users keep the default.  The results
# are the same to round-off (tests/test_compiler_flags.py runs a simulation both ways).
# Set before JAX creates its CPU backend; the variable reaches the processes the tests
# start (CLI runs, notebook kernels).  A flag the user set is left alone.
TEST_XLA_FLAGS = ("--xla_cpu_use_fusion_emitters=false",)
if tuple(int(part) for part in version("jaxlib").split(".")[:2]) >= (0, 10):
    for flag in TEST_XLA_FLAGS:
        if flag.split("=")[0] not in os.environ.get("XLA_FLAGS", ""):
            os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {flag}".strip()

import jax  # noqa: E402  after XLA_FLAGS
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)

# The cache lives with pytest's own (.pytest_cache, ignored by git).  The environment
# variables reach the subprocesses; the config updates this process, whose jax is
# already imported.
COMPILATION_CACHE = Path(__file__).resolve().parents[1] / ".pytest_cache" / "jax-compilation"
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(COMPILATION_CACHE))
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")
jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
jax.config.update(
    "jax_persistent_cache_min_compile_time_secs",
    float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]),
)


# The costliest test files (seconds on a worker in the suite on a 2-core machine with an
# empty compile cache, largest first) are handed to the workers first, so that no worker
# is left with a long file at the end; the other files follow in their usual order.  Only
# the order changes, not what runs.  pytest-xdist would otherwise hand out the files with
# the most tests first (its loadscope reordering, switched off in pyproject.toml's addopts
# by --no-loadscope-reorder): the notebooks, six tests, then started 16 minutes into a
# 22-minute run.
# (Files whose tests were since made to compile less: their suite seconds scaled by their
# times alone before and after, measured with an empty compile cache.)
COSTLIEST_FIRST = (
    "test_gradients.py",  # 261 s
    "test_notebooks.py",  # 263
    "test_fsi.py",  # 204
    "test_solver_in_the_loop.py",  # 170
    "test_calibrate.py",  # 130
    "test_rigid.py",  # 126
    "test_solid_validation.py",  # 126
    "test_3d.py",  # 100
    "test_params_used.py",  # 84
    "test_open_boundary.py",  # 80
    "test_readme.py",  # 69
    "test_startup.py",  # 57
    "test_surrogate.py",  # 53
    "test_diffrax.py",  # 52
    "test_validation_fluid.py",  # 52
    "test_fluid_unit.py",  # 48
    "test_dataset.py",  # 43
    "test_cavity.py",  # 39
    "test_stepper.py",  # 39
    "test_solid_second_order.py",  # 31
)


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(COSTLIEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable within a file


@pytest.fixture(autouse=True)
def float64():
    """Every test starts in float64, whatever an earlier test switched, and the setting
    is restored afterwards."""
    previous = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", True)
    yield
    jax.config.update("jax_enable_x64", previous)


# Every program XLA:CPU compiles maps its code into the process in about 20 separate memory
# regions, released only when the program is dropped from JAX's caches.  A test worker runs
# hundreds of test files in one process: it reached Linux's limit of 65530 maps per
# process (vm.max_map_count) near the end of the suite (64916 measured) and died in the
# next mmap (SIGSEGV or SIGABRT, wherever it happened), and pytest-xdist, with whole files
# per worker, then waits forever for the lost worker's files.  So the compiled programs are
# dropped after each test file: a later file that needs one again reads it back from the
# persistent cache above.
MAP_LIMIT = 65530


def _memory_maps() -> int | None:
    try:
        with open("/proc/self/maps") as maps:
            return sum(1 for _ in maps)
    except OSError:  # not Linux
        return None


@pytest.fixture(autouse=True, scope="module")
def compiled_programs_dropped_after_each_file():
    yield
    jax.clear_caches()
    gc.collect()
    maps = _memory_maps()
    if maps is not None and maps > MAP_LIMIT // 2:
        warnings.warn(
            f"this test worker holds {maps} memory maps after clearing JAX's caches "
            f"(the process limit is {MAP_LIMIT}); something keeps compiled programs alive",
            stacklevel=1,
        )


# What the suite spends compiling: each test process adds up the seconds JAX spends
# tracing functions, lowering them and compiling them with XLA (a read from the persistent
# cache counts as compiling: it happens in the same call), and the run ends with the sum
# over the processes beside their wall-clock and CPU time.  Processes the tests start
# themselves (CLI runs, notebook kernels) are not counted.
COMPILE_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "tracing",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lowering",
    "/jax/core/compile/backend_compile_duration": "compiling",
}
_compile_seconds = collections.Counter()
_started = time.perf_counter()
_processes = []  # one summary per test process (the workers', or this one's with -n 0)


def _count_compile_time(event, duration, **kwargs):
    if event in COMPILE_EVENTS:
        _compile_seconds[COMPILE_EVENTS[event]] += duration


jax.monitoring.register_event_duration_secs_listener(_count_compile_time)


# sphjax.native's loops are built with the machine's C++ compiler the first time a test
# needs them (about a minute on 2 cores), under a lock that the other worker waits on too.
# With workers, the controller starts that build in the background when the session
# starts, so that the workers run their first files (the costliest, XLA only) meanwhile.
_native_build: list = []


def pytest_sessionstart(session):
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    from sphjax import native

    if native.compiler() is not None:
        build = [sys.executable, "-c", "from sphjax import native; native.library()"]
        _native_build.append(
            subprocess.Popen(build, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        )


def pytest_unconfigure(config):
    for process in _native_build:
        process.wait()


def pytest_sessionfinish(session):
    summary = {
        "wall": time.perf_counter() - _started,
        "cpu": time.process_time(),
        **_compile_seconds,
    }
    if hasattr(session.config, "workeroutput"):  # a pytest-xdist worker
        session.config.workeroutput["sphjax_compile_time"] = json.dumps(summary)
    elif not getattr(session.config.option, "numprocesses", None):  # no workers: this one
        _processes.append(summary)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    summary = getattr(node, "workeroutput", {}).get("sphjax_compile_time")
    if summary:
        _processes.append(json.loads(summary))


def pytest_terminal_summary(terminalreporter):
    def total(key):
        return sum(process.get(key, 0.0) for process in _processes)

    spent = total("tracing") + total("lowering") + total("compiling")
    if not _processes or not total("wall"):
        return
    terminalreporter.write_line(
        f"JAX compile time in {len(_processes)} test process(es): {spent:.0f} s of their "
        f"{total('wall'):.0f} s wall-clock ({100 * spent / total('wall'):.0f} %; "
        f"tracing {total('tracing'):.0f} s, lowering {total('lowering'):.0f} s, XLA "
        f"{total('compiling'):.0f} s) and {total('cpu'):.0f} CPU-s; processes started by "
        f"the tests not counted"
    )
