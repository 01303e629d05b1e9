"""The estimator's pipeline with a binary table whose priors are verified per phase on first use.

One bit of one phase's prior flipped in a version-4 ``.npz``. In the first periodic phase, whose prior
the Kalman family reads when it is built: the estimator refuses to start, in one line naming the phase.
In a later phase: the table loads (its header, gains and
error transitions are verified at load, and its gains pass the check), the samples before that
phase are answered with the numbers of the intact table; the sample of that phase is refused,
counted and reported with why (the phase's checksum: its prior, which the bias test reads before
the sample, is that phase's stored one); the samples after it are answered without it (the table
departs at the missing sample, runs the recursion from the last good posterior and re-locks), and
nothing published ever used the corrupted numbers.
"""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from std_msgs.msg import UInt8

import msg_bridge as mb
from switchobs_core.design.kalman import design_kalman
from switchobs_core.model.scenarios import paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.table.gains import kalman_table

RATE = 50.0
MS = 1_000_000
#: The start-up phase whose prior is corrupted (the sample of that number after the first).
BAD = 5


def _corrupt(path, member: str, k: int, n: int) -> None:
    """Flip one bit of phase ``k``'s prior in ``member`` of the archive at ``path``, in place."""
    with zipfile.ZipFile(path) as z, open(path, "r+b") as fh:
        zi = z.getinfo(member)
        fh.seek(zi.header_offset + 26)
        skip = int.from_bytes(fh.read(2), "little") + int.from_bytes(fh.read(2), "little")
        fh.seek(zi.header_offset + 30 + skip)
        np.lib.format.read_magic(fh)
        np.lib.format.read_array_header_1_0(fh)
        at = fh.tell() + 8 * (n * (n + 1) // 2) * k + 17
        fh.seek(at)
        b = fh.read(1)
        fh.seek(at)
        fh.write(bytes([b[0] ^ 0x04]))


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    d = tmp_path_factory.mktemp("lazy")
    system = paper_system()
    table = kalman_table(system, [design_kalman(system, Cycle.from_ts(2.0, 0.6), RATE)])
    good, bad, first = table.save(d / "good.npz"), table.save(d / "bad.npz"), table.save(d / "first.npz")
    _corrupt(bad, "k0_startup_P.npy", BAD, system.n)
    _corrupt(first, "k0_periodic_P.npy", 0, system.n)
    return good, bad, first


def _run(table):
    from switchobs_ros.estimator import PARAMS
    from switchobs_ros.pipeline import EstimatorPipeline

    pl = EstimatorPipeline.from_params({**{p.name: p.default for p in PARAMS}, "gain_table": str(table),
                                        "gain_family": "kalman", "rate": RATE})
    pl.on_channel(UInt8(data=1))
    out = []
    for k in range(15):                         # 0.3 s, all on channel 1 (h_1 = 1.2 s)
        ns = 1_000_000_000 + k * 20 * MS
        out += pl.on_pose("camera", mb.xy_to_pose((0.1, 0.2), ns, "map"), ns + 10 * MS)
        out += pl.on_pose("target", mb.xy_to_pose((3.0, 1.0 + 0.01 * k), ns, "map"), ns + 10 * MS)
    out += pl.flush_all()
    return pl, {e.stamp_ns: e for e in out}


def test_a_corrupted_first_periodic_phase_refuses_the_start_in_one_line(tables):
    from refusals import node_main

    from tools.launch import ros_args

    first = tables[2]
    res = node_main("estimator", ros_args(params={"gain_table": str(first)}))
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    ours = [ln for ln in res.stderr.splitlines() if ln.startswith("estimator: error:")]
    assert len(ours) == 1 and f"{first}: phase 0 of k0_periodic_P: checksum mismatch" in ours[0], res.stderr


def test_a_corrupted_phase_is_refused_and_said_why_the_others_answered(tables):
    good, bad, _ = tables
    ref, want = _run(good)
    pl, got = _run(bad)
    assert len(want) == 15 and ref.errors == 0
    stamps = sorted(want)
    assert sorted(got) == stamps[:BAD] + stamps[BAD + 1:]       # all but the sample of the corrupted phase
    assert pl.errors == 1 and pl.updates == 14
    assert f"phase {BAD} of k0_startup_P: checksum mismatch" in pl.last_rejection, pl.last_rejection
    assert str(bad) in pl.last_rejection
    assert pl.observer._gains.departures == 1                  # at the sample after it (one missing)
    for s in stamps[BAD + 1:]:
        assert np.all(np.isfinite(got[s].x_hat)) and got[s].P is not None
    for s in stamps[:BAD]:                      # before it: the intact table's numbers, bit for bit
        e = got[s]
        assert e.x_hat.tobytes() == want[s].x_hat.tobytes()
        assert e.P is not None and e.P.tobytes() == want[s].P.tobytes()
        assert np.array_equal(e.envelope, want[s].envelope)
