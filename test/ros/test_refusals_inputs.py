"""Refusals of bad input by the tools and the estimator: huge input specifications, topic names ROS
refuses, binary tables whose members lie, bags with nothing to estimate, channels no source feeds,
a gain-table cache reached through links or that cannot be written. Every refusal is one line and
a non-zero exit within 30 s and 4 GB of address space (test/ros/refusals.py); an accepted input
keeps the good data."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import yaml
from refusals import assert_refused, run, switchobs_bag

from tools.launch import ros_args


def _inputs_file(path, section) -> str:
    path.write_text(yaml.safe_dump({"inputs": section}, default_flow_style=True, width=1 << 30))
    return str(path)


def _label(k: int) -> str:
    digits = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
    return "".join(digits[(k // 52 ** i) % 52] for i in range(3))


# ------------------------------------------------------------------ input specifications
@pytest.mark.parametrize("case, needle", [
    ("labels_100k", "100000 fields; at most 4096"),
    ("sources_9k", "9000 sources; the system's channels have 8 rows in all, so at most 8 sources"),
])
def test_huge_specifications_are_one_line_in_the_tool_and_the_node(case, needle, bag, tmp_path, paper_tables):
    """A 0.9 MB specification (100 000 labels and rows in one labelled array; 9 000 sources): the
    tool and the node refuse it in one line, their checks linear in its size (what time they take
    is reading the YAML), and the node stops on SIGTERM."""
    if case == "labels_100k":
        section = {"channel_topic": "camera/active_channel", "sources": [
            {"topic": "t", "type": "std_msgs/Float64MultiArray", "fields": [_label(k) for k in range(100_000)],
             "rows": [0] * 100_000}]}
    else:
        section = {"channel_topic": "camera/active_channel", "sources": [
            {"topic": f"s{k}", "type": "geometry_msgs/PoseStamped", "fields": ["pose.position.x"], "rows": [0]}
            for k in range(9_000)]}
    spec = _inputs_file(tmp_path / "inputs.yaml", section)
    assert (tmp_path / "inputs.yaml").stat().st_size < 1 << 20
    t0 = time.monotonic()
    res = switchobs_bag("estimate", bag, "--csv", tmp_path / "e.csv", "--gain-table", paper_tables["periodic"],
                        "-p", f"inputs:={spec}")
    assert_refused(res, needle, code=2)
    assert time.monotonic() - t0 < 15
    res = run("switchobs_ros.estimator", *ros_args(params={"gain_table": paper_tables["periodic"], "inputs": spec}))
    assert_refused(res, "estimator: error:", needle, code=2)


def test_a_topic_name_ros_refuses_is_refused_at_start_up(paper_tables, tmp_path):
    """A 5 000-character topic name passed the specification's check, then create_subscription
    raised InvalidTopicNameException (35 lines)."""
    spec = _inputs_file(tmp_path / "inputs.yaml", {"channel_topic": "c" * 5000, "sources": [
        {"topic": "camera/pose", "type": "geometry_msgs/PoseStamped", "fields": ["pose.position.x", "pose.position.y"],
         "rows": ["camera.p_x", "camera.p_y"]},
        {"topic": "target/pose", "type": "geometry_msgs/PoseStamped", "fields": ["pose.position.x", "pose.position.y"],
         "rows": [2, 3]}]})
    res = run("switchobs_ros.estimator", *ros_args(params={"gain_table": paper_tables["periodic"], "inputs": spec}))
    assert_refused(res, "estimator: error:", "channel_topic", "(5000 characters) is not a valid topic name",
                   "topic length should not exceed", code=2)
    # 240 characters: a valid name at the root, too long once the node's namespace is prepended
    spec = _inputs_file(tmp_path / "inputs240.yaml", {"channel_topic": "c" * 240, "sources": [
        {"topic": "camera/pose", "type": "geometry_msgs/PoseStamped", "fields": ["pose.position.x", "pose.position.y"],
         "rows": ["camera.p_x", "camera.p_y"]},
        {"topic": "target/pose", "type": "geometry_msgs/PoseStamped", "fields": ["pose.position.x", "pose.position.y"],
         "rows": [2, 3]}]})
    res = run("switchobs_ros.estimator", *ros_args(params={"gain_table": paper_tables["periodic"], "inputs": spec}),
              "-r", "__ns:=/robot_one")
    assert_refused(res, "estimator: error:", "in namespace /robot_one", "topic length should not exceed", code=2)


# ------------------------------------------------------------------ binary gain tables
@pytest.fixture(scope="module")
def lying_table(tmp_path_factory):
    """A Kalman table of the paper's system (.npz) whose error transition's .npy header claims
    2^33 doubles (64 GiB), in a DEFLATE member."""
    from _binary_tables import lying_member

    from switchobs_core.design.kalman import design_kalman
    from switchobs_core.model.scenarios import paper_system
    from switchobs_core.model.schedule import Cycle
    from switchobs_core.table.gains import kalman_table

    d = tmp_path_factory.mktemp("tables")
    sys_ = paper_system()
    saved = kalman_table(sys_, [design_kalman(sys_, Cycle.from_ts(2.0, 0.6), 20.0)]).save(d / "k.npz")
    bad = d / "lying.npz"
    bad.write_bytes(lying_member(saved, "k0_E.npy"))
    return bad


def test_a_binary_table_whose_member_lies_is_one_line_everywhere(lying_table, bag, tmp_path):
    """`switchobs show`, `switchobs_bag estimate --gain-table` and the estimator's start-up died
    with a 26-line traceback (Unable to allocate 64.0 GiB)."""
    from refusals import switchobs

    needles = ("not a complete binary gain table", "k0_E: its .npy header claims 68719476736 bytes")
    assert_refused(switchobs("show", lying_table), *needles, code=2)
    res = switchobs_bag("estimate", bag, "--csv", tmp_path / "e.csv", "--gain-table", lying_table)
    assert_refused(res, *needles, code=2)
    res = run("switchobs_ros.estimator", *ros_args(params={"gain_table": str(lying_table)}))
    assert_refused(res, "estimator: error:", "gain_table", *needles, code=2)


# ------------------------------------------------------------------ nothing estimated, channels never fed
CART = str(Path(__file__).resolve().parents[2] / "config" / "cart_pair.yaml")


def _copy_bag(src, dst, *, drop=(), keep=None, edit=None) -> Path:
    """A copy of bag ``src`` (file order, log times kept) without the messages of ``drop``, only the
    topics of ``keep`` (None: all), ``edit(message) -> bytes | None`` applied to each message."""
    from switchobs_ros.bag.io import BagIn, BagOut

    with BagIn(src) as b:
        msgs, topics = b.messages(order="file"), dict(b.topics)
    with BagOut(dst, "mcap") as out:
        for t, ty in topics.items():
            if keep is None or t in keep:
                out.add(t, ty)
        for m in msgs:
            if m.topic in drop or (keep is not None and m.topic not in keep):
                continue
            data = m.data if edit is None else edit(m)
            if data is not None:
                out.write(m.topic, m.log_ns, data)
    return dst


@pytest.fixture(scope="module")
def cart_bag(run_cache):
    """A cart_pair bag (3 s at 20 Hz) by the tool, made once per test run (the workers share it) and only read."""
    def make(d):
        res = switchobs_bag("generate", d / "cart", "--system", CART, "--duration", "3", "--rate", "20")
        assert res.returncode == 0, res.stderr
    return run_cache("cart_bag", make) / "cart"


def test_nothing_estimated_is_a_non_zero_exit_for_any_system(bag, cart_bag, tmp_path, paper_tables):
    """Nothing to estimate, for any system: a channel topic with 0 messages, a cart_pair bag whose
    point topics are empty, a channel topic whose every message is invalid: one line naming why,
    exit 2."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import UInt8

    table = ["--gain-table", paper_tables["periodic"]]
    no_channel = _copy_bag(bag, tmp_path / "no_channel", drop={"/camera/active_channel"})
    res = switchobs_bag("estimate", no_channel, "--csv", tmp_path / "a.csv", *table)
    assert_refused(res, "channel topic /camera/active_channel holds no messages",
                   "/camera/pose, /target/pose need their channel", "nothing to estimate", code=2)
    empty = _copy_bag(cart_bag, tmp_path / "cart_empty", drop={"/left/point", "/right/point"})
    res = switchobs_bag("estimate", empty, "--csv", tmp_path / "b.csv", "--system", CART)
    assert_refused(res, "topics /left/point and /right/point hold no messages", "nothing to estimate", code=2)
    bad = serialize_message(UInt8(data=7))
    invalid = _copy_bag(bag, tmp_path / "invalid",
                        edit=lambda m: bad if m.topic == "/camera/active_channel" else m.data)
    res = switchobs_bag("estimate", invalid, "--csv", tmp_path / "c.csv", *table)
    line = assert_refused(res, "no estimate:", "every input message was rejected", code=2)
    assert "camera/active_channel bad_channel 41" in line and "target/pose no_channel 41" in line, line
    only_clock = _copy_bag(bag, tmp_path / "only_clock", keep={"/clock"})
    res = switchobs_bag("estimate", only_clock, "--csv", tmp_path / "d.csv", *table)
    assert_refused(res, "topic /camera/pose is missing", code=2)


def test_a_channel_no_source_feeds_is_reported(cart_bag, tmp_path):
    """cart_pair read with a source for channel 1 only: accepted, and the channel no source feeds
    is reported (the docs promise it "is reported, not refused"): the tool warns on stderr and in
    --json; the node logs it at start-up."""
    import json

    from switchobs_ros.counters import PipelineLog
    from switchobs_ros.pipeline import EstimatorPipeline

    spec = _inputs_file(tmp_path / "left.yaml", {"sources": [
        {"topic": "left/point", "type": "geometry_msgs/PointStamped", "channel": 1, "fields": ["point.x"],
         "rows": [0]}]})
    res = switchobs_bag("estimate", cart_bag, "--csv", tmp_path / "e.csv", "--system", CART, "-p", f"inputs:={spec}",
                        "--json")
    assert res.returncode == 0, res.stderr
    warn = res.stderr.strip().splitlines()
    assert len(warn) == 1 and warn[0].startswith("switchobs_bag: warning: no source feeds channel 2 "), warn
    assert json.loads(res.stdout)["uncovered_channels"] == [2]

    class Log(PipelineLog):
        lines: list = []

        def warn(self, text, throttle=False):
            self.lines.append(text)

    EstimatorPipeline.from_params({"system": CART, "inputs": spec, "gain_table_cache_dir": str(tmp_path)}, Log())
    assert [t for t in Log.lines if t.startswith("no source feeds channel 2 ")], Log.lines


# ------------------------------------------------------------------ the gain-table cache
@pytest.fixture
def cache_case(paper_tables, tmp_path, monkeypatch):
    """A private cache folder, where the paper's default table is cached, and a log that keeps its
    lines; the design at start-up is the session's table (no SDP here)."""
    import os

    from switchobs_core.table.gains import GainTable
    from switchobs_ros import core_config
    from switchobs_ros.config import EstimatorConfig
    from switchobs_ros.counters import PipelineLog

    table = GainTable.load(paper_tables["periodic"])
    designs = []
    monkeypatch.setattr(core_config, "design_family_table", lambda *a, **k: designs.append(1) or table)
    cache = tmp_path / "cache"
    cache.mkdir()
    os.chmod(cache, 0o700)
    conf = EstimatorConfig.from_values({"gain_table_cache_dir": str(cache)})
    where = core_config.table_cache_path(str(cache), conf.system, conf.mode, list(conf.cycles), None, conf["delta"])

    class Log(PipelineLog):
        def __init__(self):
            self.lines = []

        def info(self, text):
            self.lines.append(("info", text))

        def warn(self, text, throttle=False):
            self.lines.append(("warn", text))
    return {"cache": cache, "where": where, "table": table, "designs": designs, "Log": Log}


def test_the_cache_trust_check_follows_links_safely(cache_case, tmp_path):
    """The cached table a symlink into a world-writable folder, or to /dev/zero: every link on the
    way and the folder that finally holds the table are checked (not just the target file), and a
    target that is not a regular file is named as such."""
    import os

    from switchobs_ros.params import ConfigError
    from switchobs_ros.pipeline import EstimatorPipeline

    c = cache_case
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, 0o777)
    c["table"].save(shared / "t.npz")            # a private file (0644), in a folder anyone may write
    os.symlink(shared / "t.npz", c["where"])
    cfg = {"gain_table_cache_dir": str(c["cache"])}
    with pytest.raises(ConfigError, match=rf"the folder {shared} holding cached gain table {c['where']} \(a symlink "
                                          r"to .*t\.npz\) is writable by group and others") as err:
        EstimatorPipeline.from_params(cfg, c["Log"]())
    assert "\n" not in str(err.value)
    os.unlink(c["where"])
    os.symlink("/dev/zero", c["where"])
    with pytest.raises(ConfigError, match=rf"cached gain table {c['where']} is a character device \(a symlink to "
                                          r"/dev/zero\), not a regular file"):
        EstimatorPipeline.from_params(cfg, c["Log"]())
    # a link that another folder anyone may write holds (not sticky): refused for the link's folder
    os.unlink(c["where"])
    os.symlink(c["cache"] / "real.npz", shared / "hop")
    c["table"].save(c["cache"] / "real.npz")
    os.symlink(shared / "hop", c["where"])
    with pytest.raises(ConfigError, match=rf"symlink {shared / 'hop'} is in {shared}, which group and others may "
                                          "write"):
        EstimatorPipeline.from_params(cfg, c["Log"]())
    # links within private folders are fine
    os.unlink(c["where"])
    os.symlink(c["cache"] / "real.npz", c["where"])
    EstimatorPipeline.from_params(cfg, c["Log"]())
    assert not c["designs"]


@pytest.mark.parametrize("how", ["read_only", "full", "loop"])
def test_a_cache_that_cannot_be_written_is_reported_once(cache_case, monkeypatch, how):
    """A cache write that fails (read-only or full filesystem, a symlink loop): the start-up goes on
    with the designed table and says once, as a warning, why the cache was not written and what it
    costs (the table is designed again at every start)."""
    import errno
    import os

    from switchobs_core.table.gains import GainTable
    from switchobs_ros.pipeline import EstimatorPipeline

    c = cache_case
    if how == "loop":
        os.symlink(c["where"], c["where"])
    else:
        code = errno.EROFS if how == "read_only" else errno.ENOSPC

        def fails(self, path, *a, **k):
            raise OSError(code, os.strerror(code), str(path))
        monkeypatch.setattr(GainTable, "save", fails)
    log = c["Log"]()
    pl = EstimatorPipeline.from_params({"gain_table_cache_dir": str(c["cache"])}, log)
    assert pl.table is c["table"] and c["designs"] == [1]
    warns = [t for lvl, t in log.lines if lvl == "warn"]
    assert len(warns) == 1 and warns[0].startswith(f"could not cache the gain table at {c['where']}"), log.lines
    assert "designed again at every start" in warns[0]
    assert {"read_only": "Read-only file system", "full": "No space left on device",
            "loop": "symbolic links"}[how] in warns[0]
