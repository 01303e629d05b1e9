"""The typed outputs of ``switchobs_bag estimate`` written without a message serialised per estimate:
the typed estimate's covariance as a view (``cdr.Template.pieces``), the bounds message from a template
per validity and text (``typed_cdr.ErrorBoundsBytes``), and a message in pieces through the MCAP writer."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray
from switchobs_msgs.msg import ErrorBounds, StateEstimate

from msg_bridge.typed import ErrorBoundsWriter, StateEstimateWriter
from switchobs_ros.bag import cdr
from switchobs_ros.bag.io import BagIn, BagOut
from switchobs_ros.bag.typed_cdr import ErrorBoundsBytes

_F = st.floats(allow_nan=True, allow_infinity=True, width=64)


def _estimate_template(n: int) -> cdr.Template:
    labels = tuple(f"agent{i}.p_x" for i in range(n))
    return cdr.Template(StateEstimateWriter(labels, "world").msg(np.zeros(n), 0, np.zeros((n, n))),
                        stamp=("header", "stamp"), arrays=[("x",), ("covariance",)])


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 9), stamp=st.integers(0, 2_000_000_000 * 10 ** 9), seed=st.integers(0, 2 ** 32 - 1),
       transposed=st.booleans())
def test_pieces_are_the_templates_bytes(n, stamp, seed, transposed):
    """Property: the pieces joined are the bytes of ``Template.bytes`` (any stamp, any covariance, a
    non-contiguous one too), and the covariance's piece is a view of the array when it is float64 in C
    order (no copy)."""
    rng = np.random.default_rng(seed)
    w = _estimate_template(n)
    x, P = rng.standard_normal(n), rng.standard_normal((n, n))
    P = P.T if transposed else P
    parts = w.pieces(stamp, arrays=(x, P))
    assert b"".join(parts) == w.bytes(stamp, arrays=(x, P))
    if not transposed:
        assert np.shares_memory(np.frombuffer(parts[1], dtype=float), P)


def test_pieces_refuse_a_wrong_length_and_a_template_without_arrays():
    w = _estimate_template(3)
    with pytest.raises(ValueError):
        w.pieces(0, arrays=(np.zeros(3), np.zeros(8)))
    with pytest.raises(ValueError):
        w.pieces(0, arrays=(np.zeros(4), np.zeros(9)))
    with pytest.raises(ValueError):
        cdr.Template(StateEstimateWriter(("a",), "world").msg(np.zeros(1), 0), stamp=("header", "stamp")).pieces(0)


@settings(max_examples=60, deadline=None)
@given(N=st.integers(1, 5), declared=st.booleans(), stamp=st.integers(0, 2_000_000_000 * 10 ** 9), data=st.data())
def test_bounds_bytes_read_back_as_the_writers_message(N, declared, stamp, data):
    """Property: over a sequence of envelopes (bounds valid, withdrawn (-1), any doubles), validity and
    texts (a why and a note of any length and any characters), each message read back from
    ``ErrorBoundsBytes`` equals the one ``ErrorBoundsWriter`` makes from the same arguments."""
    ref = ErrorBoundsWriter(N, "world", declared)
    b = ErrorBoundsBytes(ErrorBoundsWriter(N, "world", declared))
    texts = st.sampled_from(["", "withdrawn: a gap", "re-certified from data at stamp 12"]) | st.text(max_size=30)
    for _ in range(data.draw(st.integers(1, 12))):       # repeats: the template patched directly
        size = N + 2 + declared
        values = data.draw(st.lists(_F | st.just(-1.0), min_size=size, max_size=size))
        valid, why, note = data.draw(st.booleans()), data.draw(texts), data.draw(texts)
        got = deserialize_message(b.bytes(values, stamp, valid, why, note), ErrorBounds)
        want = deserialize_message(serialize_message(ref.msg(values, stamp, valid, why, note)), ErrorBounds)
        assert got == want or _same_with_nan(got, want)


def _same_with_nan(a: ErrorBounds, b: ErrorBounds) -> bool:
    """Field for field, NaN equal to NaN."""
    def eq(u, v):
        return np.array_equal(np.asarray(u, float), np.asarray(v, float), equal_nan=True)
    return (a.header == b.header and a.why_invalid == b.why_invalid and eq(a.paper_envelope, b.paper_envelope)
            and all(eq(getattr(a, f), getattr(b, f)) for f in ("exact_bound", "noise_bound", "paper_bound"))
            and (a.exact_bound_valid, a.noise_bound_valid, a.noise_bound_declared)
            == (b.exact_bound_valid, b.noise_bound_valid, b.noise_bound_declared))


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_message_in_pieces_is_written_whole(tmp_path, storage):
    """A typed estimate given to ``BagOut.write_many`` in pieces (among whole messages, over several
    chunks) reads back as the bytes joined; the estimate reads back with its covariance."""
    n = 40
    w = _estimate_template(n)
    rng = np.random.default_rng(5)
    want = []
    with BagOut(tmp_path / "b", storage) as out:
        out.add("/se", "switchobs_msgs/msg/StateEstimate")
        out.add("/other", "std_msgs/msg/Float64MultiArray")
        for k in range(120):        # 120 x 12.8 kB: several 1 MiB chunks
            x, P = rng.standard_normal(n), rng.standard_normal((n, n))
            other = serialize_message(Float64MultiArray(data=[float(k)]))
            out.write_many(["/other", "/se"], 1000 + k, [other, w.pieces(k, arrays=(x, P))])
            want += [("/other", 1000 + k, other), ("/se", 1000 + k, w.bytes(k, arrays=(x, P)))]
            if k == 7:
                got = deserialize_message(want[-1][2], StateEstimate)
                assert np.array_equal(np.asarray(got.covariance), P.ravel()) and list(got.x) == x.tolist()
    assert [(m.topic, m.log_ns, m.data) for m in BagIn(tmp_path / "b").messages(order="file")] == want


def test_template_bytes_have_their_padding_zeroed():
    """The bags' templates (the typed estimate with and without P, a labelled array, the bounds message from
    a template and, with no envelope, serialised per message) write zeros in the CDR alignment padding: the
    bytes of the message serialised with its padding zeroed (msg_bridge.cdr_padding, rosbags' bytes), after
    memory full of other bytes was freed (where rclpy's padding comes from)."""
    import copy

    from msg_bridge.cdr_padding import zero_padding
    from msg_bridge.convert import labelled_array

    junk = [bytes([0xAB]) * 4096 for _ in range(200)]
    del junk
    x, P = np.linspace(1.0, 2.0, 3), np.eye(3)
    writer = StateEstimateWriter(("a.p", "b.p_x", "b.p_y"), "world")
    for arrays in ((x, P), (x,)):       # (the writer's message is one object, rewritten by each call)
        t = cdr.Template(copy.deepcopy(writer.msg(x, 0, *arrays[1:])), stamp=("header", "stamp"),
                         arrays=[("x",), ("covariance",)][:len(arrays)])
        m5 = writer.msg(x, 5, *arrays[1:])
        assert t.bytes(5, arrays=arrays) == bytes(zero_padding(m5, serialize_message(m5)))
    arr = labelled_array(x, ("a", "b", "c"), 5)
    got = cdr.Template(labelled_array(np.zeros(3), ("a", "b", "c"), 0), array=("data",)).bytes(array=arr.data)
    assert got == bytes(zero_padding(arr, serialize_message(arr)))
    for N in (0, 2):
        w = ErrorBoundsWriter(N, "world", True)
        values = list(np.linspace(1.0, 2.0, N + 3))
        for why in ("", "ab", "abcde"):
            m = w.msg(values, 5, False, why, "n")
            got = ErrorBoundsBytes(ErrorBoundsWriter(N, "world", True)).bytes(values, 5, False, why, "n")
            assert got == bytes(zero_padding(m, serialize_message(m)))
