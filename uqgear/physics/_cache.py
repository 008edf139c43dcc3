"""The compiled kernels' on-disk cache, stale as soon as any compiled module of the package changes.

numba keys a cached kernel on the source of the file that defines it. The
kernels here inline helpers from other files (every family steps with
:mod:`uqgear.physics._rhs`; the pair path, the lanes and the calibration's
harmonic balance build on it), so a cache keyed on one file would keep
serving a kernel compiled from an earlier version of a helper. The locators
below key every cached kernel of the package on the contents of all its
compiled modules together: editing any of them recompiles every kernel
once, and a warm cache always holds the code that is on disk. Functions
elsewhere keep numba's own locators.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Any

from numba.core import caching

PACKAGE_ROOT = Path(__file__).resolve().parent.parent
#: The package's modules whose compiled functions call into each other (relative to the package root).
COMPILED_MODULES = (
    "physics/_rhs.py",
    "physics/_stepper.py",
    "physics/_quotient.py",
    "physics/_batch_record.py",
    "physics/_pairs.py",
    "physics/_pair_extremes.py",
    "physics/_kernels.py",
    "physics/_lane_loop.py",
    "physics/_lanes.py",
    "physics/_pair_lanes.py",
    "physics/_lane_tables.py",
    "physics/_variational.py",
    "physics/_runup_kernels.py",
    "physics/_runup_lanes.py",
    "physics/kernels.py",
    "calibration/harmonics.py",
    "rig/foreign_rig.py",
    "rig/foreign_response.py",
    "rig/foreign_runup.py",
)


@functools.cache
def package_stamp() -> bytes:
    """SHA-256 of the compiled modules' contents, in :data:`COMPILED_MODULES` order (once per process)."""
    digest = hashlib.sha256()
    for name in COMPILED_MODULES:
        digest.update(name.encode())
        digest.update((PACKAGE_ROOT / name).read_bytes())
    return digest.digest()


def _compiled_module(py_file: str) -> bool:
    try:
        return Path(py_file).resolve() in {PACKAGE_ROOT / name for name in COMPILED_MODULES}
    except OSError:
        return False


class _PackageStamp:
    """Locator mixin: a kernel of the package is fresh only for the package's current compiled sources."""

    def get_source_stamp(self) -> Any:
        return package_stamp()

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> Any:
        if not _compiled_module(py_file):
            return None
        return super().from_function(py_func, py_file)  # type: ignore[misc]


class UserProvidedKernelLocator(_PackageStamp, caching.UserProvidedCacheLocator):
    """numba's locator for a cache folder the user names (``NUMBA_CACHE_DIR``) with the package-wide stamp."""


class InTreeKernelLocator(_PackageStamp, caching.InTreeCacheLocator):
    """numba's ``__pycache__`` locator with the package-wide stamp."""


class UserWideKernelLocator(_PackageStamp, caching.UserWideCacheLocator):
    """numba's user-wide locator (read-only installations) with the package-wide stamp."""


def register_kernel_cache() -> bool:
    """Put the package's locators before numba's own (once); False where this numba has no locator list."""
    locators = getattr(caching.CacheImpl, "_locator_classes", None)
    if not isinstance(locators, list):
        return False
    # numba's order: a folder the user names, then __pycache__, then the user-wide folder
    for locator in (UserWideKernelLocator, InTreeKernelLocator, UserProvidedKernelLocator):
        if locator not in locators:
            locators.insert(0, locator)
    return True


__all__ = [
    "COMPILED_MODULES",
    "package_stamp",
    "register_kernel_cache",
    "UserProvidedKernelLocator",
    "InTreeKernelLocator",
    "UserWideKernelLocator",
]
