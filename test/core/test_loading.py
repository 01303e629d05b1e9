"""Every bad file a tool reads gives one line on stderr and exit code 2: no traceback, no hang.

The cases of docs/failures.md, "Tools: bad files", through ``switchobs`` in process, plus hypothesis fuzz
of the system-YAML and gain-table loaders (random bytes and mutations of a valid file).
"""

from __future__ import annotations

import json
import os
import stat
import time
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from switchobs_core.cli import main
from switchobs_core.design.lmi import design_table
from switchobs_core.exceptions import GainTableError, InvalidSystem, SwitchobsError
from switchobs_core.loading import MAX_DEPTH, MAX_YAML_BYTES, check_depth, json_depth, parse_json, parse_yaml
from switchobs_core.model.scenarios import load_noise, load_system, paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.model.system import LTISystem
from switchobs_core.table.gains import GainTable

TINY = {
    "name": "tiny",
    "A": [[0.0, 1.0], [-1.0, -0.5]],
    "channels": [{"name": "position", "C": [[1.0, 0.0]]}, {"name": "velocity", "C": [[0.0, 1.0]]}],
}

#: A 377-byte "billion laughs": 10 levels of 9 aliases, 9^9 = 387 million strings if expanded.
ALIAS_BOMB = 'a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]\n' + "".join(
    f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]\n" for p, c in zip("abcdefghi", "bcdefghij")
)


@pytest.fixture(scope="module")
def tiny_table_path(tmp_path_factory):
    """A small valid LMI gain table (the two-state system TINY, one cycle) and its system file."""
    d = tmp_path_factory.mktemp("tables")
    system = LTISystem.from_dict(TINY)
    path = design_table(system, cycles=[Cycle.from_ts(2.0, 0.6)], progress=False).save(d / "tiny.json")
    (d / "tiny.yaml").write_text(yaml.safe_dump(TINY))
    return path


def _run(argv, capsys):
    """``switchobs ARGV`` in process: (exit code, stderr); the caller asserts what it says."""
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    return rc, err


def _one_line_exit_2(rc, err, *needles):
    assert rc == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], lines[0]
    return lines[0]


def _design_argv(cfg, tmp_path):
    return ["design", cfg, "--cycle", "2,0.6", "-o", tmp_path / "out.json"]


def _tiny_yaml(tmp_path, text):
    p = tmp_path / "system.yaml"
    p.write_text(text) if isinstance(text, str) else p.write_bytes(text)
    return p


# --------------------------------------------------------------------------- system YAML


def test_system_yaml_binary_garbage(tmp_path, capsys):
    cfg = _tiny_yaml(tmp_path, bytes(range(256)) * 4)
    line = _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "not UTF-8", str(cfg))
    assert "byte 0x80 at line 2, column 118" in line  # the first byte >= 0x80, after the 0x0a at index 10


@pytest.mark.parametrize("text", [
    "A: " + "[" * 100_000 + "]" * 100_000 + "\n",
    "A: " + "{a: " * 100_000 + "1" + "}" * 100_000 + "\n",
    "".join("  " * i + f"k{i}:\n" for i in range(200)) + "  " * 200 + "1\n",
    "".join("  " * i + "-\n" for i in range(200)) + "  " * 200 + "1\n",
], ids=["flow_lists", "flow_mappings", "block_mappings", "block_lists"])
def test_system_yaml_deeply_nested(tmp_path, capsys, text):
    cfg = _tiny_yaml(tmp_path, text)
    t0 = time.perf_counter()
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), f"nested deeper than {MAX_DEPTH} levels")
    assert time.perf_counter() - t0 < 1.0


def test_system_yaml_entry_too_large(tmp_path, capsys):
    cfg = _tiny_yaml(tmp_path, yaml.safe_dump(TINY).replace("-0.5", "1.0e+300"))
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "A row 2, column 2", "beyond the supported",
                     "1e+12")


def test_system_yaml_alias_bomb(tmp_path, capsys):
    cfg = _tiny_yaml(tmp_path, ALIAS_BOMB)
    assert len(ALIAS_BOMB) < 1024
    t0 = time.perf_counter()
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "anchors (&a) are not allowed", "line 1")
    assert time.perf_counter() - t0 < 0.5
    cfg.write_text("A: [[1.0]]\nB: *x\n")
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "line 2: YAML aliases (*x) are not allowed")


def test_system_yaml_boolean_entry(tmp_path, capsys):
    spec = json.loads(json.dumps(TINY))
    spec["A"][0][0] = True
    cfg = _tiny_yaml(tmp_path, yaml.safe_dump(spec))
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "A row 1, column 1 must be a number",
                     "boolean true")
    spec = json.loads(json.dumps(TINY))
    spec["channels"][1]["C"] = [[False, 1.0]]
    cfg.write_text(yaml.safe_dump(spec))
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "channels[1].C row 1, column 1", "boolean false")


def test_system_yaml_duplicate_channel_names(tmp_path, capsys):
    spec = json.loads(json.dumps(TINY))
    spec["channels"][1]["name"] = "position"
    cfg = _tiny_yaml(tmp_path, yaml.safe_dump(spec))
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "channel names must be distinct", "'position'")


def test_system_yaml_duplicate_key(tmp_path, capsys):
    cfg = _tiny_yaml(tmp_path, yaml.safe_dump(TINY) + "A: [[1.0]]\n")
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "duplicate key 'A'")


def test_system_yaml_too_large(tmp_path, capsys):
    cfg = _tiny_yaml(tmp_path, yaml.safe_dump(TINY) + "#" * MAX_YAML_BYTES + "\n")
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "larger than 1 MiB")


def test_scenario_file_bounded(tmp_path, capsys):
    cfg = _tiny_yaml(tmp_path, "scenario: camera_agents\nagents: 1000000000\n")
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "at most 200 agents", str(cfg))
    cfg.write_text("scenario: camera_agents\nagents: true\n")
    _one_line_exit_2(*_run(_design_argv(cfg, tmp_path), capsys), "agents must be a whole number")


def test_noise_section_read_through_the_same_loader(tmp_path):
    cfg = _tiny_yaml(tmp_path, yaml.safe_dump(TINY) + "noise:\n  measurement_std: 0.01\n  P0: 1.0\n")
    system = load_system(cfg)
    assert load_noise(cfg, system).P0[0, 0] == 1.0
    cfg.write_text(cfg.read_text() + "  P0: 2.0\n")
    with pytest.raises(InvalidSystem, match="duplicate key 'P0'"):
        load_noise(cfg, system)


# --------------------------------------------------------------------------- gain tables


def test_gain_table_nested_deep(tmp_path, capsys, tiny_table_path):
    bad = tmp_path / "deep.json"
    bad.write_text("[" * 100_000 + "]" * 100_000)
    _one_line_exit_2(*_run(["show", bad], capsys), f"nested deeper than {MAX_DEPTH} levels", str(bad))
    # nested inside a valid table (checksum recomputed), within the decoder's recursion limit
    data = json.loads(tiny_table_path.read_text())
    data.pop("payload_sha256")
    data["settings"]["x"] = json.loads("[" * 500 + "]" * 500)
    data["payload_sha256"] = GainTable._digest(data)
    bad.write_text(json.dumps(data))
    _one_line_exit_2(*_run(["show", bad], capsys), f"nested deeper than {MAX_DEPTH} levels")


def test_gain_table_nested_deep_estimator(tmp_path):
    """The estimator's start-up path (gain_table parameter) refuses it with one ConfigError line."""
    core_config = pytest.importorskip("switchobs_ros.core_config")
    from switchobs_ros.params import ConfigError

    bad = tmp_path / "deep.json"
    bad.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises((ConfigError, GainTableError)) as e:
        core_config.load_or_design_table(str(bad), str(tmp_path), paper_system(), "periodic",
                                         [Cycle.from_ts(2.0, 0.6)], None, 0.99, print)
    assert "nested deeper" in str(e.value) and "\n" not in str(e.value)


def test_gain_table_missing_checksum(tmp_path, capsys, tiny_table_path):
    data = json.loads(tiny_table_path.read_text())
    del data["payload_sha256"]
    bad = tmp_path / "nosum.json"
    bad.write_text(json.dumps(data))
    line = _one_line_exit_2(*_run(["show", bad], capsys), "checksum (payload_sha256) is missing")
    assert "mismatch" not in line


def test_gain_table_binary_garbage(tmp_path, capsys):
    bad = tmp_path / "bin.json"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    _one_line_exit_2(*_run(["show", bad], capsys), "not UTF-8", "gain table")


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_gain_table_written_with_open_mode(tmp_path, tiny_table_path, umask, mode):
    """Gain tables (and so the estimator's design cache, which saves through GainTable.save) get
    the mode a plain open() gives, not tempfile's 0600: a service of another user can read them."""
    table = GainTable.load(tiny_table_path)
    old = os.umask(umask)
    try:
        path = table.save(tmp_path / "sub" / "g.json")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == mode
    assert not [p for p in path.parent.iterdir() if p.name.startswith(".")]  # no temporary left
    assert GainTable.load(path).fingerprint == table.fingerprint


# --------------------------------------------------------------------------- params files


def test_params_file_alias_bomb_and_garbage(tmp_path):
    config = pytest.importorskip("switchobs_ros.config")
    from switchobs_ros.params import ConfigError

    f = tmp_path / "params.yaml"
    f.write_text("estimator:\n  ros__parameters:\n" + "".join("    " + ln + "\n" for ln in ALIAS_BOMB.splitlines()))
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match="params file .*anchors"):
        config.params_from_file([f])
    assert time.perf_counter() - t0 < 0.5
    f.write_bytes(b"\xff\xfe" * 100)
    with pytest.raises(ConfigError, match="not UTF-8"):
        config.params_from_file([f])
    with pytest.raises(ConfigError, match="does not exist"):
        config.params_from_file([tmp_path / "nope.yaml"])


# --------------------------------------------------------------------------- fuzz

FUZZ = settings(max_examples=int(os.environ.get("FUZZN", 200)), deadline=2000, derandomize=not os.environ.get("FUZZN"),
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

_json_leaf = st.one_of(st.none(), st.booleans(), st.integers(-10**30, 10**30), st.floats(allow_nan=False),
                       st.text(max_size=8))
_json_value = st.recursive(_json_leaf, lambda c: st.one_of(st.lists(c, max_size=3),
                                                          st.dictionaries(st.text(max_size=4), c, max_size=3)),
                           max_leaves=6)


def _mutate(tree, data):
    """Replace, delete or wrap one node of a JSON-like tree, chosen by a random walk."""
    node, parent, key = tree, None, None
    while isinstance(node, (dict, list)) and node and data.draw(st.integers(0, 3)) > 0:
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        parent, key = node, data.draw(st.sampled_from(keys))
        node = node[key]
    what = data.draw(st.sampled_from(["replace", "delete", "wrap", "duplicate"]))
    if parent is None:
        return data.draw(_json_value)
    if what == "delete":
        del parent[key]
    elif what == "wrap":
        parent[key] = [node]
    elif what == "duplicate" and isinstance(parent, list):
        parent.append(node)
    else:
        parent[key] = data.draw(_json_value)
    return tree


def _assert_refused_in_one_line(err):
    assert isinstance(err, SwitchobsError), repr(err)
    assert len(str(err).strip().splitlines()) == 1, str(err)


@FUZZ
@given(raw=st.binary(max_size=300))
def test_fuzz_system_yaml_random_bytes(tmp_path, raw):
    cfg = tmp_path / "fuzz.yaml"
    cfg.write_bytes(raw)
    try:
        load_system(cfg)
    except SwitchobsError as err:
        _assert_refused_in_one_line(err)


@FUZZ
@given(data=st.data(), base=st.sampled_from(["tiny", "paper", "scenario"]), as_text=st.booleans())
def test_fuzz_system_yaml_mutations(tmp_path, data, base, as_text):
    spec = {"tiny": TINY, "paper": paper_system().to_dict(),
            "scenario": {"scenario": "camera_agents", "agents": 3, "D_agents": [[0, 0.2], [0, 0.1], [0, 0.3]],
                         "noise": {"measurement_std": 0.001, "P0": 10.0}}}[base]
    spec = _mutate(json.loads(json.dumps(spec)), data)
    text = yaml.safe_dump(spec)
    if as_text:  # a few characters of YAML syntax spliced in
        pos = data.draw(st.integers(0, len(text)))
        text = text[:pos] + data.draw(st.text(alphabet="[]{}:-&*!|>'\"#, \n\t0e.x", max_size=6)) + text[pos:]
    cfg = tmp_path / "fuzz.yaml"
    cfg.write_text(text)
    try:
        system = load_system(cfg)
        load_noise(cfg, system)
    except SwitchobsError as err:
        _assert_refused_in_one_line(err)


@FUZZ
@given(raw=st.binary(max_size=300))
def test_fuzz_gain_table_random_bytes(tmp_path, raw):
    f = tmp_path / "fuzz.json"
    f.write_bytes(raw)
    with pytest.raises(GainTableError) as e:
        GainTable.load(f)
    _assert_refused_in_one_line(e.value)


@FUZZ
@given(data=st.data(), resum=st.booleans())
def test_fuzz_gain_table_mutations(tmp_path, tiny_table_path, capsys, data, resum):
    """A mutated table, its checksum recomputed (so the checks behind it are reached) or not: it
    loads or is refused in one line; one that loads is shown, or refused in one line, by
    ``switchobs show`` with and without ``--system``."""
    tree = json.loads(tiny_table_path.read_text())
    tree = _mutate(tree, data)
    if resum and isinstance(tree, dict):
        tree.pop("payload_sha256", None)
        tree["payload_sha256"] = GainTable._digest(tree)
    f = tmp_path / "fuzz.json"
    f.write_text(json.dumps(tree))
    try:
        GainTable.load(f)
    except SwitchobsError as err:
        _assert_refused_in_one_line(err)
        return
    capsys.readouterr()
    for argv in (["show", f], ["show", f, "--json"], ["show", f, "--system", tiny_table_path.with_suffix(".yaml")]):
        rc, err = _run(argv, capsys)
        assert rc in (0, 2) and "Traceback" not in err
        if rc == 2:
            assert len(err.strip().splitlines()) == 1


def test_strict_yaml_accepts_what_the_configs_use():
    """The strict loader reads every YAML file of the repository like yaml.safe_load."""
    root = Path(__file__).resolve().parents[2]
    files = sorted(root.glob("config/*.yaml")) + sorted(root.glob("test/**/*.yaml"))
    assert files
    for f in files:
        assert parse_yaml(f.read_text(), exc=InvalidSystem, source=str(f)) == yaml.safe_load(f.read_text())


# --------------------------------------------------------------------------- JSON nesting from the text

#: Strings that look like JSON structure: brackets, quotes and backslashes escaped, non-ASCII text.
_TRICKY_TEXT = st.text(alphabet=st.sampled_from(list('[]{}"\\,:ab é\u2603\n\t')), max_size=8)
_JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-10, 10) | st.floats(allow_nan=False, allow_infinity=False) | _TRICKY_TEXT,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_TRICKY_TEXT, inner, max_size=4),
    max_leaves=40)


def _walked_depth(value) -> int:
    """The nesting check_depth finds: the least limit it passes."""
    for limit in range(0, 200):
        try:
            check_depth(value, exc=SwitchobsError, source="x", limit=limit)
            return limit
        except SwitchobsError:
            pass
    raise AssertionError("deeper than 200")


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(value=_JSON_VALUES, indent=st.sampled_from([None, 0, 2]), ascii_only=st.booleans())
def test_json_depth_of_the_text_is_the_walked_depth(value, indent, ascii_only):
    """The depth read from the text (parse_json's check) equals the parsed value's, whatever its
    strings hold (brackets, quotes, escapes, non-ASCII) and however it is laid out."""
    text = json.dumps(value, indent=indent, ensure_ascii=ascii_only)
    assert json_depth(text) == _walked_depth(json.loads(text))


def test_json_depth_without_a_backslash_skips_the_literals_by_their_quotes():
    """Text without an escape (split at its quotes) and the same value with one (the expression): brackets
    inside literals never count, either way."""
    plain = '["[[[", {"a": "]]]]", "{": [1, "}}"]}]'
    assert json_depth(plain) == 3 == _walked_depth(json.loads(plain))
    escaped = '["\\"[[[", {"a": "]]]]", "{": [1, "}}"]}]'
    assert json_depth(escaped) == 3 == _walked_depth(json.loads(escaped))
    assert json_depth('"[[["') == 0 and json_depth("[]") == 1


def test_parse_json_refuses_one_level_too_deep_and_reads_brackets_in_strings():
    ok = "[" * MAX_DEPTH + '"]]]{{{"' + "]" * MAX_DEPTH
    assert parse_json(ok, exc=GainTableError, source="t")
    too_deep = "[" * (MAX_DEPTH + 1) + "1" + "]" * (MAX_DEPTH + 1)
    with pytest.raises(GainTableError, match=f"nested deeper than {MAX_DEPTH} levels"):
        parse_json(too_deep, exc=GainTableError, source="t")
    hidden = '{"a": "\\"[[[[", "b": ' + "[" * MAX_DEPTH + "]" * MAX_DEPTH + "}"     # an escaped quote, then brackets
    with pytest.raises(GainTableError, match="nested deeper"):
        parse_json(hidden, exc=GainTableError, source="t")
