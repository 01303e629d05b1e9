"""Bad files to the tools (issue: every bad input gets one clear line): each case of the issue
through the CLI (exit 2, one line on stderr, no traceback), and a fuzz test of the system-YAML and
gain-table loaders under a time and memory budget per case."""

from __future__ import annotations

import json
import os
import stat
import time
import tracemalloc

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from switchobs_core.cli import main
from switchobs_core.design import design_table
from switchobs_core.exceptions import InvalidSystem, SwitchobsError
from switchobs_core.gains import GainTable
from switchobs_core.loading import MAX_DEPTH
from switchobs_core.scenarios import load_system
from switchobs_core.schedule import Cycle
from switchobs_core.system import LTISystem

SMALL = {"name": "pair", "A": [[0, 1], [0, 0]], "B": [[0], [1]],
         "channels": [{"name": "pos", "C": [[1, 0]]}, {"name": "vel", "C": [[0, 1]]}]}


@pytest.fixture(scope="module")
def table_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("loading") / "gains.json"
    sys_ = LTISystem.from_dict(SMALL)
    design_table(sys_, cycles=[Cycle.from_ts(2.0, 0.5)], delta=0.99, progress=False).save(path)
    return path


def _one_line_error(argv, capsys, *needles):
    t0 = time.perf_counter()
    rc = main(argv)
    dt = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert rc == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in err, (n, err)
    return err, dt


ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
    for p, c in zip("abcdefgh", "bcdefghi"))


@pytest.mark.parametrize("name, content, needles", [
    ("binary.yaml", b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe", ("not UTF-8", "offset")),
    ("deep_list.yaml", ("A: " + "[" * 100_000 + "]" * 100_000).encode(), ("nested deeper",)),
    ("deep_map.yaml", ("".join("  " * i + f"k{i}:\n" for i in range(200)) + "  " * 200 + "v: 1\n").encode(),
     ("nested deeper",)),
    ("huge.yaml", yaml.safe_dump({**SMALL, "A": [[0, 1e300], [0, 0]]}).encode(), ("A[0][1]", "1e+12")),
    ("bool.yaml", yaml.safe_dump({**SMALL, "A": [[0, True], [0, 0]]}).encode(), ("A[0][1]", "must be a number")),
    ("dup.yaml", yaml.safe_dump({**SMALL, "channels": [{"name": "cam", "C": [[1, 0]]},
                                                       {"name": "cam", "C": [[0, 1]]}]}).encode(),
     ("duplicate channel name 'cam'",)),
    ("dupkey.yaml", b"A: [[0, 1], [0, 0]]\nA: [[0, 0], [0, 0]]\nchannels: []\n", ("duplicate key 'A'", "line 2")),
    ("bomb.yaml", ALIAS_BOMB.encode(), ("anchors and aliases", "line 1")),
])
def test_bad_system_file_is_one_line(tmp_path, capsys, table_file, name, content, needles):
    """Each bad system file of the issue: exit 2, one line naming the problem, in well under a second
    (the alias bomb took 50 s and 2.5 GB before; the deep nesting ended in RecursionError)."""
    path = tmp_path / name
    path.write_bytes(content)
    _, dt = _one_line_error(["show", str(table_file), "--system", str(path)], capsys, str(path), *needles)
    assert dt < 2.0


def test_gain_table_nested_deep_and_missing_checksum(tmp_path, capsys, table_file):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    _one_line_error(["show", str(deep)], capsys, "nested deeper")
    data = json.loads(table_file.read_text())
    del data["payload_sha256"]
    nosum = tmp_path / "nosum.json"
    nosum.write_text(json.dumps(data))
    _one_line_error(["show", str(nosum)], capsys, "checksum (payload_sha256) is missing")
    garbage = tmp_path / "garbage.json"
    garbage.write_bytes(b"\xff\xfe\x00binary")
    _one_line_error(["show", str(garbage)], capsys, "not UTF-8")


def test_tables_are_written_readable_by_other_users(tmp_path, table_file):
    """A service running as another user reads the table: mode 0666 less the umask (was 0600)."""
    out = GainTable.load(table_file).save(tmp_path / "copy.json")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~umask
    assert stat.S_IMODE(out.stat().st_mode) & stat.S_IROTH or umask & 0o004


def _check_one_line(err: Exception) -> None:
    assert isinstance(err, SwitchobsError)
    assert len(str(err).splitlines()) == 1


def _budgeted(fn):
    """Run fn under tracemalloc: at most 1 s and 50 MB per case."""
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        fn()
    except SwitchobsError as err:
        _check_one_line(err)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - t0 < 1.0 and peak < 50 * 2**20


VALID_YAML = yaml.safe_dump(SMALL)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.one_of(
    st.binary(max_size=400),
    st.tuples(st.integers(0, len(VALID_YAML)), st.integers(0, 40), st.binary(max_size=20)).map(
        lambda m: VALID_YAML.encode()[:m[0]] + m[2] + VALID_YAML.encode()[m[0] + m[1]:]),
    st.text(alphabet="[]{}&*:-, \nab01", max_size=300).map(str.encode),
))
def test_fuzz_system_loader(tmp_path, data):
    """Random bytes, structured mutations of a valid file and YAML-syntax soup: the loader returns a
    system or raises the project's error with one line, within 1 s and 50 MB."""
    path = tmp_path / "fuzz.yaml"
    path.write_bytes(data)
    _budgeted(lambda: load_system(path))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, 10_000), junk=st.binary(max_size=30), depth=st.integers(0, 3 * MAX_DEPTH))
def test_fuzz_gain_table_loader(table_file, cut, junk, depth):
    """Mutations of a valid gain table (a splice of junk, a wrapping in deep brackets): a table (the
    mutation was harmless) or a one-line GainTableError within the budget, never another exception."""
    text = table_file.read_text()
    cut %= len(text)
    mutated = "[" * depth + text[:cut] + junk.decode("utf-8", "replace") + text[cut + 1:] + "]" * depth

    _budgeted(lambda: GainTable.from_json(mutated, source="fuzz.json"))    # a table (e.g. a space cut) or one line


def test_valid_system_still_loads(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text(VALID_YAML)
    assert load_system(path).channel_names == ("pos", "vel")
    with pytest.raises(InvalidSystem, match="must be a number"):
        LTISystem.from_dict({**SMALL, "A": [[0, "x"], [0, 0]]})
