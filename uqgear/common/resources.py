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

    Examples
    --------
    >>> import uqgear
    >>> uqgear.bundled_names("design")
    ('locomotive', 'pair_17_38')
    >>> "smoke" in uqgear.bundled_names("study"), "eccentricity" in uqgear.bundled_names("rig")
    (True, True)
    >>> all(uqgear.example_rig_file(name).is_file() for name in uqgear.bundled_names("rig"))
    True
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


def bundled_by_name(kind: str, text: str, candidate: Path) -> Path | None:
    """The bundled file that ``text`` names, when it can only mean that one.

    ``text`` as typed by the user and ``candidate`` the path it resolves to;
    the bundled file is meant when ``candidate`` does not exist and ``text``
    is a bare name (no suffix, no folder) of a bundled file of ``kind``.
    Otherwise None: the caller goes on with ``candidate``.
    """
    bare = isinstance(text, str) and not Path(text).suffix and Path(text).name == text
    if bare and not candidate.exists() and text in bundled_names(kind):
        return bundled_file(kind, text)
    return None


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

    Examples
    --------
    >>> import uqgear
    >>> path = uqgear.example_rig_file("healthy")
    >>> path.name, path.is_file()
    ('healthy.nc', True)
    >>> rig = uqgear.read_rig(path)
    >>> rig.attrs["conventions"], rig.sizes["op"], list(rig.data_vars)
    ('uqgear-rig/1', 8, ['te', 'acc_pinion', 'acc_gear'])
    >>> try:
    ...     uqgear.example_rig_file("broken")
    ... except uqgear.UqgearError as error:
    ...     print(str(error).split(" (")[0])
    'broken': not a bundled rig
    """
    return bundled_file("rig", name)


__all__ = ["ResourceError", "bundled_names", "bundled_file", "bundled_by_name", "example_rig_file"]
