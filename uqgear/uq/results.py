"""Analysis results on disk: netCDF files with provenance, written atomically.

A result is an :class:`xarray.Dataset`. :func:`save_result` stamps it with
provenance (package versions, seed, design, study text, creation time) and
writes it to netCDF; :func:`load_result` reads it back fully into memory.

netCDF attributes can only hold strings, numbers and 1-D numeric arrays, while
results carry booleans, ``None``, nested mappings and lists of labels. Such
attributes are stored as text (JSON) or small integers, and the names of the
attributes that were converted are recorded, per variable, in the attribute
``uqgear_encoded_attrs``, so that reading restores the original values and a
saved-and-loaded dataset is identical to the one saved.

Files are written under a temporary name in the target folder and renamed into
place, so a crash or an error never leaves a half-written result behind and an
existing file at the target path stays intact until the new one is complete.
"""

from __future__ import annotations

import json
import os
import platform
from collections.abc import Hashable, Mapping
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import xarray as xr

from ..common.errors import UqgearError
from ..common.fileio import atomic_path

if TYPE_CHECKING:
    from ..physics.design import Design

#: Attribute listing, as a JSON object ``{name: kind}``, the attributes of a
#: variable or dataset that were converted to be storable in netCDF.
ENCODED_ATTRS_MARKER = "uqgear_encoded_attrs"

#: Attributes added by :func:`save_result`.
PROVENANCE_ATTRS: tuple[str, ...] = (
    "uqgear_version",
    "provenance_versions",
    "numba_target_cpu",
    "created",
    "seed",
    "seed_spawn_key",
    "design",
    "study",
)

#: Distributions whose versions are recorded in ``provenance_versions``.
_PROVENANCE_PACKAGES: tuple[str, ...] = (
    "numpy",
    "scipy",
    "xarray",
    "netCDF4",
    "chaospy",
    "SALib",
    "emcee",
    "numba",
    "llvmlite",
)

_FALLBACK_VERSION = "0.1.0"
_INT64 = np.iinfo(np.int64)
_NETCDF_ENGINE: Final = "netcdf4"


def uqgear_version() -> str:
    """The installed uqgear version, or ``"0.1.0"`` when running from a source checkout."""
    try:
        return metadata.version("uqgear")
    except metadata.PackageNotFoundError:
        return _FALLBACK_VERSION


def package_versions() -> dict[str, str]:
    """Versions of Python, uqgear and the numerical packages a result depends on.

    Returns
    -------
    dict of str to str
        Distribution name to version; ``"not installed"`` for a missing one.
    """
    versions = {"python": platform.python_version(), "uqgear": uqgear_version()}
    for name in _PROVENANCE_PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def numba_target_cpu() -> str:
    """The CPU name numba compiles the kernels for (``NUMBA_CPU_NAME`` or the host's).

    The kernels use no fast-math, so their results should not depend on it;
    it is recorded so that a difference between machines can be traced from
    the output files alone.
    """
    from numba.core import config

    # numba.config's options are module attributes it sets at import: no static type knows them
    if config.CPU_NAME:  # type: ignore[attr-defined]
        return str(config.CPU_NAME)  # type: ignore[attr-defined]
    import llvmlite.binding

    return str(llvmlite.binding.get_host_cpu_name())


# --------------------------------------------------------------------------- attributes


def json_default(value: Any) -> Any:
    """``json.dumps`` default: numpy scalars and arrays nested inside lists and dicts."""
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _encode_value(value: Any, where: str) -> tuple[Any, str | None]:
    """An attribute value netCDF can store, and the kind of conversion (None: unchanged)."""
    if value is None:
        return "null", "json"
    if isinstance(value, (bool, np.bool_)):
        return np.int8(value), "bool"
    if isinstance(value, str):
        return value, None
    if isinstance(value, (int, np.integer)):
        if _INT64.min <= int(value) <= _INT64.max:
            return value, None
        return json.dumps(int(value)), "json"
    if isinstance(value, (float, np.floating)):
        return value, None
    if isinstance(value, np.ndarray):
        # netCDF attributes are 1-D and a length-1 array reads back as a scalar
        if value.ndim == 1 and value.size >= 2 and value.dtype.kind in "iuf" and value.dtype != np.float16:
            return value, None
        if value.dtype.kind not in "biuf":
            raise UqgearError(
                f"{where}: cannot store an attribute array of dtype {value.dtype} "
                "in netCDF; expected a numeric or boolean array"
            )
        text = json.dumps({"dtype": value.dtype.str, "shape": list(value.shape), "data": value.tolist()})
        return text, "ndarray"
    if isinstance(value, (list, tuple, dict)):
        # lists always go through JSON: a netCDF list of one element reads back
        # as a scalar and a list of strings may not be storable at all
        try:
            return json.dumps(value, default=json_default), "json"
        except (TypeError, ValueError) as exc:
            raise UqgearError(
                f"{where}: cannot store this attribute in netCDF ({exc}); "
                "expected lists/dicts of strings, numbers, booleans or None"
            ) from None
    raise UqgearError(
        f"{where}: cannot store an attribute of type {type(value).__name__} in "
        "netCDF; expected a string, number, bool, None, list, dict or numpy array"
    )


def _encode_attrs(attrs: Mapping[Hashable, Any], where: str) -> dict[str, Any]:
    encoded: dict[str, Any] = {}
    kinds: dict[str, str] = {}
    for name, value in attrs.items():
        if name == ENCODED_ATTRS_MARKER:
            continue
        if not isinstance(name, str):
            raise UqgearError(
                f"{where}attribute {name!r}: netCDF attribute names must be strings; got {type(name).__name__}"
            )
        stored, kind = _encode_value(value, f"{where}attribute {name!r}")
        encoded[name] = stored
        if kind is not None:
            kinds[name] = kind
    if kinds:
        encoded[ENCODED_ATTRS_MARKER] = json.dumps(kinds, sort_keys=True)
    return encoded


def _decode_value(stored: Any, kind: str, where: str) -> Any:
    try:
        if kind == "json":
            return json.loads(stored)
        if kind == "bool":
            return bool(int(stored))
        if kind == "ndarray":
            spec = json.loads(stored)
            return np.asarray(spec["data"], dtype=np.dtype(spec["dtype"])).reshape(spec["shape"])
    except (TypeError, ValueError, KeyError) as exc:
        raise UqgearError(f"{where}: cannot decode the stored {kind} value ({exc})") from None
    raise UqgearError(
        f"{where}: unknown attribute encoding {kind!r}; expected json, bool or "
        "ndarray (file written by a newer uqgear?)"
    )


def _decode_attrs(attrs: Mapping[Hashable, Any], where: str) -> dict[Hashable, Any]:
    decoded = dict(attrs)
    marker = decoded.pop(ENCODED_ATTRS_MARKER, None)
    if marker is None:
        return decoded
    try:
        kinds = json.loads(marker)
    except (TypeError, ValueError):
        raise UqgearError(f"{where}{ENCODED_ATTRS_MARKER}: expected a JSON object; got {marker!r}") from None
    for name, kind in kinds.items():
        if name in decoded:
            decoded[name] = _decode_value(decoded[name], kind, f"{where}attribute {name!r}")
    return decoded


def _encode_dataset(ds: xr.Dataset) -> xr.Dataset:
    # shallow copy: values are shared, attrs dicts are replaced, the caller's dataset is untouched
    encoded = ds.copy(deep=False)
    encoded.attrs = _encode_attrs(ds.attrs, "")
    for name, variable in encoded.variables.items():
        variable.attrs = _encode_attrs(ds.variables[name].attrs, f"variable {name!r}: ")
    return encoded


def _as_unicode(values: np.ndarray) -> np.ndarray | None:
    """Object arrays of strings (how netCDF strings read back) as numpy unicode arrays."""
    if values.dtype != object or values.size == 0:
        return None
    if not all(isinstance(item, str) for item in values.flat):
        return None
    return values.astype(str)


def _decode_dataset(ds: xr.Dataset, where: str) -> xr.Dataset:
    ds.attrs = _decode_attrs(ds.attrs, f"{where}: ")
    for name, variable in ds.variables.items():
        variable.attrs = _decode_attrs(variable.attrs, f"{where}: variable {name!r}: ")
    replacements = {}
    for name, variable in ds.variables.items():
        unicode = _as_unicode(variable.values)
        if unicode is not None:
            replacements[name] = variable.copy(data=unicode)
    for name, variable in replacements.items():
        if name in ds.coords:
            ds = ds.assign_coords({name: variable})
        else:
            ds[name] = variable
    return ds


# --------------------------------------------------------------------------- files


def write_dataset(ds: xr.Dataset, path: str | os.PathLike[str]) -> Path:
    """Write a dataset to netCDF atomically, with attributes made storable.

    Parameters
    ----------
    ds : xarray.Dataset
        The dataset; it is not modified.
    path : str or path-like
        Target file. Its folder must exist; an existing file is replaced only
        once the new one is completely written.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    UqgearError
        If the folder does not exist, an attribute cannot be stored, or writing fails.
    """
    if not isinstance(ds, xr.Dataset):
        raise UqgearError(f"{path}: expected an xarray Dataset to write; got {type(ds).__name__}")
    target = Path(path)
    folder = target.parent
    if not folder.is_dir():
        raise UqgearError(f"{target}: the folder {folder} does not exist; create it or choose another output path")
    if target.is_dir():
        raise UqgearError(f"{target}: is a folder; expected a file path for the netCDF output")
    encoded = _encode_dataset(ds)
    try:
        with atomic_path(target) as temporary:
            encoded.to_netcdf(temporary, engine=_NETCDF_ENGINE)
    except (OSError, ValueError, TypeError, RuntimeError) as exc:
        raise UqgearError(f"{target}: could not write the netCDF file ({type(exc).__name__}: {exc})") from exc
    return target


def read_dataset(path: str | os.PathLike[str]) -> xr.Dataset:
    """Read a netCDF file written by :func:`write_dataset` fully into memory.

    The file is closed on return; attributes converted on writing are restored
    and string variables are numpy unicode arrays.

    Raises
    ------
    UqgearError
        If the file does not exist or is not a readable netCDF file.
    """
    source = Path(path)
    if not source.is_file():
        raise UqgearError(f"{source}: no such file; expected a netCDF result file")
    try:
        with xr.open_dataset(source, engine=_NETCDF_ENGINE) as opened:
            ds = opened.load()
    except (OSError, ValueError, TypeError, RuntimeError) as exc:
        raise UqgearError(f"{source}: not a readable netCDF file ({type(exc).__name__}: {exc})") from None
    return _decode_dataset(ds, str(source))


# --------------------------------------------------------------------------- results


def _seed_attrs(seed: int | np.random.SeedSequence) -> dict[str, str]:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer, np.random.SeedSequence)):
        raise UqgearError(f"seed: expected a non-negative integer or a numpy SeedSequence; got {seed!r}")
    if not isinstance(seed, np.random.SeedSequence):
        if int(seed) < 0:
            raise UqgearError(f"seed: expected a non-negative integer; got {seed!r}")
        seed = np.random.SeedSequence(int(seed))
    entropy = seed.entropy
    # entropy is usually a 128-bit integer, too large for a netCDF integer attribute
    attrs = {
        "seed": str(entropy)
        if isinstance(entropy, (int, np.integer))
        else json.dumps(list(np.asarray(entropy).tolist()))
    }
    if seed.spawn_key:
        attrs["seed_spawn_key"] = json.dumps([int(k) for k in seed.spawn_key])
    return attrs


def provenance_attrs(
    *,
    seed: int | np.random.SeedSequence | None = None,
    design: Design | str | None = None,
    study_text: str | None = None,
) -> dict[str, str]:
    """The provenance attributes :func:`save_result` adds to a result.

    Parameters
    ----------
    seed : int or numpy.random.SeedSequence, optional
        The seed of the analysis; stored as the decimal text of its entropy
        (``numpy.random.SeedSequence(int(attrs["seed"]))`` rebuilds it), plus
        ``seed_spawn_key`` for a spawned sequence.
    design : Design or str, optional
        The nominal design, stored as the JSON text of its keys (the rig
        format's ``design`` attribute; ``design_from_json`` reads it back).
    study_text : str, optional
        The study definition (YAML text) as given by the user.

    Returns
    -------
    dict of str to str
    """
    attrs = {
        "uqgear_version": uqgear_version(),
        "provenance_versions": json.dumps(package_versions(), sort_keys=True),
        "numba_target_cpu": numba_target_cpu(),
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    if seed is not None:
        attrs.update(_seed_attrs(seed))
    if design is not None:
        if isinstance(design, str):
            try:
                json.loads(design)
            except ValueError:
                raise UqgearError(f"design: expected a Design or its JSON text; got {design[:60]!r}") from None
            attrs["design"] = design
        elif callable(getattr(design, "to_json", None)):
            attrs["design"] = design.to_json()
        else:
            raise UqgearError(f"design: expected a Design or its JSON text; got {type(design).__name__}")
    if study_text is not None:
        if not isinstance(study_text, str):
            raise UqgearError(f"study_text: expected the study YAML as a string; got {type(study_text).__name__}")
        attrs["study"] = study_text
    return attrs


def save_result(
    ds: xr.Dataset,
    path: str | os.PathLike[str],
    *,
    seed: int | np.random.SeedSequence | None = None,
    design: Design | str | None = None,
    study_text: str | None = None,
) -> Path:
    """Save an analysis result as netCDF with provenance attributes.

    Parameters
    ----------
    ds : xarray.Dataset
        The result; it is not modified. Its attributes may be strings,
        numbers, booleans, None, lists, dicts and numpy arrays.
    path : str or path-like
        Output file; its folder must exist. Written atomically.
    seed, design, study_text
        Provenance, see :func:`provenance_attrs`. Package versions, the
        uqgear version and the UTC creation time are always added.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    UqgearError
        If the folder does not exist, an attribute cannot be stored or a
        provenance argument has the wrong type.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import xarray as xr
    >>> import uqgear
    >>> result = xr.Dataset({"dte_rms": ("bound", [6.25e-6, 13.07e-6], {"units": "m"})},
    ...                     coords={"bound": ["lower", "upper"]}, attrs={"method": "vertex"})
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = uqgear.save_result(result, pathlib.Path(folder) / "band.nc", seed=1,
    ...                               design=uqgear.load_design("locomotive"))
    ...     saved = uqgear.load_result(path)
    >>> path.name, bool((saved["dte_rms"] == result["dte_rms"]).all()), saved["dte_rms"].attrs["units"]
    ('band.nc', True, 'm')
    >>> saved.attrs["method"], saved.attrs["seed"], "uqgear_version" in saved.attrs, "created" in saved.attrs
    ('vertex', '1', True, True)
    >>> "seed" in result.attrs                  # the Dataset saved is not changed
    False
    """
    if not isinstance(ds, xr.Dataset):
        raise UqgearError(f"{path}: expected an xarray Dataset to save; got {type(ds).__name__}")
    stamped = ds.copy(deep=False)
    # provenance of an earlier save (a loaded result saved again) is replaced, not mixed
    stamped.attrs = {name: value for name, value in ds.attrs.items() if name not in PROVENANCE_ATTRS}
    stamped.attrs.update(provenance_attrs(seed=seed, design=design, study_text=study_text))
    return write_dataset(stamped, path)


def load_result(path: str | os.PathLike[str]) -> xr.Dataset:
    """Load a result saved with :func:`save_result` into memory (the file is closed).

    Attributes stored as JSON by :func:`save_result` are decoded back to their
    original values; the provenance attributes ``provenance_versions`` and
    ``design`` stay JSON text.

    Raises
    ------
    UqgearError
        If the file does not exist or is not a readable netCDF file.

    Examples
    --------
    Attributes that netCDF cannot hold (a dict, a list of strings) come back
    as they were saved:

    >>> import pathlib, tempfile
    >>> import xarray as xr
    >>> import uqgear
    >>> result = xr.Dataset({"y": ("bound", [0.0, 0.49])},
    ...                     attrs={"units": {"y": "m"}, "parameters": ["a", "b"], "runs": 9})
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     loaded = uqgear.load_result(uqgear.save_result(result, pathlib.Path(folder) / "result.nc"))
    >>> loaded.attrs["units"], loaded.attrs["parameters"], int(loaded.attrs["runs"])
    ({'y': 'm'}, ['a', 'b'], 9)
    >>> loaded["y"].values.tolist()
    [0.0, 0.49]
    >>> try:
    ...     uqgear.load_result("missing/result.nc")
    ... except uqgear.UqgearError as error:
    ...     print(type(error).__name__)
    UqgearError
    """
    return read_dataset(path)


__all__ = [
    "save_result",
    "load_result",
    "write_dataset",
    "read_dataset",
    "provenance_attrs",
    "package_versions",
    "numba_target_cpu",
    "uqgear_version",
    "PROVENANCE_ATTRS",
    "ENCODED_ATTRS_MARKER",
]
