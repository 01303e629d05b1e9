"""Binary gain tables (.npz) made to lie, for the container's refusal tests (core and tools)."""

from __future__ import annotations

import io
import zipfile

import numpy as np


def lying_member(path, member: str = "k0_E.npy", count: int = 2**33, *, deflate: bool = True) -> bytes:
    """A copy of the archive at ``path`` whose ``member`` has a ``.npy`` header claiming ``count``
    elements (2^33 float64: 64 GiB) over the member's real bytes, DEFLATE-compressed by default."""
    src = zipfile.ZipFile(path)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as z:
        for info in src.infolist():
            b = src.read(info)
            if info.filename == member:
                a = np.load(io.BytesIO(b))
                head = io.BytesIO()
                np.lib.format.write_array_header_1_0(head, {"descr": a.dtype.str, "fortran_order": False,
                                                            "shape": (count,)})
                b = head.getvalue() + a.tobytes()
            z.writestr(info.filename, b, compress_type=zipfile.ZIP_DEFLATED if deflate else zipfile.ZIP_STORED)
    return out.getvalue()


def flip_bit(path, at: int) -> None:
    """Flip the lowest bit of the byte at offset ``at`` of the file ``path`` (in place)."""
    with open(path, "r+b") as fh:
        fh.seek(at)
        b = fh.read(1)
        fh.seek(at)
        fh.write(bytes([b[0] ^ 0x01]))
