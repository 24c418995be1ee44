"""JAX's persistent compilation cache, as the main job and its worker processes turn it on."""

from __future__ import annotations

import os
from pathlib import Path


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path:
    """Turn on JAX's persistent compilation cache at ``path`` (default ``$PMPJAX_CACHE_DIR`` or
    ``~/.cache/pmpjax/jax``) for every compiled function, however quick to compile."""
    import jax

    cache = Path(path or os.environ.get("PMPJAX_CACHE_DIR") or Path.home() / ".cache" / "pmpjax" / "jax")
    cache.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return cache
