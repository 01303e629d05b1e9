"""The binary gain-table container (.npz): bit-for-bit round trip, old JSON tables still load, edited
and truncated files refused in one line, every double hashed and checked however it is read, the size
limit derived from n and the stored phases."""

from __future__ import annotations

import io
import json
import re
import zipfile

import numpy as np
import pytest
from _binary_tables import flip_bit, lying_member
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from switchobs_core.design.kalman import design_kalman
from switchobs_core.exceptions import GainTableError
from switchobs_core.model.scenarios import paper_system
from switchobs_core.model.schedule import Cycle
from switchobs_core.table import container
from switchobs_core.table.container import MAX_BINARY_BYTES, is_binary, size_limit
from switchobs_core.table.gains import GainTable, kalman_table
from switchobs_core.table.io import table_payload

PAPER = paper_system()
CYCLES = [Cycle.from_ts(2.0, 0.6), Cycle((0.5, 0.5), 0.1)]


@pytest.fixture(scope="module")
def table():
    return kalman_table(PAPER, [design_kalman(PAPER, c, 50.0) for c in CYCLES])


@pytest.fixture()
def saved(table, tmp_path):
    return table.save(tmp_path / "k.npz")


def _phases(kd):
    return kd.periodic + kd.startup


def test_round_trip_bit_for_bit(table, saved, tmp_path):
    """Every stored double (priors, gains, error transition) and every header value comes back
    unchanged; the JSON text of the loaded table equals the original's; and a JSON table saved as
    .npz and loaded again is the same table."""
    assert is_binary(saved)
    loaded = GainTable.load(saved, system=PAPER)
    for c in CYCLES:
        a, b = table.kalman_design([c], PAPER), loaded.kalman_design([c], PAPER)
        assert len(_phases(a)) == len(_phases(b)) and len(a.startup) > 0
        for x, y in zip(_phases(a), _phases(b), strict=True):
            assert (x.channel, x.dt, x.rows) == (y.channel, y.dt, y.rows)
            assert x.P_prior.tobytes() == y.P_prior.tobytes() and x.K.tobytes() == y.K.tobytes()
        assert a.error_transition.tobytes() == b.error_transition.tobytes()
        assert (a.rho, a.norm, a.periods, a.change) == (b.rho, b.norm, b.periods, b.change)
    assert loaded.to_json() == table.to_json()
    js = table.save(tmp_path / "k.json")
    again = GainTable.load(GainTable.load(js).save(tmp_path / "k2.npz"))
    assert again.to_json() == table.to_json()
    # the binary file is smaller than the JSON text (packed triangles, 8 bytes a double)
    assert saved.stat().st_size < 0.5 * js.stat().st_size


def test_old_json_table_loads_bit_for_bit(table, tmp_path):
    """A JSON table written before the binary container (the same text) loads with the same doubles."""
    path = tmp_path / "old.json"
    path.write_text(table.to_json())
    loaded = GainTable.load(path, system=PAPER)
    assert loaded.to_json() == path.read_text()
    a, b = table.kalman_design(CYCLES[:1], PAPER), loaded.kalman_design(CYCLES[:1], PAPER)
    assert all(x.P_prior.tobytes() == y.P_prior.tobytes() for x, y in zip(_phases(a), _phases(b), strict=True))


@pytest.mark.parametrize("chunk", [8, 24, 4096])
@pytest.mark.parametrize("where", [0, -1])
def test_read_in_slices_hashes_and_checks_every_double(table, tmp_path, monkeypatch, chunk, where):
    """Members read a slice at a time (``chunk`` bytes: one double, three, many) load bit for bit, and a
    NaN in the first or last double of a gain array, written with a checksum that matches, is found."""
    monkeypatch.setattr(container, "_CHUNK", chunk)
    saved = table.save(tmp_path / "k.npz")
    assert GainTable.load(saved, system=PAPER).to_json() == table.to_json()
    with np.load(saved) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays.pop("header").tobytes())
    header.pop("payload_sha256")
    arrays["k0_periodic_K"] = arrays["k0_periodic_K"].copy()
    arrays["k0_periodic_K"][where] = np.nan
    header["payload_sha256"] = container._digest(header, arrays)     # a checksum that matches the NaN
    bad = tmp_path / "nan.npz"
    text = json.dumps(header, sort_keys=True).encode()
    np.savez(bad, header=np.frombuffer(text, dtype=np.uint8), **arrays)
    with pytest.raises(GainTableError, match="non-finite number in k0_periodic_K"):
        GainTable.load(bad)


def _rewrite(path, edit):
    """A copy of the archive with ``edit(name, bytes) -> bytes`` applied to its members (valid zip)."""
    src = zipfile.ZipFile(path)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z:
        for info in src.infolist():
            z.writestr(info, edit(info.filename, src.read(info)))
    return out.getvalue()


def _flip_last_double(name, b):
    if name != "k0_periodic_K.npy":
        return b
    return b[:-1] + bytes([b[-1] ^ 1])


def _data_offset(path, member):
    """Byte offset in the archive of the first number of a stored ``member`` (after its ``.npy`` header)."""
    with zipfile.ZipFile(path) as z, open(path, "rb") as fh:
        zi = z.getinfo(member)
        fh.seek(zi.header_offset + 26)
        name_len, extra_len = int.from_bytes(fh.read(2), "little"), int.from_bytes(fh.read(2), "little")
        start = zi.header_offset + 30 + name_len + extra_len
        fh.seek(start)
        np.lib.format.read_magic(fh)
        np.lib.format.read_array_header_1_0(fh)
        return fh.tell()


def _save_v3(table, path):
    """The table written in version 3 of the container (every array verified at load)."""
    from switchobs_core.table.io import table_payload
    with open(path, "wb") as fh:
        container.encode(table_payload(table), fh, version=3)
    return path


@pytest.mark.parametrize("how, match", [
    ("half", r"not a complete binary gain table \(File is not a zip file\)"),
    ("tail", r"not a complete binary gain table"),
    ("byte", r"checksum mismatch: the file was modified"),
    ("byte_v3", r"checksum mismatch: the file was modified"),
    ("gain", r"checksum mismatch: the file was modified"),
    ("rate", r"checksum mismatch: the file was modified"),
    ("shape", r"array k0_periodic_P is float64 \(\d+, 77\), not float64 \(\d+, 78\)"),
])
def test_edited_or_truncated_refused_in_one_line(saved, tmp_path, how, match):
    data = saved.read_bytes()
    if how == "half":
        bad = data[: len(data) // 2]
    elif how == "tail":
        bad = data[:-7]
    elif how == "byte":     # a byte of a gain changed in place (arrays are read past zip's CRC: the SHA-256)
        i = _data_offset(saved, "k0_periodic_K.npy") + 13
        bad = data[:i] + bytes([data[i] ^ 0x10]) + data[i + 1:]
    elif how == "byte_v3":  # a byte of a prior changed in place in a version-3 file: refused at load
        data = _save_v3(GainTable.load(saved), tmp_path / "v3.npz").read_bytes()
        i = data.index(b"k0_periodic_P.npy") + 4096
        bad = data[:i] + bytes([data[i] ^ 0x10]) + data[i + 1:]
    elif how == "gain":     # a valid archive with one gain's last bit flipped
        bad = _rewrite(saved, _flip_last_double)
    elif how == "rate":     # a valid archive with an edited header value
        bad = _rewrite(saved, lambda n, b: b.replace(b'"rate": 50.0', b'"rate": 51.0') if n == "header.npy" else b)
    else:                   # an array of another shape
        def edit(n, b):
            if n != "k0_periodic_P.npy":
                return b
            a = np.load(io.BytesIO(b))
            buf = io.BytesIO()
            np.save(buf, a[:, :-1])
            return buf.getvalue()
        bad = _rewrite(saved, edit)
    p = tmp_path / "bad.npz"
    p.write_bytes(bad)
    with pytest.raises(GainTableError, match=match) as err:
        GainTable.load(p)
    assert "\n" not in str(err.value)


def test_size_limit_from_n_and_phases(saved, tmp_path):
    """The limit is 16 MiB plus 8 (n(n+1)/2 + n p_max) bytes per stored phase (plus 8 n^2 per design);
    a file larger than its header allows is refused naming n and the phase count."""
    assert size_limit(12, 4, 0, 0) == 16 * 2**20
    assert size_limit(132, 4, 1000, 1) == 16 * 2**20 + 1000 * 8 * (132 * 133 // 2 + 132 * 4) + 8 * 132**2
    assert size_limit(10**5, 4, 10**9, 1) == MAX_BINARY_BYTES
    header = json.loads(np.load(io.BytesIO(zipfile.ZipFile(saved).read("header.npy"))).tobytes())
    phases = sum(len(d[s]["channel"]) for d in header["kalman"] for s in ("periodic", "startup"))
    limit = size_limit(12, 4, phases, len(CYCLES))
    data = saved.read_bytes()
    big = tmp_path / "big.npz"
    with zipfile.ZipFile(big, "w") as z:       # the same members and a padding member past the limit
        src = zipfile.ZipFile(io.BytesIO(data))
        for info in src.infolist():
            z.writestr(info, src.read(info))
        z.writestr("pad.bin", b"\0" * (limit - len(data) + 1024))
    with pytest.raises(GainTableError, match=rf"larger than {limit / 2**20:.1f} MiB, the limit for a table of "
                                             rf"n = 12 states and {phases} stored phases"):
        GainTable.load(big)


@pytest.mark.parametrize("member", ["k0_E.npy", "header.npy"])
@pytest.mark.parametrize("deflate", [True, False])
def test_a_member_header_that_lies_is_refused_before_allocating(saved, tmp_path, member, deflate):
    """A ``.npy`` header claiming 2^33 elements (64 GiB of float64), in a stored or a DEFLATE
    member: every member's header is checked against the member's size before anything is
    allocated (numpy alone would allocate first): one line, at once, whatever the compression."""
    import resource
    import time
    p = tmp_path / "lying.npz"
    p.write_bytes(lying_member(saved, member, 2**33 if member != "header.npy" else 2**36, deflate=deflate))
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (4 * 10**9, hard))       # the acceptance limit: no 64 GiB
    try:
        t0 = time.perf_counter()
        with pytest.raises(GainTableError, match=rf"{member[:-4]}: its \.npy header claims \d+ bytes; the member "
                                                 r"holds \d+") as err:
            GainTable.load(p)
        assert time.perf_counter() - t0 < 1.0
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("seg, k, byte", [("startup", 0, 0), ("startup", 3, 77), ("periodic", -1, 8 * 78 - 1)])
@pytest.mark.parametrize("when", ["before_load", "after_load"])
def test_a_flipped_prior_is_refused_at_its_first_use(table, saved, seg, k, byte, when):
    """Version 4: loading reads no prior; a prior is read and checked against its own SHA-256 when
    first used. One bit flipped in one phase's prior (in the file before it is loaded, or rewritten in
    place after): every other phase gives the stored doubles bit for bit, that phase raises a
    one-line GainTableError naming the file, array and phase, every time it is asked for, and its
    numbers are never returned."""
    c = CYCLES[0]
    ref = table.kalman_design([c], PAPER)
    phases = getattr(ref, seg)
    k %= len(phases)
    m = PAPER.n * (PAPER.n + 1) // 2
    at = _data_offset(saved, f"k0_{seg}_P.npy") + 8 * m * k + byte
    if when == "before_load":
        flip_bit(saved, at)
    loaded = GainTable.load(saved, system=PAPER)      # the gains are checked (table/check.py); no prior read
    rows = loaded.kalman[0][seg]["P_prior"]
    assert rows.verified() == 0
    if when == "after_load":
        flip_bit(saved, at)
    kd = loaded.kalman_design([c], PAPER)
    for j, (x, y) in enumerate(zip(phases, getattr(kd, seg), strict=True)):
        assert x.K.tobytes() == y.K.tobytes()
        if j != k:
            assert x.P_prior.tobytes() == y.P_prior.tobytes()
    for _ in range(2):
        with pytest.raises(GainTableError, match=rf"{saved}: phase {k} of k0_{seg}_P: checksum mismatch") as err:
            _ = getattr(kd, seg)[k].P_prior
        assert "\n" not in str(err.value)
    assert rows.verified() == len(phases) - 1


def test_version_3_still_read_and_verified_whole(table, tmp_path):
    """A version-3 file (every array in the one checksum) loads bit for bit, with every prior read at load."""
    old = _save_v3(table, tmp_path / "v3.npz")
    loaded = GainTable.load(old, system=PAPER)
    assert loaded.to_json() == table.to_json()
    segments = [d[s]["P_prior"] for d in loaded.kalman for s in ("periodic", "startup")]
    assert all(isinstance(p, container.PackedRows) for p in segments)
    with zipfile.ZipFile(old) as z:
        assert json.loads(np.load(io.BytesIO(z.read("header.npy"))).tobytes())["format_version"] == 3
    again = GainTable.load(loaded.save(tmp_path / "v4.npz"))     # written again: version 4, the same table
    assert again.to_json() == table.to_json()


@settings(max_examples=80, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(where=st.floats(0.0, 1.0, exclude_max=True), bit=st.integers(0, 7))
def test_any_bit_flipped_never_gives_other_numbers(table, saved, tmp_path, where, bit):
    """One bit flipped anywhere in a version-4 file: loading refuses it, or every gain and transition
    is the stored one and every prior is the stored one or refused at its use (GainTableError).
    No flip makes the table answer with numbers other than the ones written."""
    data = bytearray(saved.read_bytes())
    i = int(where * len(data))
    data[i] ^= 1 << bit
    p = tmp_path / "flipped.npz"
    p.write_bytes(bytes(data))
    try:
        loaded = GainTable.load(p, system=PAPER)
    except GainTableError:
        return
    for c in CYCLES:
        a, b = table.kalman_design([c], PAPER), loaded.kalman_design([c], PAPER)
        assert a.error_transition.tobytes() == b.error_transition.tobytes()
        for x, y in zip(_phases(a), _phases(b), strict=True):
            assert x.K.tobytes() == y.K.tobytes() and (x.channel, x.dt, x.rows) == (y.channel, y.dt, y.rows)
            try:
                P = y.P_prior
            except GainTableError as err:
                assert "checksum mismatch" in str(err)
                continue
            assert P.tobytes() == x.P_prior.tobytes()


def _header(path) -> dict:
    return json.loads(np.load(io.BytesIO(zipfile.ZipFile(path).read("header.npy"))).tobytes())


@pytest.mark.parametrize("version", [4, 5])
def test_bases_and_noise_as_arrays_from_version_5_and_version_4_still_read(table, tmp_path, version):
    """Version 5 holds every channel's observable basis and each design's noise matrices as arrays (the
    header refers to them); version 4 holds them in the header's JSON. Either loads to the same table
    (its JSON text, the bases' and noise matrices' bytes) and saves again in version 5."""
    path = tmp_path / f"v{version}.npz"
    with open(path, "wb") as fh:
        container.encode(table_payload(table), fh, version=version)
    head, members = _header(path), set(zipfile.ZipFile(path).namelist())
    arrays = {f"c{i}_T_o.npy" for i in range(PAPER.N)} | {f"k{i}_noise_{k}.npy" for i in range(len(CYCLES))
                                                          for k in ("Q_c", "P0")}
    if version == 5:
        assert arrays <= members
        assert all(ch["T_o"] == {"$array": f"c{i}_T_o"} for i, ch in enumerate(head["channels"]))
        assert head["kalman"][0]["noise"]["Q_c"] == {"$array": "k0_noise_Q_c"}
    else:
        assert not arrays & members and isinstance(head["channels"][0]["T_o"], list)
    loaded = GainTable.load(path, system=PAPER)
    assert loaded.to_json() == table.to_json()
    for i in range(1, PAPER.N + 1):
        assert loaded.T_o(i).tobytes() == table.T_o(i).tobytes()
    a, b = table.kalman_design([CYCLES[0]], PAPER).noise, loaded.kalman_design([CYCLES[0]], PAPER).noise
    assert a.Q_c.tobytes() == b.Q_c.tobytes() and a.P0.tobytes() == b.P0.tobytes()
    assert _header(loaded.save(tmp_path / "again.npz"))["format_version"] == 5


@pytest.mark.parametrize("member", ["c1_T_o.npy", "k0_noise_P0.npy"])
def test_a_changed_basis_or_noise_matrix_is_refused(saved, tmp_path, member):
    """One bit of a stored basis or noise matrix flipped: the checksum refuses the file in one line."""
    bad = tmp_path / "bad.npz"
    bad.write_bytes(saved.read_bytes())
    at = _data_offset(bad, member) + 13
    data = bytearray(bad.read_bytes())
    data[at] ^= 0x08
    bad.write_bytes(bytes(data))
    with pytest.raises(GainTableError, match="checksum mismatch: the file was modified"):
        GainTable.load(bad)


@pytest.mark.parametrize("noise", [None, [1, 2], "Q_c"])
def test_a_version_5_header_without_a_noise_object_is_refused_in_one_line(table, tmp_path, noise):
    """A header (checksum made to match, as a writer with a bug would) whose design has no noise object
    for the matrices to go in: a GainTableError naming the entry, as version 4 refuses it."""
    path = tmp_path / "v5.npz"
    with open(path, "wb") as fh:
        container.encode(table_payload(table), fh, version=5)
    zf = zipfile.ZipFile(path)
    head = _header(path)
    arrays = {m[:-4]: np.load(io.BytesIO(zf.read(m))) for m in zf.namelist() if m != "header.npy"}
    head.pop("payload_sha256")
    if noise is None:
        head["kalman"][0].pop("noise")
    else:
        head["kalman"][0]["noise"] = noise
    head["payload_sha256"] = container._digest(head, arrays)
    bad = tmp_path / "bad.npz"
    with open(bad, "wb") as fh:
        np.savez(fh, header=np.frombuffer(json.dumps(head, sort_keys=True).encode(), dtype=np.uint8), **arrays)
    with pytest.raises(GainTableError, match=r"kalman\[0\]\.noise"):
        GainTable.load(bad, system=PAPER)


_DIGIT = st.sampled_from("0123456789abcdef")
_DIGEST = st.text(_DIGIT, min_size=64, max_size=64)
_NOT_DIGEST = st.one_of(st.text(_DIGIT, max_size=63), st.text(_DIGIT, min_size=65, max_size=70),
                        st.text(st.sampled_from("0123456789abcdefABCDEFg \n"), min_size=64, max_size=64),
                        st.integers(), st.none(), st.lists(st.integers(), max_size=2))


@settings(max_examples=200, deadline=None)
@given(xs=st.lists(st.one_of(_DIGEST, _NOT_DIGEST), max_size=6))
def test_digest_lists_checked_at_once_as_one_by_one(xs):
    """The header's prior digests checked in one match: the verdict of a full match of ``[0-9a-f]{64}``
    on each item (a string, of exactly 64 lower-case hex digits)."""
    one_by_one = all(isinstance(x, str) and re.fullmatch(r"[0-9a-f]{64}", x) is not None for x in xs)
    assert container._all_sha256(xs) is one_by_one
