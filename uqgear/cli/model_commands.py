"""The model commands: ``simulate`` (one operating point) and ``synth-rig`` (a virtual-rig campaign)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .base import check_new_file, fail, parse_assignments

# ---------------------------------------------------------------------------- simulate


def _command_simulate(args: argparse.Namespace) -> int:
    from ..physics.design import load_design
    from ..study.limits import check_dpi, check_operating_value, check_run_length

    design = load_design(args.design)
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.suffix.lower() not in (".png", ".nc"):
            return fail(f"--out {out}: expected a file name ending in .png (figure) or .nc (data)")
        check_new_file(out, args.force)
    # the limits a study puts on the same values
    speed = check_operating_value("pinion_speed", args.speed, "--speed")
    drive = (
        check_operating_value("drive_torque", args.drive_torque, "--drive-torque")
        if args.drive_torque is not None
        else design.operation.drive_torque
    )
    adhesion = (
        check_operating_value("adhesion_torque", args.adhesion_torque, "--adhesion-torque")
        if args.adhesion_torque is not None
        else drive * design.z2 / design.z1
    )
    n_periods, keep_periods = check_run_length(
        args.n_periods, args.keep_periods, where=("--n-periods", "--keep-periods")
    )
    dpi = check_dpi(args.dpi, "--dpi")

    from ..report import simulation_figure_png
    from ..study.analyses import quick_run
    from ..uq.results import save_result

    run = quick_run(design, speed, drive, adhesion, n_periods=n_periods, keep_periods=keep_periods)
    print(
        f"pinion speed {speed:g} rpm, T1 {drive / 1e3:.4g} kN m, T2 {adhesion / 1e3:.4g} kN m "
        f"({design.name}): {run.attrs['regime']} ({run.attrs['regime_reason']})"
    )
    print(
        f"  DTE RMS {run.attrs['dte_rms'] * 1e6:.4g} um, peak-to-peak "
        f"{run.attrs['dte_peak_to_peak'] * 1e6:.4g} um, dynamic load factor "
        f"{run.attrs['dynamic_load_factor']:.4g}, separated {100 * run.attrs['fraction_separation']:.3g} % "
        f"of the time, back-side contact {100 * run.attrs['fraction_back_contact']:.3g} %"
    )
    if out is not None:
        if out.suffix.lower() == ".png":
            from ..common.fileio import atomic_path

            data = simulation_figure_png(run, dpi=dpi)
            with atomic_path(out) as temporary:
                temporary.write_bytes(data)
        else:
            save_result(run, out, design=design)
        print(f"written to {out}")
    return 0



def _command_synth_rig(args: argparse.Namespace) -> int:
    from ..physics.design import load_design
    from ..physics.effects import parse_effect
    from ..rig.virtual_rig import synth_rig
    from ..rig.virtual_runup import parse_ramps, synth_runup_rig

    design = load_design(args.design)
    effects = [parse_effect(text) for text in args.effect]
    true_parameters = parse_assignments(args.true, "--true")
    out = Path(args.out)
    if out.suffix != ".nc":
        return fail(f"--out {out}: expected a file name ending in .nc")
    check_new_file(out, args.force)
    if args.noise < 0:
        return fail(f"--noise: expected a relative noise level >= 0; got {args.noise:g}")
    options: dict[str, Any] = {"effects": effects, "seed": args.seed, "relative_noise": args.noise}
    ramps = parse_ramps(args.ramp, option="--ramp") if args.ramp else None
    rig, gears = "virtual rig", ""
    if args.foreign is not None:
        from ..rig.foreign_synth import synth_foreign_rig

        if true_parameters:  # the foreign rig's physics is not the model's: it has no model parameters to set
            return fail("--true: the foreign rig (--foreign) has no true model parameters; leave --true out")
        synth_foreign_rig(design, out, args.foreign, ramps=ramps, gears_seed=args.gears_seed, option="--foreign",
                          **options)
        gears_seed = args.seed if args.gears_seed is None else args.gears_seed
        rig, gears = "foreign virtual rig", f", grade {args.foreign:g} gears of gears seed {gears_seed}"
    elif args.gears_seed is not None:
        return fail("--gears-seed: seeds the gears of the foreign rig; give it with --foreign GRADE")
    elif ramps is not None:
        synth_runup_rig(design, out, ramps, true_parameters=true_parameters, **options)
    else:
        synth_rig(design, out, true_parameters=true_parameters, **options)
    described = "; ".join(repr(effect) for effect in effects) or "no effect"
    print(f"{rig} campaign written to {out} ({design.name}{gears}, {described}, seed {args.seed})")
    return 0



# ---------------------------------------------------------------------------- parsers


def add_model_commands(commands: Any) -> None:
    """The parsers of ``simulate`` and ``synth-rig`` in ``commands``."""
    simulate = commands.add_parser(
        "simulate",
        help="one quick run with a plot",
        description="Simulate one operating point; print its regime and QoIs; "
        "optionally write a figure (time history, phase plane, Poincare map, "
        "spectrum) or the data.",
    )
    simulate.add_argument("--speed", type=float, required=True, metavar="RPM", help="pinion speed in rpm")
    simulate.add_argument(
        "--drive-torque", type=float, metavar="NM", help="drive torque T1 in N m (default: the design's rated torque)"
    )
    simulate.add_argument(
        "--adhesion-torque",
        type=float,
        metavar="NM",
        help="adhesion torque T2 in N m (default: T1 z2/z1, balancing T1)",
    )
    simulate.add_argument(
        "--design",
        default="locomotive",
        metavar="NAME|FILE",
        help="bundled design name or design YAML file (default: locomotive)",
    )
    simulate.add_argument("--out", metavar="FILE.png|FILE.nc", help="write a figure or the data")
    simulate.add_argument("--n-periods", type=int, default=400, help="mesh periods integrated (default 400)")
    simulate.add_argument(
        "--keep-periods", type=int, default=200, help="mesh periods kept after the transient (default 200)"
    )
    simulate.add_argument("--dpi", type=int, default=110, help="figure resolution (default 110)")
    simulate.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    simulate.set_defaults(handler=_command_simulate)

    synth = commands.add_parser(
        "synth-rig",
        help="simulate a virtual-rig campaign in the rig format",
        description="Simulate a test-rig campaign (8 operating points by default) "
        "with chosen true parameters, sensor noise and unmodelled effects, and write "
        "it as a uqgear-rig/1 netCDF file; with --foreign, a campaign of the foreign virtual rig.",
    )
    synth.add_argument("--design", default="locomotive", metavar="NAME|FILE",
                       help="nominal design (bundled name or YAML file; default: locomotive)")
    synth.add_argument("--out", required=True, metavar="FILE.nc", help="rig file to write")
    synth.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    synth.add_argument("--effect", action="append", default=[], metavar="NAME:param=value,...",
                       help="add an unmodelled effect, e.g. eccentricity:amplitude=12e-6,kappa=0.03 (repeatable)")
    synth.add_argument("--true", action="append", default=[], metavar="KEY=VALUE",
                       help="true value differing from the nominal design, e.g. mesh_stiffness_scale=0.97 or "
                       "k1=1.05e9 (repeatable)")
    synth.add_argument("--seed", type=int, default=0, help="seed of noise and record starts (default 0)")
    synth.add_argument("--noise", type=float, default=0.02,
                       help="sensor noise as a fraction of each record's RMS (default 0.02)")
    synth.add_argument("--ramp", action="append", default=[], metavar="START:STOP:RATE[:TORQUE]",
                       help="a run-up (or coast-down) START to STOP rpm at RATE rpm/s, drive torque TORQUE N m "
                       "(default 7000), recorded instead of the steady runs (repeatable)")
    synth.add_argument("--foreign", type=float, metavar="GRADE",
                       help="record the foreign virtual rig (a gearbox of another model form than the model's) "
                       "with gears drawn at ISO 1328-1 class GRADE (1 to 11); takes --effect, --noise, --seed "
                       "and --ramp, not --true")
    synth.add_argument("--gears-seed", type=int, metavar="N",
                       help="with --foreign: seed of the drawn gears (default: --seed); one seed gives the same "
                       "gears steady and with --ramp, so a healthy reference and a test campaign of one "
                       "--gears-seed and different --seed share their gears, as diagnose --reference needs")
    synth.set_defaults(handler=_command_synth_rig)


__all__ = ["add_model_commands"]
