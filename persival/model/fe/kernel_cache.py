"""Keep numba's on-disk kernel cache honest across modules.

numba's ``cache=True`` keys a compiled kernel by its own source file only. The element kernel of
:mod:`persival.model.fe.assembly` inlines the constitutive law of :mod:`persival.model.fe.material`, so
after a change of the law numba would keep serving the kernel compiled with the old one. That
happened: the fibre-reference fix (docs/theory.md, 1.6) passed the law's own tests (material.py's kernels were
recompiled) while every FE solve still ran the old law from assembly's cached kernel.
:func:`drop_stale_kernels` keeps a hash of the dependencies' sources beside the cache and removes
the module's cached kernels when it changes, before numba looks at them.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["drop_stale_kernels"]


def _cache_dirs(module_file: Path) -> list[Path]:
    """Where numba may keep the module's kernels: __pycache__ beside it, or under NUMBA_CACHE_DIR."""
    dirs = [module_file.parent / "__pycache__"]
    if os.environ.get("NUMBA_CACHE_DIR"):
        dirs += [p for p in Path(os.environ["NUMBA_CACHE_DIR"]).rglob("*") if p.is_dir()]
    return dirs


def drop_stale_kernels(module_file: str, dependencies: list[str]) -> bool:
    """Remove the cached numba kernels of ``module_file`` if any of ``dependencies`` (source files
    whose njit functions it calls) changed since they were compiled. Returns True if it removed some."""
    module = Path(module_file)
    digest = hashlib.sha256(b"".join(Path(d).read_bytes() for d in dependencies)).hexdigest()
    removed = False
    for folder in _cache_dirs(module):
        stamp = folder / f"{module.stem}.dependencies.sha256"
        try:
            if stamp.exists() and stamp.read_text() == digest:
                continue
            kernels = list(folder.glob(f"{module.stem}.*.nbi")) + list(folder.glob(f"{module.stem}.*.nbc"))
            for path in kernels:
                path.unlink(missing_ok=True)
            removed = removed or bool(kernels)
            if folder.is_dir():
                stamp.write_text(digest)
        except OSError:
            pass  # a read-only install: numba recompiles or uses its own cache folder
    return removed
