"""A long-lived process does not run out of memory maps: JAX's compiled programs are dropped in time."""

import os

import jax
import jax.numpy as jnp
import pytest

from diffwash._cache import relieve_compiled_programs


def _maps() -> int:
    with open("/proc/self/maps") as f:
        return sum(1 for _ in f)


@pytest.mark.skipif(not os.path.exists("/proc/self/maps"), reason="Linux's /proc tells a process's memory maps")
def test_compiled_programs_are_dropped_past_the_share_and_kept_below_it():
    f = jax.jit(lambda x: jnp.cumsum(jnp.sin(x) @ jnp.cos(x).T, axis=0))
    for n in range(2, 40):
        f(jnp.ones((n, 3))).block_until_ready()
    assert f._cache_size() == 38
    assert relieve_compiled_programs(share=1e9) is False and f._cache_size() == 38
    before = _maps()
    assert relieve_compiled_programs(share=0.0) is True
    assert f._cache_size() == 0 and _maps() < before
