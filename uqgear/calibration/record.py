"""What a fitted calibration reports: why it is not a result, its discrepancy, its record.

:class:`CalibrationRecord` holds the readers of a fitted
:class:`~uqgear.calibration.Calibration`'s state (``calibration.json`` is its
:meth:`~CalibrationRecord.to_dict`); the estimator's :meth:`fit` sets that
state.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..physics.design import Design
from ..physics.geometry import geometry_notes
from .discrepancy_results import Discrepancy
from .errors import CalibrationError
from .failure import failure_causes
from .pitch_correction import PitchCorrection
from .settings import CalibrationSettings
from .summaries import result_content


class CalibrationRecord(CalibrationSettings):
    """The settings of a calibration and the readers of its fitted state.

    The fitted attributes are those of :class:`~uqgear.calibration.Calibration`,
    set by its :meth:`~uqgear.calibration.Calibration.fit`; before it the
    readers raise :class:`CalibrationError`.

    Examples
    --------
    >>> from uqgear.calibration import CalibrationError
    >>> from uqgear.calibration.record import CalibrationRecord
    >>> try:
    ...     CalibrationRecord().to_dict()
    ... except CalibrationError as error:
    ...     print(error)
    calibration: not fitted yet; call fit(rig) first
    """

    rig_source_: str
    design_: Design
    converged_: bool
    diagnostics_: dict[str, Any]
    summary_: dict[str, Any]
    predictive_: xr.Dataset
    predictive_check_: dict[str, Any]
    emulator_: dict[str, Any]
    timing_: dict[str, Any]
    speed_: list[dict[str, object]]
    used_: np.ndarray
    pitch_errors_: PitchCorrection | None
    discrepancy_: Discrepancy | None

    # ------------------------------------------------------------------ results

    def failure(self) -> dict[str, Any]:
        """What keeps the fit from being a result (:func:`~uqgear.calibration.failure.failure_causes`)."""
        if not hasattr(self, "posterior_"):
            raise CalibrationError("calibration: not fitted yet; call fit(rig) first")
        return failure_causes(
            diagnostics=self.diagnostics_,
            summary=self.summary_,
            predictive_check=self.predictive_check_,
            predictive=self.predictive_,
            model_error_cap=self.model_error_range[1],
            discrepancy_cap=self.discrepancy_range[1] if self.discrepancy else None,
        )

    def discrepancy_at(
        self,
        pinion_speed: Sequence[float] | np.ndarray,
        drive_torque: Sequence[float] | np.ndarray,
        draws: int,
        rng: np.random.Generator,
    ) -> xr.DataArray:
        """Posterior draws of the fitted discrepancy at operating points (:meth:`Discrepancy.at
        <uqgear.calibration.discrepancy_results.Discrepancy.at>`), to add to predicted log amplitudes.

        Parameters
        ----------
        pinion_speed, drive_torque : array-like (n,)
            Operating points, rpm and N m.
        draws : int
            Number of draws.
        rng : numpy.random.Generator
            Source of the draws.

        Returns
        -------
        xarray.DataArray
            (draw, point, channel, harmonic), log-amplitude units.

        Raises
        ------
        CalibrationError
            Not fitted, or fitted without ``discrepancy``.

        Examples
        --------
        >>> import numpy as np, uqgear
        >>> try:
        ...     uqgear.Calibration().discrepancy_at([2000.0], [6000.0], 10, np.random.default_rng(0))
        ... except uqgear.UqgearError as error:
        ...     print(error)
        calibration: no fitted discrepancy; fit(rig) with discrepancy=True first
        """
        fitted = getattr(self, "discrepancy_", None)
        if fitted is None:
            raise CalibrationError("calibration: no fitted discrepancy; fit(rig) with discrepancy=True first")
        return fitted.at(pinion_speed, drive_torque, draws, rng)

    def to_dict(self) -> dict[str, Any]:
        """The calibration result as a JSON-ready mapping (the content of ``calibration.json``)."""
        if not hasattr(self, "posterior_"):
            raise CalibrationError("calibration: not fitted yet; call fit(rig) first")
        content = result_content(
            rig=self.rig_source_,
            converged=self.converged_,
            design=self.design_.to_dict(),
            diagnostics=self.diagnostics_,
            summary=self.summary_,
            predictive_check=self.predictive_check_,
            emulator=self.emulator_,
            timing=self.timing_,
            settings=self.settings(),
            speed=self.speed_,
            failure=self.failure(),
        )
        # what the model did with the design's geometry (an undercut tooth), for the report and the record
        content["design_notes"] = geometry_notes(self.design_)
        content["pitch_errors"] = None if self.pitch_errors_ is None else self.pitch_errors_.summary(self.used_)
        return content
