"""The compiled kernels' cache is keyed on every compiled module of the package, not on the kernel's file alone."""

import hashlib
import shutil

import numba

from uqgear.calibration import harmonics
from uqgear.physics import (
    _cache,
    _kernels,
    _lane_loop,
    _lane_tables,
    _lanes,
    _pair_lanes,
    _pairs,
    _runup_kernels,
    _runup_lanes,
    _stepper,
    _variational,
)
from uqgear.rig import foreign_response, foreign_rig


def _dispatchers(module):
    return [value for value in vars(module).values() if isinstance(value, numba.core.registry.CPUDispatcher)]


def test_every_kernel_of_the_compiled_modules_is_located_with_the_package_stamp():
    modules = (
        _kernels,
        _stepper,
        _pairs,
        _lane_loop,
        _lanes,
        _pair_lanes,
        _lane_tables,
        _runup_kernels,
        _runup_lanes,
        _variational,
        harmonics,
        foreign_rig,
        foreign_response,
    )
    for module in modules:
        kernels = [kernel for kernel in _dispatchers(module) if kernel._cache._impl is not None]
        assert kernels, module.__name__
        for kernel in kernels:
            assert isinstance(kernel._cache._impl.locator, _cache.InTreeKernelLocator), (module.__name__, kernel)
    # the foreign rig's response kernel steps with the foreign rig's own: both are keyed on the package stamp
    assert {"rig/foreign_rig.py", "rig/foreign_response.py"} <= set(_cache.COMPILED_MODULES)


def test_the_stamp_is_the_digest_of_all_compiled_modules_and_follows_an_edit_of_any(tmp_path, monkeypatch):
    digest = hashlib.sha256()
    for name in _cache.COMPILED_MODULES:
        digest.update(name.encode())
        digest.update((_cache.PACKAGE_ROOT / name).read_bytes())
    assert _cache.package_stamp() == digest.digest()
    locator = _cache.InTreeKernelLocator.from_function(_kernels.integrate_history.py_func, _kernels.__file__)
    assert locator.get_source_stamp() == digest.digest()
    # an edited helper (the right-hand side every family inlines) makes every kernel's cache stale
    for name in _cache.COMPILED_MODULES:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(_cache.PACKAGE_ROOT / name, tmp_path / name)
    monkeypatch.setattr(_cache, "PACKAGE_ROOT", tmp_path)
    _cache.package_stamp.cache_clear()
    try:
        unchanged = _cache.package_stamp()
        with open(tmp_path / "physics/_rhs.py", "a") as handle:
            handle.write("\n# edited\n")
        _cache.package_stamp.cache_clear()
        assert unchanged == digest.digest() and _cache.package_stamp() != unchanged
    finally:
        _cache.package_stamp.cache_clear()


def test_a_function_outside_the_compiled_modules_gets_numbas_own_locators():
    assert _cache.InTreeKernelLocator.from_function(_kernels.integrate_history.py_func, shutil.__file__) is None
    assert _cache.register_kernel_cache()  # registered already: registering again changes nothing
    locators = numba.core.caching.CacheImpl._locator_classes
    assert locators.count(_cache.InTreeKernelLocator) == 1
