"""Tooth-pair loads and tooth stresses over the mesh cycle, from a run's DTE history.

The model's mesh force is ``sum_i k_i f(x - e_i) + c_m x'`` over the pairs in
mesh (:mod:`uqgear.physics._rhs`, :mod:`uqgear.physics._pairs`): pair ``i``,
at ``u + i`` base pitches along the path of contact in mesh cycle ``n``, has
the Ishikawa pair stiffness ``k_p(u + i)`` of the model's table (its share of
a smooth table, its tooth factors, the stiffness scale and run-out modulation
applied as the kernels apply them) and the pitch offset ``e_i`` of its teeth.
:func:`pair_loads` evaluates each pair's load from the DTE ``x`` and its rate:
its elastic force ``k_i f(x - e_i)`` (negative in back-side contact) plus its
share ``k_i / sum_j k_j`` of the mesh damping force, the share taken over the
pairs that touch; a pair that does not touch carries nothing (the classical
model's damping force in separation is no tooth load).

:func:`tooth_stresses` follows one tooth through its engagement (``0 <= s <
eps`` base pitches, ``s = 0`` at the pinion's root) and turns its load ``P``
into stresses by ISO 6336 factors of a
:class:`~uqgear.physics.rating.StaticRating` of the same design:

- tooth root (ISO 6336-3 method B), per gear:
  ``sigma_F = P cos(alpha) / (b m) Y_F Y_S K_A K_Fbeta K_Falpha``; ``P cos(alpha)``
  is the pair's tangential force at the reference circle, Y_F and Y_S those of
  the critical section with the load at the outer point of single pair contact
  (the position that governs the root stress), so that the peak of a static
  history is ISO's sigma_F at K_v = 1; back-side contact gives a negative root
  stress (compression of the loaded fillet);
- flank (Hertz, with ISO 6336-2's elasticity and contact-ratio factors):
  ``sigma_H = Z_eps Z_E sqrt(K_A K_Hbeta K_Halpha P+ / (b rho(s)))`` with the
  reduced radius of curvature ``rho = rho_1 rho_2 / (rho_1 + rho_2)`` at the
  contact point, counted on each gear's flank while the contact point lies on
  its dedendum, the pitch point included (where ISO 6336-2 rates it with Z_B
  and Z_D); zero elsewhere. At the pitch point this is ISO's
  ``Z_H Z_E Z_eps sqrt(F_t / (d_1 b) (u + 1) / u)``, so the peak of a static
  history is ISO's sigma_H at K_v = 1 of each gear.

Histories are sampled ``samples_per_period`` times per mesh period from the
start of mesh period ``first_period`` (the layout of
:func:`~uqgear.physics.integration.simulate` and
:func:`~uqgear.physics.history_batch.integrate_histories`). Loads in N,
stresses in Pa, positions in base pitches.
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from ..physics import kernels as K
from ..physics.design import Design
from ..physics.model import ModelSetup
from ..physics.rating import StaticRating

#: The gears of a tooth-stress dataset, in order.
GEARS = ("pinion", "gear")


def _rate(x: np.ndarray, samples_per_period: int, setup: ModelSetup) -> np.ndarray:
    """dx/dt of a sampled history by second-order differences (used where the run kept no rate)."""
    dt = 1.0 / (setup.mesh_frequency * samples_per_period)
    return np.gradient(x, dt) if x.size > 1 else np.zeros_like(x)


def _pair_arrays(setup: ModelSetup, x: np.ndarray, rate: np.ndarray, first_period: int, samples_per_period: int):
    """:func:`pair_loads`'s arrays: (load, stiffness, position, in mesh, meshing number, time, pair slots)."""
    p = setup.parameters
    eps, z1, z2 = float(p[K.CONTACT_RATIO]), int(p[K.Z1]), int(p[K.Z2])
    rows = np.arange(x.size)
    cycle = first_period + rows // samples_per_period
    phase = (rows % samples_per_period) / samples_per_period
    slots = np.arange(math.ceil(eps))
    position = phase[:, None] + slots[None, :]
    in_mesh = position < eps
    grid = np.linspace(0.0, eps, setup.pair_stiffness.size)
    stiffness = np.where(in_mesh, np.interp(position, grid, setup.pair_stiffness), 0.0)
    if p[K.USE_PERIOD_TABLE] != 0.0:
        # a smooth table's k(t) shared in proportion to the Ishikawa pair stiffness (_rhs.smooth_share)
        smooth = np.interp(phase, np.linspace(0.0, 1.0, setup.period_stiffness.size), setup.period_stiffness)
        stiffness *= (smooth / stiffness.sum(axis=1))[:, None]
    number = cycle[:, None] - slots[None, :]
    stiffness *= setup.factor_pinion[number % z1] * setup.factor_gear[number % z2]
    time = (cycle + phase) / setup.mesh_frequency
    scale = p[K.STIFFNESS_SCALE] * (1.0 + p[K.ECC_KAPPA] * np.cos(p[K.ECC_OMEGA] * time + p[K.ECC_PHASE]))
    stiffness *= scale[:, None]
    offset = np.zeros_like(position)
    if p[K.PITCH_ERRORS] != 0.0:
        offset = p[K.N_PARAMS + number % z1] + p[K.N_PARAMS + z1 + number % z2]
    deflection = x[:, None] - offset
    b = p[K.HALF_BACKLASH]
    elastic = stiffness * np.where(deflection > b, deflection - b, np.where(deflection < -b, deflection + b, 0.0))
    touching = in_mesh & (elastic != 0.0)
    touching_k = np.where(touching, stiffness, 0.0).sum(axis=1)
    damping = p[K.CM] * rate
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(touching, stiffness / touching_k[:, None], 0.0)
    load = np.where(touching, elastic + share * damping[:, None], 0.0)
    return load, stiffness, position, in_mesh, number, time, slots


def pair_loads(setup: ModelSetup, x, x_velocity=None, *, first_period: int, samples_per_period: int) -> xr.Dataset:
    """The load each tooth pair in mesh carries at every sample of a DTE history.

    Parameters
    ----------
    setup : ModelSetup
        The run's set-up (:func:`uqgear.physics.model.build_model`).
    x : array_like
        The DTE history, m, sampled ``samples_per_period`` times per mesh period from the start of
        mesh period ``first_period``.
    x_velocity : array_like, optional
        dx/dt, m/s; second-order differences of ``x`` where not given.
    first_period : int
        The mesh period the history starts with (``n_periods - keep_periods`` of a run).
    samples_per_period : int

    Returns
    -------
    xarray.Dataset
        Dims ``time`` and ``pair`` (0: the pair that entered last): ``pair_load`` (N, zero for a
        pair out of mesh or apart), ``pair_stiffness`` (N/m), ``pair_position`` (base pitches from
        the start of contact, NaN out of mesh), ``meshing_number`` (the engagement's number; the
        pinion tooth is its remainder by z1, the gear tooth by z2) and ``mesh_force``, their sum.

    Examples
    --------
    In the single pair zone one pair carries the mesh force:

    >>> import numpy as np, uqgear
    >>> from uqgear.dynamics.tooth_loads import pair_loads
    >>> setup = uqgear.build_model(uqgear.load_design("locomotive"), 50.0, 7000.0, 7000.0 * 101 / 21)
    >>> x = np.full(8, setup.static_state()[2])
    >>> loads = pair_loads(setup, x, np.zeros(8), first_period=0, samples_per_period=8)
    >>> loads.sizes["pair"], int((loads["pair_load"] > 0).sum("pair")[6])
    (2, 1)
    """
    x = np.asarray(x, dtype=float)
    rate = _rate(x, samples_per_period, setup) if x_velocity is None else np.asarray(x_velocity, dtype=float)
    if x.ndim != 1 or rate.shape != x.shape:
        raise ValueError(f"x, x_velocity: expected two 1-D histories of one length; got {x.shape}, {rate.shape}")
    load, stiffness, position, in_mesh, number, time, slots = _pair_arrays(
        setup, x, rate, first_period, samples_per_period
    )
    eps = float(setup.parameters[K.CONTACT_RATIO])
    return xr.Dataset(
        {
            "pair_load": (("time", "pair"), load, {"units": "N", "long_name": "load carried by the tooth pair"}),
            "pair_stiffness": (("time", "pair"), stiffness, {"units": "N m-1"}),
            "pair_position": (
                ("time", "pair"),
                np.where(in_mesh, position, np.nan),
                {"units": "base pitches", "long_name": "position on the path of contact from its start"},
            ),
            "meshing_number": (("time", "pair"), number),
            "mesh_force": (("time",), load.sum(axis=1), {"units": "N", "long_name": "sum of the pair loads"}),
        },
        coords={"time": ("time", time, {"units": "s"}), "pair": ("pair", slots)},
        attrs={"contact_ratio": eps, "samples_per_period": samples_per_period},
    )


def _engagement_arrays(pair_load: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`engagement_loads`'s arrays from the (time, pair) loads: (engagement x position loads, positions)."""
    pairs = pair_load.shape[1]
    cycles = pair_load.shape[0] // samples
    count = cycles - pairs + 1
    if count < 1:
        raise ValueError(f"loads: a whole engagement needs {pairs} mesh periods; the history holds {cycles}")
    table = pair_load[: cycles * samples].reshape(cycles, samples, pairs)
    # engagement m is pair slot i in mesh cycle m + i
    parts = [table[i : i + count, :, i] for i in range(pairs)]
    return np.concatenate(parts, axis=1), np.arange(pairs * samples) / samples


def engagement_loads(loads: xr.Dataset) -> xr.Dataset:
    """The load of each tooth pair over its whole engagement, for the engagements a history holds whole.

    Parameters
    ----------
    loads : xarray.Dataset
        :func:`pair_loads`'s result.

    Returns
    -------
    xarray.Dataset
        ``tooth_load`` with dims ``engagement`` (the meshing number) and ``position`` (base pitches
        from the start of contact, ``ceil(eps)`` mesh periods of samples; zero beyond ``eps``).

    Examples
    --------
    >>> import numpy as np, uqgear
    >>> from uqgear.dynamics.tooth_loads import engagement_loads, pair_loads
    >>> setup = uqgear.build_model(uqgear.load_design("locomotive"), 50.0, 7000.0, 7000.0 * 101 / 21)
    >>> loads = pair_loads(setup, np.full(40, setup.static_state()[2]), np.zeros(40),
    ...                    first_period=3, samples_per_period=8)
    >>> engagement_loads(loads)["tooth_load"].sizes
    Frozen({'engagement': 4, 'position': 16})
    """
    samples = int(loads.attrs["samples_per_period"])
    load, position = _engagement_arrays(loads["pair_load"].values, samples)
    count = load.shape[0]
    first = int(loads["meshing_number"].values[0, 0])
    return xr.Dataset(
        {"tooth_load": (("engagement", "position"), load, {"units": "N", "long_name": "load of the tooth pair"})},
        coords={
            "engagement": ("engagement", first + np.arange(count)),
            "position": ("position", position, {"units": "base pitches"}),
        },
        attrs=dict(loads.attrs),
    )


def _flank_radii(setup: ModelSetup, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Radii of curvature (m) of the pinion and gear flanks at a position on the path of contact."""
    p = setup.parameters
    pinion = p[K.PATH_START] + p[K.BASE_PITCH] * position
    return pinion, p[K.LOA_LENGTH] - pinion


def tooth_stresses(
    setup: ModelSetup, rating: StaticRating, x, x_velocity=None, *, first_period: int, samples_per_period: int
) -> xr.Dataset:
    """Tooth root and flank stress histories of every tooth engagement in a DTE history, with their peaks.

    Parameters
    ----------
    setup : ModelSetup
        The run's set-up.
    rating : StaticRating
        An ISO 6336 rating of the same design (:func:`~uqgear.physics.rating.static_rating`):
        its nominal stresses per unit of tangential force (Y_F, Y_S), contact factors and load
        factors (K_A, K_beta, K_alpha; its K_v is divided out).
    x, x_velocity, first_period, samples_per_period
        As for :func:`pair_loads`.

    Returns
    -------
    xarray.Dataset
        ``tooth_load`` (engagement, position), N; ``root_stress`` and ``contact_stress`` (gear,
        engagement, position), Pa; per gear the scalar QoIs ``root_stress_peak``,
        ``root_stress_amplitude``, ``contact_stress_peak`` and ``contact_stress_amplitude`` (half
        the largest range of the stress of a tooth, whose unloaded value is zero), Pa.

    Examples
    --------
    Every tooth engagement of a history at a constant DTE (the mean static deflection), peaks in MPa:

    >>> import numpy as np, uqgear
    >>> from uqgear.physics.rating import static_rating
    >>> from uqgear.dynamics.tooth_loads import tooth_stresses
    >>> design = uqgear.load_design("locomotive")
    >>> setup = uqgear.build_model(design, 50.0, 7000.0, 7000.0 * 101 / 21)
    >>> rating = static_rating(design, 7000.0, 50.0, dynamic_factor=1.0)
    >>> x = np.full(3 * 512, setup.static_state()[2])
    >>> stresses = tooth_stresses(setup, rating, x, np.zeros(x.size), first_period=0, samples_per_period=512)
    >>> stresses.sizes["engagement"], stresses["root_stress_peak"].round(-5).values / 1e6
    (2, array([135.4, 142.8]))
    """
    loads = engagement_loads(
        pair_loads(setup, x, x_velocity, first_period=first_period, samples_per_period=samples_per_period)
    )
    root, contact = _stress_arrays(setup, rating, loads["tooth_load"].values, loads["position"].values)
    return _stress_dataset(loads, root, contact)


def stress_peaks(
    setup: ModelSetup, rating: StaticRating, x, x_velocity=None, *, first_period: int, samples_per_period: int
) -> dict[str, np.ndarray]:
    """:func:`tooth_stresses`'s scalar QoIs alone, the same numbers without its Datasets (a batch's reduction).

    Returns
    -------
    dict
        ``root_stress_peak``, ``root_stress_amplitude``, ``contact_stress_peak`` and
        ``contact_stress_amplitude``, each per gear (pinion, gear), Pa.

    Examples
    --------
    >>> import numpy as np, uqgear
    >>> from uqgear.physics.rating import static_rating
    >>> from uqgear.dynamics.tooth_loads import stress_peaks, tooth_stresses
    >>> design = uqgear.load_design("locomotive")
    >>> setup = uqgear.build_model(design, 50.0, 7000.0, 7000.0 * 101 / 21)
    >>> rating = static_rating(design, 7000.0, 50.0, dynamic_factor=1.0)
    >>> x = np.full(3 * 64, setup.static_state()[2])
    >>> peaks = stress_peaks(setup, rating, x, np.zeros(x.size), first_period=0, samples_per_period=64)
    >>> full = tooth_stresses(setup, rating, x, np.zeros(x.size), first_period=0, samples_per_period=64)
    >>> all(np.array_equal(peaks[name], full[name].values) for name in peaks)
    True
    """
    x = np.asarray(x, dtype=float)
    rate = _rate(x, samples_per_period, setup) if x_velocity is None else np.asarray(x_velocity, dtype=float)
    load = _pair_arrays(setup, x, rate, first_period, samples_per_period)[0]
    engagement, position = _engagement_arrays(load, samples_per_period)
    return _peaks(*_stress_arrays(setup, rating, engagement, position))


def _stress_factors(design: Design, rating: StaticRating) -> tuple[list[float], float]:
    """(root stress per unit of pair load, per gear; Hertz factor Z_eps Z_E sqrt(K_A K_Hbeta K_Halpha / b))."""
    # the rating's stresses per unit of tangential force at the reference circle, its K_v divided out
    per_load = math.cos(math.radians(design.pressure_angle)) / rating.tangential_force
    root = [per_load * actual / rating.dynamic_factor for actual in rating.root_stress]
    factors = rating.contact
    # K_A K_Hbeta K_Halpha: sigma_H = Z_B sigma_H0 sqrt(K_A K_v K_Hbeta K_Halpha)
    load_factor = (rating.contact_stress[0] / (factors.single_pair_pinion * rating.contact_stress_nominal)) ** 2
    load_factor /= rating.dynamic_factor
    return root, factors.contact_ratio * factors.elasticity * math.sqrt(load_factor / design.face_width)


def _stress_arrays(
    setup: ModelSetup, rating: StaticRating, load: np.ndarray, position: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(root, contact) stresses (gear, engagement, position) of the engagements' loads; module text."""
    per_load, hertz_factor = _stress_factors(setup.design, rating)
    root = np.stack([load * factor for factor in per_load])
    rho_1, rho_2 = _flank_radii(setup, position)
    in_mesh = position < setup.parameters[K.CONTACT_RATIO]
    reduced = np.where(in_mesh, rho_1 * rho_2 / (rho_1 + rho_2), np.inf)
    hertz = hertz_factor * np.sqrt(np.maximum(load, 0.0) / reduced)
    pitch = setup.parameters[K.PITCH_POSITION]
    # each flank where the contact point is on its dedendum, the pitch point C included
    on_dedendum = np.stack([position <= pitch + K.PITCH_TOLERANCE, position >= pitch - K.PITCH_TOLERANCE])
    contact = np.where(on_dedendum[:, None, :], hertz[None, :, :], 0.0)
    return root, contact


def peaks_from_extremes(design: Design, rating: StaticRating, extremes) -> dict[str, np.ndarray]:
    """:func:`stress_peaks` from a run's extremes of its pair loads, as the batch kernels keep them.

    The root stress is a constant of each gear times the pair load, the flank stress a constant
    times ``sqrt(P+ / rho)`` on that gear's dedendum: the largest and the smallest pair load and per
    gear the largest ``P+ / rho`` give the peaks and amplitudes as :func:`stress_peaks` forms them.

    Parameters
    ----------
    design : Design
        The run's design.
    rating : StaticRating
        As for :func:`tooth_stresses`.
    extremes : array_like
        ``pair_load_max``, ``pair_load_min`` (N), ``flank_load_pinion`` and ``flank_load_gear``
        (N/m): the variables of :data:`~uqgear.physics.batch_setup.PAIR_EXTREME_INFO`, in that order.

    Returns
    -------
    dict
        As :func:`stress_peaks`.

    Examples
    --------
    A pair load between 20 kN and 50 kN on the drive side:

    >>> import uqgear
    >>> from uqgear.physics.rating import static_rating
    >>> design = uqgear.load_design("locomotive")
    >>> rating = static_rating(design, 7000.0, 50.0, dynamic_factor=1.0)
    >>> peaks = peaks_from_extremes(design, rating, [50e3, 20e3, 2e6, 1.5e6])
    >>> bool(peaks["root_stress_amplitude"][0] == 0.5 * peaks["root_stress_peak"][0])
    True
    """
    high, low, flank_pinion, flank_gear = (float(value) for value in extremes)
    per_load, hertz_factor = _stress_factors(design, rating)
    root_high = np.array([max(factor * high, 0.0) for factor in per_load])
    root_low = np.array([min(factor * low, 0.0) for factor in per_load])
    contact = hertz_factor * np.sqrt(np.array([flank_pinion, flank_gear]))
    return {
        "root_stress_peak": root_high,
        "root_stress_amplitude": 0.5 * (root_high - root_low),
        "contact_stress_peak": contact,
        "contact_stress_amplitude": 0.5 * contact,
    }


def _peaks(root: np.ndarray, contact: np.ndarray) -> dict[str, np.ndarray]:
    """Per gear the peak and the amplitude (half the largest range; an unloaded tooth is at zero) of each stress."""
    peaks: dict[str, np.ndarray] = {}
    for name, values in (("root_stress", root), ("contact_stress", contact)):
        high = np.maximum(values.max(axis=(1, 2)), 0.0)
        low = np.minimum(values.min(axis=(1, 2)), 0.0)
        peaks[f"{name}_peak"] = high
        peaks[f"{name}_amplitude"] = 0.5 * (high - low)
    return peaks


def _stress_dataset(loads: xr.Dataset, root: np.ndarray, contact: np.ndarray) -> xr.Dataset:
    dims = ("gear", "engagement", "position")
    result = loads.assign(
        root_stress=(dims, root, {"units": "Pa", "long_name": "tooth root stress (ISO 6336-3 method B section)"}),
        contact_stress=(dims, contact, {"units": "Pa", "long_name": "flank contact stress on the dedendum"}),
    ).assign_coords(gear=("gear", list(GEARS)))
    for key, values in _peaks(root, contact).items():
        name, quantity = key.rsplit("_", 1)
        text = f"largest {name.replace('_', ' ')}" if quantity == "peak" else f"half the largest range of the {name}"
        result[key] = ("gear", values, {"units": "Pa", "long_name": text.replace("_", " ")})
    return result


__all__ = ["GEARS", "pair_loads", "engagement_loads", "peaks_from_extremes", "stress_peaks", "tooth_stresses"]
