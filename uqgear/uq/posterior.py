"""A calibration's posterior as an input: joint draws of the calibrated parameters.

A :class:`PosteriorDraws` holds the global parameters of a posterior (mesh
stiffness scale, mesh damping, backlash, ...) as rows of joint draws, so that
their dependence travels with them: an analysis that propagates them takes
whole rows, never the marginals. It is read from a ``uqgear calibrate``
output (``posterior.nc``), from the Dataset of a ``calibrate`` analysis, or
from a fitted :class:`~uqgear.calibration.Calibration` (its ``posterior_``),
and thinned to a given number of draws with a seed.

The per-run adhesion torques of the posterior (dim ``op``) are left out: they
belong to the rig's operating points, and a prediction keeps T2 an interval.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import ParameterSpaceError
from .seeds import SeedLike, as_seed_sequence

#: Draws a study takes from a posterior when it does not say (thinned, seeded).
DEFAULT_DRAWS = 64


class PosteriorError(ParameterSpaceError):
    """A posterior cannot be used as an input (not converged, another design, unreadable).

    Examples
    --------
    >>> import uqgear
    >>> issubclass(uqgear.PosteriorError, ValueError)
    True
    """


def _global_names(posterior: xr.Dataset, source: str) -> list[str]:
    listed = posterior.attrs.get("parameters")
    names = json.loads(listed) if isinstance(listed, str) else None
    if names is None:
        names = [name for name, values in posterior.data_vars.items() if values.dims == ("chain", "draw")]
        names = [name for name in names if name != "log_likelihood"]
    missing = [name for name in names if name not in posterior.data_vars]
    if not names or missing:
        raise PosteriorError(
            f"{source}: expected a posterior with draws (dims chain, draw) of the calibrated parameters; "
            f"got {'none' if not names else 'no variable ' + repr(missing[0])}"
        )
    return [str(name) for name in names]


def read_posterior(path: str | os.PathLike[str]) -> xr.Dataset:
    """The Dataset of a ``posterior.nc`` (``uqgear calibrate``, or a ``calibrate`` analysis's file), loaded.

    Raises
    ------
    PosteriorError
        The file is missing or unreadable.
    """
    location = Path(path)
    if not location.is_file():
        raise PosteriorError(f"{location}: posterior file not found; expected a posterior.nc of uqgear calibrate")
    try:
        with xr.open_dataset(location) as opened:
            return opened.load()
    except (OSError, ValueError) as exc:
        raise PosteriorError(f"{location}: cannot read the posterior ({exc})") from None


@dataclass(frozen=True)
class PosteriorDraws:
    """Joint draws of calibrated parameters.

    Parameters
    ----------
    names : tuple of str
        The parameters, one column each.
    values : numpy.ndarray
        Shape ``(draws, len(names))``; each row one joint draw.
    converged : bool
        Whether the sampler's convergence checks passed.
    source : str
        Where the draws come from (a file, an analysis), for messages and reports.
    design : dict, optional
        The design the calibration ran on (``Design.to_dict()``), for the check
        against a study's design.
    units : dict, optional
        Name -> units.
    campaign : dict, optional
        The rig campaign's operating range the posterior was learnt on:
        ``pinion_speed``, ``drive_torque``, ``adhesion_torque`` -> (lowest,
        highest); a prediction flags what lies outside it.
    discrepancy_beta : numpy.ndarray, optional
        Shape ``(draws, channel, harmonic, basis)``: with each row, the draw of
        the model discrepancy's coefficients drawn with it (a calibration with
        ``discrepancy=True``; ``posterior.nc``'s ``discrepancy_beta``), so that
        a prediction carries the discrepancy that goes with each row's
        parameters. Thinning keeps it aligned.

    Examples
    --------
    A posterior of known mean and covariance, as a calibration would write it:

    >>> import numpy as np, xarray as xr
    >>> import uqgear
    >>> rng = np.random.default_rng(0)
    >>> rows = rng.multivariate_normal([1.0, 0.05], [[1e-4, 4e-7], [4e-7, 4e-6]], size=(8, 50))
    >>> posterior = xr.Dataset({"mesh_stiffness_scale": (("chain", "draw"), rows[..., 0]),
    ...                         "zeta_mesh": (("chain", "draw"), rows[..., 1])}, attrs={"converged": 1})
    >>> draws = uqgear.PosteriorDraws.from_dataset(posterior, source="example")
    >>> draws.names, draws.size
    (('mesh_stiffness_scale', 'zeta_mesh'), 400)
    >>> thinned = draws.thin(64, seed=1)
    >>> thinned.size, bool(np.isin(thinned.values[:, 0], draws.values[:, 0]).all())
    (64, True)
    """

    names: tuple[str, ...]
    values: np.ndarray
    converged: bool = True
    source: str = ""
    design: dict[str, Any] | None = None
    units: dict[str, str] = field(default_factory=dict)
    campaign: dict[str, tuple[float, float]] = field(default_factory=dict)
    discrepancy_beta: np.ndarray | None = None

    def __post_init__(self) -> None:
        values = np.array(self.values, dtype=float)
        if values.ndim != 2 or values.shape[1] != len(self.names) or values.shape[0] < 1:
            raise PosteriorError(
                f"{self.source or 'posterior'}: expected draws of shape (draws, {len(self.names)}); got {values.shape}"
            )
        if not np.isfinite(values).all():
            raise PosteriorError(f"{self.source or 'posterior'}: the draws hold non-finite values")
        values.setflags(write=False)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "values", values)
        if self.discrepancy_beta is not None:
            beta = np.array(self.discrepancy_beta, dtype=float)
            if beta.ndim != 4 or beta.shape[0] != values.shape[0]:
                raise PosteriorError(
                    f"{self.source or 'posterior'}: discrepancy_beta: expected shape (draws={values.shape[0]}, "
                    f"channel, harmonic, basis); got {beta.shape}"
                )
            beta.setflags(write=False)
            object.__setattr__(self, "discrepancy_beta", beta)

    # -- construction ---------------------------------------------------------------

    @classmethod
    def from_dataset(cls, posterior: xr.Dataset, *, source: str = "") -> PosteriorDraws:
        """Read the draws of a posterior Dataset (``posterior.nc``, a ``calibrate`` analysis's result)."""
        where = source or "posterior"
        names = _global_names(posterior, where)
        columns = []
        for name in names:
            variable = posterior[name]
            if set(variable.dims) != {"chain", "draw"}:
                raise PosteriorError(f"{where}: {name}: expected dims (chain, draw); got {variable.dims}")
            columns.append(variable.transpose("chain", "draw").values.reshape(-1))
        design = posterior.attrs.get("design")
        campaign = {}
        for name, low, high in (
            ("pinion_speed", "pinion_speed", "pinion_speed"),
            ("drive_torque", "drive_torque", "drive_torque"),
            ("adhesion_torque", "adhesion_torque_lower", "adhesion_torque_upper"),
        ):
            if low in posterior.coords and high in posterior.coords:
                campaign[name] = (float(posterior[low].min()), float(posterior[high].max()))
        beta = None
        if "discrepancy_beta" in posterior.data_vars:
            # (chain, draw, ...) flattened in the order of the parameters' columns
            stacked = posterior["discrepancy_beta"].transpose("chain", "draw", "channel", "harmonic", "basis").values
            beta = stacked.reshape(-1, *stacked.shape[2:])
        return cls(
            names=tuple(names),
            values=np.stack(columns, axis=1),
            converged=bool(int(posterior.attrs.get("converged", 0))),
            source=source,
            design=json.loads(design) if isinstance(design, str) else None,
            units={name: str(posterior[name].attrs.get("units", "")) for name in names},
            campaign=campaign,
            discrepancy_beta=beta,
        )

    @classmethod
    def from_calibration(cls, calibration: Any, *, source: str = "") -> PosteriorDraws:
        """The draws of a fitted :class:`~uqgear.calibration.Calibration` (or of a posterior Dataset)."""
        if isinstance(calibration, xr.Dataset):
            return cls.from_dataset(calibration, source=source)
        posterior = getattr(calibration, "posterior_", None)
        if not isinstance(posterior, xr.Dataset):
            raise PosteriorError(
                f"{source or 'calibration'}: expected a fitted Calibration (with posterior_) or a posterior "
                f"Dataset; got {type(calibration).__name__}"
            )
        design = getattr(calibration, "design_", None)
        where = source or f"calibration on {getattr(calibration, 'rig_source_', '?')}"
        draws = cls.from_dataset(posterior, source=where)
        if design is not None and draws.design is None:
            draws = dataclasses.replace(draws, design=design.to_dict())
        return draws

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> PosteriorDraws:
        """Read ``posterior.nc`` written by ``uqgear calibrate`` (or a ``calibrate`` analysis's file)."""
        posterior = read_posterior(path)
        return cls.from_dataset(posterior, source=str(Path(path)))

    # -- use ------------------------------------------------------------------------

    @property
    def size(self) -> int:
        """Number of draws."""
        return int(self.values.shape[0])

    def column(self, name: str) -> np.ndarray:
        """The draws of one parameter."""
        if name not in self.names:
            raise PosteriorError(f"{name}: not a parameter of the posterior ({', '.join(self.names)})")
        return self.values[:, self.names.index(name)]

    def median(self, name: str) -> float:
        """Posterior median of one parameter (its value where an analysis does not propagate it)."""
        return float(np.median(self.column(name)))

    def mean(self) -> np.ndarray:
        """Posterior mean of each parameter, in ``names`` order."""
        return self.values.mean(axis=0)

    def cov(self) -> np.ndarray:
        """Posterior covariance of the parameters."""
        return np.atleast_2d(np.cov(self.values, rowvar=False))

    def thin(self, draws: int, seed: SeedLike) -> PosteriorDraws:
        """``draws`` rows taken without replacement (all rows, shuffled, when there are fewer).

        Whole rows are taken, so the dependence between the parameters is kept.
        """
        if int(draws) < 1:
            raise PosteriorError(f"draws: expected at least 1; got {draws}")
        rng = np.random.default_rng(as_seed_sequence(seed))
        rows = np.sort(rng.permutation(self.size)[: min(int(draws), self.size)])
        beta = None if self.discrepancy_beta is None else self.discrepancy_beta[rows]
        return dataclasses.replace(self, values=self.values[rows], discrepancy_beta=beta)

    def check_design(self, design_values: dict[str, Any], *, where: str = "") -> None:
        """Refuse a posterior calibrated on another design (the keys both hold, compared to 1e-9)."""
        if self.design is None:
            return
        for key, value in design_values.items():
            if key not in self.design or key == "name":
                continue
            theirs = self.design[key]
            if isinstance(value, (int, float)) and isinstance(theirs, (int, float)):
                same = bool(np.isclose(float(value), float(theirs), rtol=1e-9, atol=0.0))
            else:
                same = value == theirs
            if not same:
                raise PosteriorError(
                    f"{where or self.source}: the posterior was calibrated on another design "
                    f"({key} = {theirs!r} there, {value!r} here); expected the study's design"
                )

    def to_dataset(self) -> xr.Dataset:
        """The draws as a Dataset with dim ``draw``."""
        return xr.Dataset(
            {
                name: ("draw", self.values[:, index], {"units": self.units.get(name, "")})
                for index, name in enumerate(self.names)
            },
            coords={"draw": np.arange(self.size)},
            attrs={"source": self.source, "converged": int(self.converged)},
        )


__all__ = ["PosteriorDraws", "PosteriorError", "DEFAULT_DRAWS", "read_posterior"]
