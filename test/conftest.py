"""Test-session setup shared by the core and ROS tests, and the fixtures both use."""

import itertools
import os
import stat
from collections.abc import Callable
from pathlib import Path

import pytest

from switchobs_core.threads import single_threaded_blas

# One process designs gains (Clarabel) and then runs observers: keep BLAS single-threaded
# (small matrices; see switchobs_core.threads).
single_threaded_blas()


@pytest.fixture
def fifo(tmp_path):
    """A FIFO in tmp (a reader that opens it blocks until a writer comes)."""
    p = tmp_path / "fifo"
    os.mkfifo(p)
    return p


@pytest.fixture
def device(tmp_path):
    """A character device node of our own (/dev/null's numbers) in tmp: never a real device."""
    if os.geteuid() != 0:
        pytest.skip("mknod needs root")
    p = tmp_path / "dev"
    os.mknod(p, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    return p


@pytest.fixture(scope="session")
def run_cache(tmp_path_factory) -> Callable[[str, Callable[[Path], None]], Path]:
    """``run_cache(name, make)``: the folder ``name`` of this test run's cache, made by
    ``make(folder)`` once per run. The pytest-xdist workers of one run share it (their base
    temporary folders have one parent; a lock file makes the others wait for the first), so an
    SDP design that several workers need is solved once. A folder ``make`` failed to fill is
    made again by the next caller."""
    import fcntl
    import shutil

    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent
    root = base / "run-cache"
    root.mkdir(exist_ok=True)

    def cached(name: str, make: Callable[[Path], None]) -> Path:
        folder = root / name
        with open(root / f"{name}.lock", "a") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                if not (folder / ".done").exists():
                    shutil.rmtree(folder, ignore_errors=True)
                    folder.mkdir()
                    make(folder)
                    (folder / ".done").touch()
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)
        return folder
    return cached


# ---- the full run under pytest-xdist (scripts/test.sh: two workers) -------------------------------

#: Tests known to take long, longest first (from ``pytest --durations``): they are handed out
#: first, so that the two workers end together instead of one of them finishing a 2-minute test
#: alone at the end. Only an order: a test missing here just runs in its place.
LONG_FIRST = (
    "test/core/bounds/test_units_audit.py::test_bound_holds_and_says_something[oscillator_si_jitter-kalman-online",
    "test/core/sim/test_simulate.py::test_ten_minutes_without_a_violation[sequence-100.0]",
    "test/ros/test_attribution.py::test_demo_under_load_publishes_no_false_bound",
    "test/core/bounds/test_units_audit.py::test_bound_holds_and_says_something[oscillator_si_jitter-kalman-120s]",
    "test/ros/test_fail_node.py::test_random_stream_over_dds_node_stays_up_every_valid_answered",
    "test/ros/test_fail_inputs.py::test_fuzz_100k_messages_every_valid_one_answered",
    "test/ros/test_own_robot_tutorial.py",
    "test/ros/test_bias_node.py::test_a_bias_over_dds_withdraws_the_bounds_and_they_come_back",
    "test/ros/test_bag_live.py",
    "test/ros/test_colcon_package.py::test_colcon_build_and_ament_index_run",      # builds colcon_workspace
    "test/ros/test_bound_long_bag.py",
    "test/ros/test_tutorial_clone.py::test_own_system_tutorial_from_a_fresh_clone",
    "test/ros/test_consistency.py",
    "test/ros/test_disturbance_node.py",
    "test/core/bounds/test_units_audit.py::test_bound_holds_and_says_something[oscillator_si-kalman-300s]",
    "test/ros/test_fail_node.py",
    "test/ros/test_netns.py",
    "test/ros/test_dds_convergence.py::test_converges_over_dds",
    "test/ros/test_kalman_ros.py",
    "test/core/design/test_precision.py::test_well_posed_designs_accepted[32",
    "test/ros/test_own_clock_stamps.py",
    "test/core/runtime/test_online_sqrt.py::test_long_stiff_run_stays_positive_definite",
    "test/ros/test_refusals_inputs.py",
    "test/ros/test_refusals_node.py",
    "test/ros/test_clock_offsets.py",
    "test/ros/test_recovery_node.py",
    "test/ros/test_fail_faults.py",
    "test/ros/test_control_input.py",
    "test/ros/test_behaviour_preserved.py",
    "test/ros/test_clock_jump.py",
    "test/ros/test_lifecycle.py",
    "test/core/runtime/test_kalman_table_cache.py::test_monte_carlo_every_disturbance",
    "test/core/design/test_conditioning.py",
    "test/core/sim/test_simulate.py::test_ten_minutes_without_a_violation",
    "test/core/bounds/test_audit.py::test_bounds_never_below_the_error",
    "test/ros/test_typed_msgs.py::test_colcon_builds_the_package_in_a_workspace",  # once colcon_workspace is built
    "test/core/bounds/test_units_audit.py",
    "test/ros/test_docs.py::test_site_builds_in_strict_mode",
    "test/ros/test_dead_time_ros.py",
    "test/ros/test_refusals_tools.py",
    "test/core/test_docs_numbers.py::test_docs_block",
    "test/core/runtime/test_observer.py::test_innovation_hold_exact_bound_is_exact_for_samples",
    "test/core/runtime/test_recertify_manoeuvre.py",
    "test/core/numerics/test_rounding.py",
    "test/core/design/test_precision.py",
    "test/ros/test_tool_inputs.py",
    "test/core/runtime/test_kalman_late_start.py",
)


def _long_rank(nodeid: str) -> int:
    for i, prefix in enumerate(LONG_FIRST):
        if nodeid.startswith(prefix):
            return i
    return len(LONG_FIRST)


def pytest_collection_modifyitems(config, items):
    """Under xdist: the long tests first (LONG_FIRST), the ``serial`` ones last (each worker
    collects and sorts alike: the order is a function of the node ids alone).

    ``--dist load`` gives each of the W workers a first chunk of ``n // W // 4`` tests in a row
    (xdist's LoadScheduling), then the rest as they finish. The long tests are dealt out over
    those first chunks (the 1st, (W+1)th, ... long test to the first chunk, the 2nd, (W+2)th, ...
    to the second), so that each worker starts with its share of them instead of the first
    worker getting them all."""
    workerinput = getattr(config, "workerinput", None)
    if workerinput is None:
        return
    order = {item.nodeid: i for i, item in enumerate(items)}
    items.sort(key=lambda it: (it.get_closest_marker("serial") is not None, _long_rank(it.nodeid),
                               order[it.nodeid]))
    workers = int(workerinput.get("workercount", 1))
    if workerinput.get("switchobs_dist") != "load" or workers < 2 or len(items) < 2 * workers:
        return
    chunk = max(min(len(items) // workers // 4, workerinput.get("switchobs_maxschedchunk") or len(items)), 2)
    is_long = [_long_rank(it.nodeid) < len(LONG_FIRST) and it.get_closest_marker("serial") is None
               for it in items]
    long = [it for it, x in zip(items, is_long) if x]
    rest = [it for it, x in zip(items, is_long) if not x]
    shares = [long[w::workers] for w in range(workers)]
    head = []
    for share in shares:
        mine = share[:chunk]
        head += mine + rest[:chunk - len(mine)]
        rest = rest[chunk - len(mine):]
    overflow = [it for group in itertools.zip_longest(*(share[chunk:] for share in shares)) for it in group
                if it is not None]
    items[:] = head + overflow + rest


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """(pytest-xdist, on the controller) The workers learn the distribution mode and chunk limit
    (their own options say ``--dist no``) for pytest_collection_modifyitems."""
    node.workerinput["switchobs_dist"] = node.config.getoption("dist", None)
    node.workerinput["switchobs_maxschedchunk"] = node.config.getoption("maxschedchunk", None)


def _serial_lock_path(uid: str) -> str:
    import tempfile

    return os.path.join(tempfile.gettempdir(), f"switchobs-pytest-serial-{uid}.lock")


def pytest_configure(config):
    """The xdist controller fixes the run's id itself, to remove the run's lock file at the end."""
    if not hasattr(config, "workerinput") and config.getoption("numprocesses", None) \
            and config.getoption("testrunuid", None) is None:
        import uuid

        config.option.testrunuid = uuid.uuid4().hex


def pytest_unconfigure(config):
    uid = config.getoption("testrunuid", None)
    if uid and not hasattr(config, "workerinput"):
        try:
            os.remove(_serial_lock_path(uid))
        except FileNotFoundError:
            pass


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Under xdist, a ``serial`` test (a timed run over DDS whose numbers depend on the CPU it
    gets) runs alone: it takes this run's lock file exclusively, every other test shares it, so
    the other worker waits between two tests while a serial one runs."""
    uid = getattr(item.config, "workerinput", {}).get("testrunuid")
    if not uid:
        yield
        return
    path = _serial_lock_path(uid)
    import fcntl

    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX if item.get_closest_marker("serial") else fcntl.LOCK_SH)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)
