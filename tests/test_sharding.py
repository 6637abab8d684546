"""Batch fits spread over every local device (jax.sharding), checked on a CPU that XLA splits into four."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np

SCRIPT = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from diffwash import km, pigments
    from diffwash.fit import _kmfit, fit_table, read_table

    assert jax.local_device_count() == 4, jax.devices()
    seen = []
    unpad = _kmfit.unpad
    def spy(tree, size):
        seen.append(len(jax.tree.leaves(tree)[0].sharding.device_set))
        return unpad(tree, size)
    _kmfit.unpad = spy

    names = ["Burnt Umber", "Hansa Yellow", "Cerulean Blue"]  # three pigments on four devices: one padded
    paper, ink = np.array([0.92, 0.9, 0.84]), np.array([0.035, 0.035, 0.04])
    lines = ["pigment,amount,ground,r,g,b", "paper,0,paper," + ",".join(map(str, paper)),
             "black,0,black," + ",".join(map(str, ink))]
    for n in names:
        p = pigments.load(n)
        for a in (0.5, 1, 3):
            for g, Rg in (("paper", paper), ("black", ink)):
                R, T = km.layer(p.K, p.S, a)
                lines.append(f"{n},{a},{g}," + ",".join(f"{v:.12f}" for v in np.asarray(km.over(R, T, Rg))))
    open(sys.argv[1], "w").write("\\n".join(lines) + "\\n")
    table = read_table(sys.argv[1], linear=True)
    out = {}
    for batch in ("vmap", "loop"):
        fit = fit_table(table, batch=batch)
        out[batch] = {"K": [np.asarray(p.K).tolist() for p in fit.pigments],
                      "S": [np.asarray(p.S).tolist() for p in fit.pigments], "converged": list(map(bool, fit.converged))}
    out["devices_seen"] = seen
    print(json.dumps(out))
    """
)


def test_vmapped_table_fit_shards_over_four_devices_and_agrees_with_the_loop(tmp_path):
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=4", "JAX_PLATFORMS": "cpu"}
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path / "t.csv")], env=env, capture_output=True,
                       text=True, timeout=900)  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    # Every vmapped start ran on all four devices (the loop's single pigments never reach the sharding).
    assert out["devices_seen"] and set(out["devices_seen"]) == {4}
    assert all(out["vmap"]["converged"]) and all(out["loop"]["converged"])
    np.testing.assert_allclose(out["vmap"]["K"], out["loop"]["K"], rtol=1e-7)
    np.testing.assert_allclose(out["vmap"]["S"], out["loop"]["S"], rtol=1e-7)


def test_one_device_is_left_alone():
    import jax.numpy as jnp

    from diffwash._shard import shard_leading, unpad

    x = {"a": jnp.arange(3.0)}
    y, padded = shard_leading(x, 3)
    assert padded == 3 and y is x
    assert unpad({"a": jnp.arange(4.0)}, 3)["a"].shape == (3,)
