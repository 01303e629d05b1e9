"""The gain table file's layout check (the schema of :mod:`switchobs_core.table.gains`'s format, by hand).

:func:`check_layout` refuses, in one line naming the key, a parsed table whose checksum is valid
but whose layout is not the one this software writes (types and sizes of what the loader and
``switchobs show`` read); :func:`check_finite` finds the first non-finite number.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..exceptions import GainTableError

__all__ = ["check_finite", "check_layout"]


def check_finite(obj: Any, source: str, where: str = "") -> None:
    """Raise GainTableError at the first non-finite float in a JSON-like tree (iterative walk)."""
    stack = [(obj, where)]
    while stack:
        node, at = stack.pop()
        if isinstance(node, np.ndarray):
            if not np.all(np.isfinite(node)):
                raise GainTableError(f"{source}: non-finite number in {at or 'top level'}")
        elif isinstance(node, float):
            if not math.isfinite(node):
                raise GainTableError(f"{source}: non-finite number {node} at {at or 'top level'}")
        elif isinstance(node, dict):
            stack.extend((v, f"{at}.{k}" if at else str(k)) for k, v in reversed(list(node.items())))
        elif isinstance(node, (list, tuple)):
            stack.extend((v, f"{at}[{i}]") for i, v in reversed(list(enumerate(node))))


#: The types :meth:`_Layout.numbers` accepts at once (a bool, a subclass, anything else: one by one).
_PLAIN_NUMBERS = frozenset((int, float))


class _Layout:
    """Checks of a parsed table's layout (types and sizes of what the tools read), so a table
    with a valid checksum but written by something else is refused in one line, naming the key."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, what: str) -> GainTableError:
        return GainTableError(f"{self.source}: malformed gain table: {where} must be {what}")

    def get(self, d: dict, key: str, where: str) -> Any:
        if key not in d:
            raise GainTableError(f"{self.source}: malformed gain table: {where}{'.' if where else ''}{key} is missing")
        return d[key]

    def mapping(self, x: Any, where: str) -> dict:
        if not isinstance(x, dict):
            raise self.fail(where, "an object")
        return x

    def number(self, x: Any, where: str, *, none: bool = False) -> None:
        if x is None and none:
            return
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise self.fail(where, "a number")

    def integer(self, x: Any, where: str, lo: int = 0, hi: int | None = None) -> int:
        if isinstance(x, bool) or not isinstance(x, int) or x < lo or (hi is not None and x > hi):
            raise self.fail(where, f"a whole number in {lo}..{hi if hi is not None else ''}")
        return x

    def string(self, x: Any, where: str) -> None:
        if not isinstance(x, str):
            raise self.fail(where, "a string")

    def numbers(self, x: Any, where: str, size: int | None = None) -> list:
        if not isinstance(x, list) or (size is not None and len(x) != size):
            raise self.fail(where, "a list of numbers" + (f" of length {size}" if size is not None else ""))
        if set(map(type, x)) <= _PLAIN_NUMBERS:     # every entry an int or a float: at C speed
            return x
        for i, v in enumerate(x):       # self.number inline: the name is formed only for a failure
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise self.fail(f"{where}[{i}]", "a number")
        return x

    def matrix(self, x: Any, where: str, rows: int, cols: int) -> None:
        if isinstance(x, np.ndarray):      # read from a binary table: float64, shape and finiteness checked there
            if x.dtype != np.float64 or x.shape != (rows, cols):
                raise self.fail(where, f"a {rows} x {cols} matrix")
            return
        if not isinstance(x, list) or len(x) != rows:
            raise self.fail(where, f"a {rows} x {cols} matrix (a list of {rows} rows)")
        for i, row in enumerate(x):
            self.numbers(row, f"{where}[{i}]", cols)


def check_layout(data: dict[str, Any], source: str) -> None:
    """Raise GainTableError naming the key if the table's layout is not the one this software
    writes (module docstring); what the loader and ``switchobs show`` read is checked."""
    c = _Layout(source)
    sysd = c.mapping(c.get(data, "system", ""), "system")
    c.string(c.get(sysd, "name", "system"), "system.name")
    c.string(c.get(sysd, "fingerprint", "system"), "system.fingerprint")
    n = c.integer(c.get(sysd, "n", "system"), "system.n", 1)
    p = c.get(sysd, "p", "system")
    if not isinstance(p, list) or len(p) < 2:
        raise c.fail("system.p", "a list of N >= 2 output sizes")
    for i, v in enumerate(p):
        c.integer(v, f"system.p[{i}]", 1)
    N = len(p)
    c.string(c.get(data, "software_version", ""), "software_version")
    family = data.get("family", "lmi")
    c.string(family, "family")
    settings = c.mapping(c.get(data, "settings", ""), "settings")
    c.numbers(c.get(data, "delta", ""), "delta", N if family == "lmi" else None)
    chans = c.get(data, "channels", "")
    if not isinstance(chans, list) or len(chans) != N:
        raise c.fail("channels", f"a list of N = {N} channel entries")
    rs = []
    for i, ch in enumerate(chans):
        w = f"channels[{i}]"
        c.mapping(ch, w)
        r = c.integer(c.get(ch, "r", w), f"{w}.r", 1, n)
        rs.append(r)
        c.matrix(c.get(ch, "T_o", w), f"{w}.T_o", n, r)
        if family == "lmi":
            c.number(c.get(ch, "mu", w), f"{w}.mu")
            kc = c.mapping(c.get(ch, "kappa_curve", w), f"{w}.kappa_curve")
            eta = c.numbers(c.get(kc, "eta", f"{w}.kappa_curve"), f"{w}.kappa_curve.eta")
            c.numbers(c.get(kc, "kappa", f"{w}.kappa_curve"), f"{w}.kappa_curve.kappa", len(eta))
    if family == "lmi":
        for key in ("margin", "solver"):
            c.get(settings, key, "settings")
    designs = c.get(data, "designs", "")
    if not isinstance(designs, list):
        raise c.fail("designs", "a list")
    robust = c.get(data, "robust", "")
    for w, d in [(f"designs[{k}]", d) for k, d in enumerate(designs)] + ([("robust", robust)] if robust else []):
        _check_design(c, d, w, n, p, rs)
    kalman = data.get("kalman", [])
    if not isinstance(kalman, list):
        raise c.fail("kalman", "a list")
    for k, d in enumerate(kalman):
        w = f"kalman[{k}]"
        c.mapping(d, w)
        cycles = c.get(d, "cycles", w)
        if not isinstance(cycles, list):
            raise c.fail(f"{w}.cycles", "a list of cycles")
        for j, h in enumerate(cycles):
            c.numbers(h, f"{w}.cycles[{j}]", N)
        if "dead_time" in d:
            c.number(d["dead_time"], f"{w}.dead_time")
        for key in ("rate", "rho", "norm"):
            c.number(c.get(d, key, w), f"{w}.{key}")
        c.integer(c.get(d, "periods", w), f"{w}.periods")
        c.mapping(c.get(d, "noise", w), f"{w}.noise")
        for key in ("periodic", "startup"):
            ph = c.mapping(c.get(d, key, w), f"{w}.{key}")
            if not isinstance(c.get(ph, "channel", f"{w}.{key}"), list):
                raise c.fail(f"{w}.{key}.channel", "a list")


def _check_design(c: _Layout, d: Any, w: str, n: int, p: list[int], rs: list[int]) -> None:
    c.mapping(d, w)
    c.string(c.get(d, "kind", w), f"{w}.kind")
    cyc = c.get(d, "cycle", w)
    if cyc is not None:
        c.numbers(c.get(c.mapping(cyc, f"{w}.cycle"), "h", f"{w}.cycle"), f"{w}.cycle.h", len(p))
        if "dead_time" in cyc:
            c.number(cyc["dead_time"], f"{w}.cycle.dead_time")
    hb = c.get(d, "h_bounds", w)
    if hb is not None:
        c.numbers(hb, f"{w}.h_bounds", 2)
    c.numbers(c.get(d, "delta", w), f"{w}.delta", len(p))
    chans = c.get(d, "channels", w)
    if not isinstance(chans, list) or len(chans) != len(p):
        raise c.fail(f"{w}.channels", f"a list of N = {len(p)} gains")
    for i, g in enumerate(chans):
        wi = f"{w}.channels[{i}]"
        c.mapping(g, wi)
        c.number(c.get(g, "eta_min", wi), f"{wi}.eta_min", none=True)
        for key in ("eta", "kappa", "kappa_star", "mu", "active", "inactive", "f", "eta_verified", "abscissa"):
            c.number(c.get(g, key, wi), f"{wi}.{key}")
        c.matrix(c.get(g, "L_o", wi), f"{wi}.L_o", rs[i], p[i])
        c.matrix(c.get(g, "L", wi), f"{wi}.L", n, p[i])
        c.matrix(c.get(g, "P", wi), f"{wi}.P", rs[i], rs[i])
