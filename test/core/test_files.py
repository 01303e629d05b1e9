"""File checks (switchobs_core.files): a FIFO, a device or a directory is refused before it
is read or replaced; sizes are limited; write errors (a full disk) are one line."""

from __future__ import annotations

import errno
import os
import stat
import time

import pytest

from switchobs_core import files
from switchobs_core.exceptions import GainTableError, InvalidArgument, InvalidSystem
from switchobs_core.loading import load_yaml, read_text
from switchobs_core.table.gains import GainTable


def test_reading_a_fifo_is_refused_without_blocking(fifo):
    t0 = time.monotonic()
    with pytest.raises(GainTableError, match=r"gain table .*fifo is a FIFO \(named pipe\), not a regular file"):
        GainTable.load(fifo)
    with pytest.raises(InvalidSystem, match="is a FIFO"):
        load_yaml(fifo, exc=InvalidSystem, what="system file")
    assert time.monotonic() - t0 < 2


def test_reading_a_directory_or_device_is_refused(tmp_path, device):
    with pytest.raises(InvalidArgument, match="is a directory, not a regular file"):
        read_text(tmp_path, exc=InvalidArgument, what="params file")
    with pytest.raises(InvalidArgument, match="is a character device, not a regular file"):
        read_text(device, exc=InvalidArgument, what="params file")


def test_size_limit_before_reading(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_bytes(b" " * (2 << 20))
    with pytest.raises(InvalidArgument, match=r"larger than 1 MiB \(2 MiB; the limit"):
        files.check_input(big, "metadata", max_bytes=1 << 20)
    with pytest.raises(FileNotFoundError):
        files.check_input(tmp_path / "nope", "x")


def test_outputs_never_replace_a_directory_fifo_or_device(tmp_path, fifo, device, paper_table):
    for target, kind in ((tmp_path, "a directory"), (fifo, r"a FIFO \(named pipe\)"), (device, "a character device")):
        with pytest.raises(GainTableError, match=f"is {kind}: refusing to replace it"):
            paper_table.save(target)
        assert not stat.S_ISREG(os.stat(target).st_mode)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert stat.S_ISCHR(os.stat(device).st_mode)


def test_atomic_save_writes_its_temporary_file_beside_the_target(tmp_path, paper_table, monkeypatch):
    made = []
    real_open = os.open

    def spy(path, flags, *a):
        made.append(str(path))
        return real_open(path, flags, *a)

    monkeypatch.setattr(os, "open", spy)
    paper_table.save(tmp_path / "sub" / "t.json")
    assert made and all(os.path.dirname(p) == str(tmp_path / "sub") for p in made), made


def test_write_with_a_full_disk_is_one_line(tmp_path):
    def full(path):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(InvalidArgument, match=r"^cannot write --plot .*x.png: No space left on device$"):
        files.write_with(tmp_path / "x.png", "--plot", full)


def test_check_private(tmp_path):
    d = tmp_path / "cache"
    d.mkdir(mode=0o700)
    files.check_private(d, "cache")
    os.chmod(d, 0o777)
    with pytest.raises(InvalidArgument, match=r"bad permissions: cache .* writable by group and others \(mode 0777\)"):
        files.check_private(d, "cache")
    os.chmod(d, 0o720)
    with pytest.raises(InvalidArgument, match="writable by the group"):
        files.check_private(d, "cache")
    if os.geteuid() == 0:
        os.chmod(d, 0o700)
        os.chown(d, 12345, -1)
        with pytest.raises(InvalidArgument, match=r"owned by another user \(uid 12345\)"):
            files.check_private(d, "cache")
