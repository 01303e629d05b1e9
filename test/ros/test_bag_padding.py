"""The bag tools' own serialisations are reproducible byte for byte: ``switchobs_bag generate``'s messages and
the ``/diagnostics`` message of ``switchobs_bag estimate`` are written with their CDR alignment padding zeroed
(:mod:`msg_bridge.cdr_padding`), whatever the heap held before (rclpy's serialiser leaves its bytes there)."""

from __future__ import annotations

from msg_bridge.cdr_padding import zero_padding
from switchobs_ros.bag.estimate import estimate, estimator_params
from switchobs_ros.bag.generate import TOPICS, GenerateConfig, generate
from switchobs_ros.bag.io import BagIn, deserialize, msg_class


def _dirty() -> None:
    """Memory freed full of non-zero bytes, for rclpy's padding to take up (as a process's heap does)."""
    junk = [bytes([0xAB]) * 4096 for _ in range(200)]
    del junk


def _unpadded(bag) -> list[str]:
    """The topics of ``bag``'s messages whose bytes are not those of their message with the padding zeroed."""
    with BagIn(bag) as b:
        msgs = b.messages(order="file")
    return [m.topic for m in msgs if bytes(zero_padding(deserialize(m, msg_class(m.type)), m.data)) != m.data]


def test_generated_bags_have_their_padding_zeroed_and_are_the_same_bytes(tmp_path):
    """Every generated message (the clock, the channel, the poses, the truth) reads back with zero padding, and
    two bags of the same configuration, written after the heap was filled with other bytes, are the same file."""
    cfg = GenerateConfig(duration=0.4, noise_std=0.01, seed=3)
    for k in range(2):      # the same folder name (the file and its metadata name it)
        _dirty()
        generate(tmp_path / str(k) / "g", cfg, "mcap")
    with BagIn(tmp_path / "0" / "g") as b:
        assert set(b.topics) == set(TOPICS) and b.message_count == 5 * 41       # 100 Hz, ticks 0..40
    assert _unpadded(tmp_path / "0" / "g") == []
    for name in ("g.mcap", "metadata.yaml"):
        assert (tmp_path / "0" / "g" / name).read_bytes() == (tmp_path / "1" / "g" / name).read_bytes()


def test_estimate_diagnostics_have_their_padding_zeroed(tmp_path):
    """The estimate's ``/diagnostics`` (a byte-sized level before strings: padding in every status) reads back
    with zero padding, as every other message of its output bag (the inputs copied, the templates)."""
    generate(tmp_path / "in", GenerateConfig(duration=0.4), "mcap")
    _dirty()
    estimate(tmp_path / "in", estimator_params(overrides={"e0": 5.0}), out=tmp_path / "est", keep=False)
    with BagIn(tmp_path / "est") as b:
        assert b.counts["/diagnostics"] == 1
    assert _unpadded(tmp_path / "est") == []
