"""JAX's persistent compilation cache, as the command line turns it on, leaves results unchanged
and makes a second run load every compiled function instead of compiling it again.

Two fresh interpreters share a temporary cache directory (never the user's): the first compiles
and writes, the second must write nothing new and print the same numbers to the last bit. The
workload is the main job's Figure 3 part on a short horizon (same compiled code paths: the
stability check, ``simulate_sequence``, curvature areas).
"""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

SCRIPT = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    from pmpjax._app.cache import enable_compilation_cache  # the command line's own switch
    enable_compilation_cache(sys.argv[1])
    import numpy as np
    import pmpjax as pj
    d = pj.figure3_data(duration=0.02, save_every=4)
    print(json.dumps({k: np.asarray(d[k]).ravel().tolist() for k in ("q", "x", "A_sum", "A_net")}))
    """
)


def _run(cache: Path) -> dict:
    # Not the test run's shared cache (tests/conftest.py exports it): only the directory given here.
    env = {k: v for k, v in os.environ.items() if "CACHE" not in k or not k.startswith(("JAX_", "PMPJAX_"))}
    env["JAX_PLATFORMS"] = "cpu"
    p = subprocess.run([sys.executable, "-c", SCRIPT, str(cache)], capture_output=True, text=True, env=env,
                       timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def test_second_run_loads_everything_from_the_cache_with_identical_results(tmp_path):
    cache = tmp_path / "jax-cache"
    first = _run(cache)
    entries = sorted(p.name for p in cache.iterdir())
    assert len(entries) >= 2, entries  # simulate's kernel and the stability check were cached
    second = _run(cache)
    assert sorted(p.name for p in cache.iterdir()) == entries, "the second run compiled something again"
    assert second == first  # bitwise: JSON floats round-trip exactly
