"""The uncertainty layer on the gear model itself (not just analytic test functions)."""

import numpy as np
import pytest

from uqgear.physics.integration import BatchEvaluator
from uqgear.uq.interval import IntervalAnalysis
from uqgear.uq.parameter_space import ParameterSpace
from uqgear.uq.parameters import Interval
from uqgear.uq.polynomial_chaos import PolynomialChaos
from uqgear.uq.sensitivity import SobolAnalysis


@pytest.mark.slow
def test_pce_and_salib_sobol_agree_on_reference_design(design):
    lower, upper = design.operation.adhesion_torque_bounds()
    space = ParameterSpace({"adhesion_torque": Interval(lower, upper), "mesh_stiffness_scale": Interval(0.85, 1.15),
                            "zeta_mesh": Interval(0.03, 0.08), "ste_amplitude": Interval(10e-6, 20e-6)})
    model = BatchEvaluator(design, fixed={"pinion_speed": 1700.0}, n_periods=150, keep_periods=50)
    salib = SobolAnalysis(n_base=256, qoi=["dte_rms"], seed=3).fit(model, space).result_
    pce = PolynomialChaos(max_order=4, qoi=["dte_rms"], seed=4).fit(model, space).result_
    assert salib.attrs["distribution_assumed"]
    indices, half_width = salib["dte_rms"].values, salib["dte_rms_conf"].values
    from_pce = pce["dte_rms_sobol"].transpose(*salib["dte_rms"].dims).values
    # agreement within SALib's bootstrap interval (plus a small allowance for PCE truncation)
    assert np.all(np.abs(from_pce - indices) <= half_width + 0.02)
    # T2 carries most of the DTE variance at this speed, then the mesh stiffness
    total = salib["dte_rms"].sel(index="ST")
    assert total.sel(param="adhesion_torque") > 0.5
    assert total.sel(param="mesh_stiffness_scale") > total.sel(param="zeta_mesh")


def test_chebyshev_inclusion_on_gear_model_matches_scan(design):
    lower, upper = design.operation.adhesion_torque_bounds()
    space = ParameterSpace({"adhesion_torque": Interval(lower, upper)})
    model = BatchEvaluator(design, n_periods=150, keep_periods=50)
    sweep = {"pinion_speed": np.array([800.0, 1700.0])}
    reference = IntervalAnalysis("scan", scan_points=41, qoi=["dte_rms"]).fit(model, space, sweep=sweep).result_
    chebyshev = IntervalAnalysis("chebyshev", order=7, check_points=3, qoi=["dte_rms"]).fit(
        model, space, sweep=sweep).result_
    assert np.all(chebyshev["runs"].values <= 11)
    assert chebyshev["dte_rms"].values == pytest.approx(reference["dte_rms"].values, rel=0.01)
    assert not np.any(chebyshev["flag"].values)
