"""Keys of one ``ZOHCache`` whose ``M`` has the same values (innovation-hold keys: ``M = A`` for every
channel) share the exponential and its certificate: each entry equals, bit for bit, the entry of a cache
that holds that key alone, and owns its arrays."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from switchobs_core.numerics.propagation import SHARED_KEPT, ZOHCache


def _entry_equal(a, b) -> None:
    for f in ("Phi", "Gamma", "GL", "GB", "E"):
        x, y = getattr(a, f), getattr(b, f)
        assert (x is None) == (y is None), f
        if x is not None:
            assert np.array_equal(x, y), f
    assert (a.eps, a.epsG, a.dt) == (b.eps, b.epsG, b.dt)


@settings(max_examples=15, deadline=None)
@given(n=st.integers(2, 6), keys=st.integers(2, 5), seed=st.integers(0, 2 ** 32 - 1),
       dts=st.lists(st.sampled_from([0.02, 0.01, 0.0200003, 0.5]), min_size=1, max_size=4),
       with_input=st.booleans(), scaled=st.booleans())
def test_keys_of_one_m_give_the_entries_of_separate_caches(n, keys, seed, dts, with_input, scaled):
    """Property: over random ``A`` (one copy per key, equal values), gains ``L``, outputs ``C``, an input
    ``B`` or none, a balancing or none and steps on and off the composition grid, every key's entry
    equals that of a fresh cache holding the key alone; no two entries share an array; an open-loop key
    of the same ``A`` (``Phi`` alone) is not served the pair."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n)) / 2
    scale = np.exp(rng.uniform(-2, 2, n)) if scaled else None
    shared = ZOHCache(scale=scale)
    made = []
    for k in range(keys):
        L, C = rng.standard_normal((n, 2)), rng.standard_normal((2, n))
        B = rng.standard_normal((n, 1)) if with_input else None
        shared.register(k, A.copy(), L, B, C=C)
        alone = ZOHCache(scale=scale)
        alone.register(k, A.copy(), L, B, C=C)
        for dt in dts:
            e = shared.step(k, dt)
            _entry_equal(e, alone.step(k, dt))
            made.append(e)
    shared.register("open", A.copy())
    alone = ZOHCache(scale=scale)
    alone.register("open", A.copy())
    _entry_equal(shared.step("open", dts[0]), alone.step("open", dts[0]))
    distinct = list({id(e): e for e in made}.values())      # a step repeated is the cached entry itself
    arrays = [x for e in distinct for x in (e.Phi, e.Gamma) if x is not None]
    assert not any(np.shares_memory(x, y) for i, x in enumerate(arrays) for y in arrays[i + 1:])


def test_the_shared_exponentials_are_bounded_and_cleared():
    rng = np.random.default_rng(2)
    A = rng.standard_normal((3, 3))
    c = ZOHCache()
    c.register("k", A, rng.standard_normal((3, 1)), C=rng.standard_normal((1, 3)))
    for j in range(3 * SHARED_KEPT):
        c.step("k", 0.01 * (j + 1))
    assert len(c._shared) <= SHARED_KEPT
    c.clear()
    assert len(c._shared) == 0 and len(c) == 0
