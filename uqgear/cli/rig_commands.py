"""The rig-data commands: ``calibrate``, ``diagnose`` and ``blindtest``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..common.transaction import OutputFolder
from .base import comma_list, fail, new_output_folder, one_line, pitch_classes


def _command_calibrate(args: argparse.Namespace) -> int:
    from ..calibration import calibrate

    rig = Path(args.rig)
    if not rig.is_file():
        return fail(f"{rig}: rig data file not found")
    classes = pitch_classes(args.pitch_classes)
    out = new_output_folder(Path(args.out))
    result = calibrate(
        rig,
        out,
        design=args.design,
        params=comma_list(args.params),
        seed=args.seed,
        threads=args.workers,
        pitch_classes=classes,
        discrepancy=args.discrepancy,
    )
    summary = result.to_dict()
    state = "converged" if summary.get("converged") else "NOT converged (see calibration.json)"
    print(f"calibration of {rig} {state}; results in {out}")
    if not summary.get("converged"):
        print(f"  {summary.get('message', '')}")
    for warning in summary.get("warnings") or []:
        print(f"  warning: {warning}")
    for name, values in (summary.get("parameters") or {}).items():
        if isinstance(values, dict) and "q05" in values:
            print(f"  {name:22s} median {values['q50']:.6g}   90 % interval [{values['q05']:.6g}, {values['q95']:.6g}]")
    return 0


def _command_diagnose(args: argparse.Namespace) -> int:
    from ..diagnosis import diagnose

    rig = Path(args.rig)
    if not rig.is_file():
        return fail(f"{rig}: rig data file not found")
    reference = Path(args.reference) if args.reference else None
    if reference is not None and not reference.is_file():
        return fail(f"--reference {reference}: rig data file not found")
    classes = pitch_classes(args.pitch_classes)
    out = new_output_folder(Path(args.out))
    result = diagnose(
        rig,
        out,
        design=args.design,
        effects=comma_list(args.effects),
        seed=args.seed,
        workers=args.workers,
        reference=reference,
        pitch_classes=classes,
        reference_route=args.reference_route,
        reference_gears=args.reference_gears,
    )
    gap = result.get("gap", {})
    if gap.get("baseline") is None:
        # nothing was compared (verdict inconclusive): the reason, not a row of Nones
        print(
            f"diagnosis of {rig}: verdict {result['verdict']} ({one_line(result.get('reason', ''))}); results in {out}"
        )
        return 0
    against = f" against reference {reference}" if reference is not None else ""
    print(
        f"diagnosis of {rig}{against}: verdict {result['verdict']}; gap {gap.get('metric', '')} "
        f"{gap.get('baseline')} -> {gap.get('with_effect')} (shrink {gap.get('shrink_fraction')}); results in {out}"
    )
    return 0


def _command_blindtest(args: argparse.Namespace) -> int:
    from ..validation import blindtest

    if args.n_per_effect < 1:
        return fail(f"--n-per-effect: expected a positive integer; got {args.n_per_effect}")
    out = new_output_folder(Path(args.out))
    if args.suite == "foreign":
        return _foreign_blindtest(args, out)
    result = blindtest(out, n_per_effect=args.n_per_effect, seed=args.seed, workers=args.workers, suite=args.suite)
    sets = result["effect_sets"]
    print(
        f"blind test ({args.suite}): {result['n_campaigns']} campaigns, accuracy {result['accuracy']:.2f} "
        f"({result['accuracy_detectable']:.2f} counting 'none' as right where the effect is invisible), "
        f"effect sets exactly right {sets['set_exact']:.2f} ({sets['set_exact_identifiable']:.2f} against the "
        f"effects the data can tell), false alarms on healthy controls "
        f"{result['false_alarms']} of {result['healthy_controls']}; results in {out}"
    )
    return 0


def _foreign_blindtest(args: argparse.Namespace, out: Path) -> int:
    """The differential diagnosis's blind test on the foreign virtual rig (``blindtest.json`` in ``out``)."""
    import json

    from ..common.fileio import write_text_atomic
    from ..validation.foreign_suite import run_foreign_suite

    result = run_foreign_suite(seed=args.seed, n_per_effect=args.n_per_effect, workers=args.workers)
    # the folder appears with its file, as the other suites' do
    with OutputFolder(out, where="--out", existing="refuse") as work:
        write_text_atomic(work / "blindtest.json", json.dumps(result, indent=1, default=str))
    print(
        f"blind test (foreign): {len(result['campaigns'])} campaigns, exactly right {result['exactly_right']:.2f} "
        f"(effects {result['effects_exactly_right']:.2f}; {result['exactly_right_visible']:.2f} counting 'none' as "
        f"right where an effect's noise-free change stays below the change test's thresholds, "
        f"{result['effects_visible']} effects visible), healthy tests none: {result['healthy_none']}; "
        f"results in {out}"
    )
    return 0



# ---------------------------------------------------------------------------- parsers


def add_rig_commands(commands: Any) -> None:
    """The parsers of ``calibrate``, ``diagnose`` and ``blindtest`` in ``commands``."""
    _add_calibrate(commands)
    _add_diagnose(commands)
    _add_blindtest(commands)


def _add_campaign_arguments(parser: Any) -> None:
    """The rig file, the output folder and the nominal design: what ``calibrate`` and ``diagnose`` both take."""
    parser.add_argument("rig", metavar="RIG.nc")
    parser.add_argument("--out", required=True, metavar="DIR", help="new or empty output folder")
    parser.add_argument(
        "--design",
        metavar="NAME|FILE",
        help="nominal design, replacing the rig file's "
        "(whose copy is then not checked; default: the rig file's design)",
    )


def _add_calibrate(commands: Any) -> None:
    calibrate = commands.add_parser(
        "calibrate",
        help="Bayesian calibration of the model against rig data",
        description="Calibrate mesh stiffness scale, mesh damping, backlash, STE "
        "amplitude and bearing stiffness (and T2 per run) against a rig file with "
        "emcee; write DIR/posterior.nc, DIR/calibration.json, DIR/report.html.",
    )
    _add_campaign_arguments(calibrate)
    calibrate.add_argument(
        "--params",
        nargs="+",
        metavar="NAME",
        help="parameters to calibrate (default: mesh_stiffness_scale zeta_mesh backlash ste_amplitude k1 k2)",
    )
    calibrate.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    calibrate.add_argument("--workers", type=int, metavar="N", help="integrator threads (default: all cores)")
    calibrate.add_argument(
        "--pitch-classes",
        nargs="+",
        default=["6", "8"],
        metavar="CLASS",
        help="ISO 1328-1 flank tolerance classes of the rig's gears, lowest and highest, for "
        "the pitch-error correction (default 6 8); 'none': read the level from the sidebands",
    )
    calibrate.add_argument(
        "--discrepancy",
        action="store_true",
        help="add a model-discrepancy function of speed and torque per channel and harmonic "
        "(for a rig whose physics the model does not have; docs/validation/calibration.md)",
    )
    calibrate.set_defaults(handler=_command_calibrate)


def _add_diagnose(commands: Any) -> None:
    diagnose = commands.add_parser(
        "diagnose",
        help="where model and rig disagree, which unmodelled effect causes it, how far the gap shrinks",
        description="Calibrate the nominal model, map the standardised gap over "
        "op x channel x feature family, fit each candidate effect and score it on "
        "held-out operating points; write DIR/diagnosis.json, DIR/diagnosis.nc, "
        "DIR/report.html.",
    )
    _add_campaign_arguments(diagnose)
    diagnose.add_argument(
        "--effects", nargs="+", metavar="NAME", help="candidate effects (default: all six of the library)"
    )
    diagnose.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    diagnose.add_argument("--workers", type=int, metavar="N", help="worker processes (default: one per CPU, at most 8)")
    diagnose.add_argument(
        "--reference",
        metavar="HEALTHY.nc",
        help="a campaign of the same rig with a known good gearbox: the diagnosis says what "
        "changed since it, where, and which effect explains what share of the change",
    )
    diagnose.add_argument(
        "--reference-gears",
        choices=("same", "replaced"),
        default="same",
        help="with --reference: the test runs the reference's gears (default) or a replaced set "
        "of the same quality, whose manufacturing spread is then allowed for",
    )
    diagnose.add_argument(
        "--reference-route",
        choices=("change", "transfer"),
        default="change",
        help="with --reference: judge the change on condition-monitoring features and score the "
        "effects on it (default), or learn the reference's transfer correction of the model",
    )
    diagnose.add_argument(
        "--pitch-classes",
        nargs="+",
        default=["6", "8"],
        metavar="CLASS",
        help="ISO 1328-1 flank tolerance classes of the rig's gears, lowest and highest "
        "(default 6 8): where the sidebands show pitch errors on both shafts, what such "
        "errors do is model error, not an effect; 'none': perfect gears",
    )
    diagnose.set_defaults(handler=_command_diagnose)


def _add_blindtest(commands: Any) -> None:
    blind = commands.add_parser(
        "blindtest",
        help="blind check of the diagnosis on virtual-rig campaigns",
        description="Generate campaigns with withheld effects (and healthy controls), "
        "diagnose them, write the confusion matrix, shrink statistics and detection "
        "thresholds (DIR/blindtest.json, DIR/blindtest.nc, DIR/report.html). Campaigns "
        "follow the public campaigns' service points, bearing-clearance ones a light-load "
        "bearing check; healthy controls alternate both.",
    )
    blind.add_argument("--out", required=True, metavar="DIR", help="new or empty output folder")
    blind.add_argument("--n-per-effect", type=int, default=3, metavar="N", help="campaigns per effect (default 3)")
    blind.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    blind.add_argument(
        "--suite",
        choices=("library", "real_world", "encoderless", "runup", "foreign"),
        default="library",
        help="library: each effect alone on a clean rig (default); real_world: two effects at "
        "once, a transfer-path resonance with a healthy reference, speed wander, pitch errors and "
        "healthy controls with those nuisances (--n-per-effect campaigns of each kind); encoderless: "
        "each effect alone on a rig with accelerometers only, no TE, and two such healthy controls; "
        "runup: the real_world kinds without pitch errors, each recorded as a run-up and a coast-down; "
        "foreign: what changed since a healthy reference on a rig whose physics is not the model's",
    )
    blind.add_argument(
        "--workers", type=int, metavar="N", help="worker processes of each diagnosis (default: one per CPU, at most 8)"
    )
    blind.set_defaults(handler=_command_blindtest)


__all__ = ["add_rig_commands"]
