"""Test-session setup shared by the core and ROS tests, and the fixtures both use."""

import os
import stat

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
