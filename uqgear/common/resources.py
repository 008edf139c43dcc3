"""Files shipped inside the package: bundled designs, studies and example rig campaigns.

They live in ``uqgear/data/`` and are found with :mod:`importlib.resources`,
so a wheel installed anywhere finds them exactly as a source checkout does
(the repository's top-level ``studies/`` and ``data/designs/`` point there).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from .errors import UqgearError

#: Kinds of bundled file: folder under ``uqgear/data`` and file suffix.
_KINDS: dict[str, tuple[str, str]] = {
    "design": ("designs", ".yaml"),
    "study": ("studies", ".yaml"),
    "rig": ("rig", ".nc"),
}


class ResourceError(UqgearError):
    """A bundled file was asked for by a name the package does not ship."""


def _folder(kind: str) -> Path:
    folder, _ = _KINDS[kind]
    root = resources.files("uqgear") / "data" / folder
    path = Path(str(root))
    if not path.is_dir():
        # every supported install (wheel, sdist, checkout) unpacks to real files
        raise RuntimeError(f"internal error: the package's data folder {path} is missing; reinstall uqgear")
    return path


def bundled_names(kind: str) -> tuple[str, ...]:
    """Names (file stems) of the bundled files of one kind, sorted.

    Parameters
    ----------
    kind : {"design", "study", "rig"}

    Returns
    -------
    tuple of str
    """
    if kind not in _KINDS:
        raise ValueError(f"kind: expected one of {', '.join(_KINDS)}; got {kind!r}")
    _, suffix = _KINDS[kind]
    return tuple(sorted(path.stem for path in _folder(kind).iterdir() if path.suffix == suffix))


def bundled_file(kind: str, name: str) -> Path:
    """Path of the bundled file ``name`` of one kind.

    Parameters
    ----------
    kind : {"design", "study", "rig"}
    name : str
        The file's stem (``"locomotive"``, ``"smoke"``, ``"healthy"``); the
        suffix may be given too.

    Raises
    ------
    ResourceError
        No bundled file of that kind has that name (the message lists them).
    """
    names = bundled_names(kind)
    folder, suffix = _KINDS[kind]
    stem = name[: -len(suffix)] if isinstance(name, str) and name.endswith(suffix) else name
    if stem not in names:
        shown = name if isinstance(name, str) else repr(name)
        raise ResourceError(f"{shown[:80]!r}: not a bundled {kind} (bundled: {', '.join(names) or 'none'})")
    return _folder(kind) / f"{stem}{suffix}"


def example_rig_file(name: str = "healthy") -> Path:
    """Path of a labelled rig campaign shipped with the package.

    Parameters
    ----------
    name : str
        ``"healthy"`` (default) or ``"eccentricity"``; see
        :func:`bundled_names` with ``"rig"`` for the list.

    Returns
    -------
    pathlib.Path
        A ``uqgear-rig/1`` netCDF file to try ``uqgear calibrate`` or
        ``uqgear diagnose`` on.
    """
    return bundled_file("rig", name)


__all__ = ["ResourceError", "bundled_names", "bundled_file", "example_rig_file"]
