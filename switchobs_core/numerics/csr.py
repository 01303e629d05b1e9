"""Products of a matrix in compressed rows (CSR) with dense operands, through scipy's own kernels.

``csr_array @ x`` runs scipy's ``csr_matvec`` / ``csr_matvecs`` loops (each row's sum over its
nonzeros, in the stored order) after 15-30 us of checks and conversions. At 32 agents the observer
takes several such products a sample and the table check 1 600 at start-up, so they call the kernels
directly, here: the one place that reaches into scipy's private ``scipy.sparse._sparsetools``. The
sums and their order are the kernel's either way, so a result equals the public product's bit for
bit; a scipy without that module gets the public product.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_array

try:
    from scipy.sparse._sparsetools import csr_matvec as _csr_matvec
    from scipy.sparse._sparsetools import csr_matvecs as _csr_matvecs
except ImportError:     # pragma: no cover - another scipy layout: the public product
    _csr_matvec = _csr_matvecs = None

__all__ = ["csr_matmat", "csr_matvec"]


def csr_matvec(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, shape: tuple[int, int],
               x: np.ndarray) -> np.ndarray:
    """``A x`` for ``A`` given by its CSR arrays and ``shape`` (``x`` a contiguous float vector)."""
    m, n = shape
    if _csr_matvec is None:         # pragma: no cover
        return np.asarray(csr_array((data, indices, indptr), shape=shape) @ x)
    out = np.zeros(m)
    _csr_matvec(m, n, indptr, indices, data, x, out)
    return out


def csr_matmat(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, shape: tuple[int, int],
               B: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``A B`` for ``A`` given by its CSR arrays and ``shape`` and a dense ``B`` (n x r; made
    C-contiguous if it is not); ``out``: a C-ordered float array of the result's shape (not
    overlapping ``B``) that receives it (the same doubles as a new one)."""
    m, n = shape
    B = np.ascontiguousarray(B, dtype=float)
    if out is None:
        out = np.zeros((m, B.shape[1]))
    else:
        out.fill(0.0)
    if _csr_matvecs is None:        # pragma: no cover
        np.copyto(out, np.asarray(csr_array((data, indices, indptr), shape=shape) @ B))
        return out
    _csr_matvecs(m, n, B.shape[1], indptr, indices, data, B.ravel(), out.ravel())
    return out
