"""Diagnosis benchmark on what users run: the whole real-world blind suite, campaign by campaign.

Runs ``uqgear blindtest --suite real_world --n-per-effect 1`` for each seed
(default 1 and 2: 8 operating points of 1 s at 20.48 kHz per campaign) and
prints per campaign the diagnosis's wall and CPU time with its stages (order
tracking, nominal fit, pitch-error allowance, screening, full fits, forward
selection, ...) and the campaign's whole time in the suite, which adds the
virtual rig's generation and the judging (its noise-free re-simulations of
the truth are validation work, not a user's); then the median and the
slowest diagnosis, the stages summed over the suite (where the time goes),
the verdicts and the largest resident memory of this process and of the
worker processes. Aims, for the diagnosis: median at most 15 s and every
campaign at most 30 s on 2 cores, memory at most 2 GB. ``--cli`` then times
what a user types, ``uqgear diagnose rig.nc --out DIR --workers N`` in a
fresh process on every campaign file of the suite (start-up, reading, the
diagnosis and the report; campaigns diagnosed against a healthy reference
made in memory are left out, their reference is not kept). The 50 kHz
figure (6 runs, at most 60 s) is ``python benchmarks/diagnosis.py
--fifty-khz``.

Usage: ``python benchmarks/diagnosis_suite.py [--suite real_world|foreign|runup] [--seeds 1 2] [--workers 2]
[--out DIR] [--compare DIR] [--cli] [--profile]``; ``--out`` keeps the blind tests (``DIR/seed-S``),
``--compare`` compares every campaign with an earlier ``--out``: the decisions (verdict, named set, best
candidate, borderline, cannot-tell) that differ, and how far the figures (gaps, shares, scores) moved.
``--profile`` then diagnoses the slowest campaign again under cProfile on one process and prints
the CPU shares of the integration, the FFTs, the feature line fits, the least-squares solver and
the rest (which the profiler inflates: its cost per Python call is several times a small call's).
``--suite foreign`` times the differential route instead: each campaign of the foreign virtual rig
diagnosed against a healthy reference campaign of it (``uqgear blindtest --suite foreign``), with
the change test's and the scoring's times, and for each withheld effect how visible it is to the
change test ("seen": its noise-free change over the change test's threshold, largest over runs,
channels and features).
``--suite runup`` times the run-up suite (``uqgear blindtest --suite runup``: the real-world kinds
recorded as a run-up and a coast-down, cut into 8 operating points) against the steady real-world
suite: each run-up campaign diagnosed as the blind test does, and after every ``--steady-every``-th
(default 3) the steady real-world campaign of the same kind and seed, one after the other so that both
see the same load; it prints the run-up suite's figures (sets exact, controls), per pair the two
diagnosis times and their ratio, and the median and slowest of each with their ratios.
Every campaign is timed with the compiled kernels in numba's cache: a bundled rig file and a
campaign with pitch errors are diagnosed once, untimed, first. Timings taken while other jobs load
the machine are noisy: the load average is printed with them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from uqgear.validation import blindtest, diagnose_campaign, planned_campaigns, run_foreign_suite, summarise

# the fields compared between two runs of the suite (a speed change must leave the decisions as they
# were; the figures may move by rounding, which the comparison measures)
DECISIONS = ("verdict", "effects_named", "best_candidate", "borderline", "cannot_tell")
FIGURES = ("shrink_shares", "nominal_gap", "best_score", "shrink_fraction")
# a figure that moves by more than this relative change is listed one by one
LISTED_CHANGE = 1e-3


def _load() -> str:
    """The load averages over 1, 5 and 15 minutes, as printed beside every timing."""
    return ", ".join(f"{v:.1f}" for v in os.getloadavg())


def _peak_memory_mb() -> tuple[float, float]:
    """Largest resident set of this process and of any finished worker process, MB (Linux: ru_maxrss in kB)."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    return own, children


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return bool(a == b)


def _relative_change(a: Any, b: Any) -> float:
    """Largest relative change between two figures (numbers or lists of numbers); inf where not comparable."""
    if _same(a, b):
        return 0.0
    first, second = (a if isinstance(a, list) else [a]), (b if isinstance(b, list) else [b])
    if len(first) != len(second):
        return math.inf
    change = 0.0
    for x, y in zip(first, second):
        if not isinstance(x, (int, float)) or not isinstance(y, (int, float)):
            return math.inf
        if not _same(float(x), float(y)):
            change = max(change, abs(x - y) / max(abs(x), abs(y), 1e-300))
    return change


def compare(campaigns: list[dict[str, Any]], earlier: Path) -> tuple[list[str], list[tuple[str, float, str]]]:
    """These campaigns against an earlier run's blindtest.json: decisions that differ, figures that moved.

    Returns the decision differences (one line each) and, per figure that
    moved, its name, relative change and a line saying from what to what.
    """
    if not earlier.exists():
        return [f"no earlier run to compare with ({earlier})"], []
    before = {c["id"]: c for c in json.loads(earlier.read_text())["campaigns"]}
    decisions: list[str] = []
    figures: list[tuple[str, float, str]] = []
    for campaign in campaigns:
        old = before.get(campaign["id"])
        if old is None:
            decisions.append(f"{campaign['id']}: not in {earlier}")
            continue
        for field in DECISIONS:
            if not _same(campaign.get(field), old.get(field)):
                decisions.append(f"{campaign['id']}.{field}: {old.get(field)!r} -> {campaign.get(field)!r}")
        for field in FIGURES:
            change = _relative_change(old.get(field), campaign.get(field))
            if change > 0.0:
                name = f"{campaign['id']}.{field}"
                figures.append((name, change, f"{name}: {old.get(field)!r} -> {campaign.get(field)!r}"))
    return decisions, figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, help="keep the blind tests here (DIR/seed-S)")
    parser.add_argument("--compare", type=Path, help="an earlier --out to compare the verdicts with")
    parser.add_argument("--suite", choices=("real_world", "foreign", "runup"), default="real_world")
    parser.add_argument("--steady-every", type=int, default=3, metavar="K",
                        help="--suite runup: time the steady campaign of the kind of every K-th run-up campaign")
    parser.add_argument("--profile", action="store_true",
                        help="profile the slowest campaign's diagnosis again on one process: where its CPU goes")
    parser.add_argument("--cli", action="store_true",
                        help="time 'uqgear diagnose' in a fresh process on every campaign file of the suite")
    args = parser.parse_args()
    if args.suite == "foreign":
        foreign(args)
        return
    if args.suite == "runup":
        runup(args)
        return
    print(f"cpus available: {os.cpu_count()}, workers: {args.workers}, load average: "
          f"{_load()}", flush=True)
    scratch = tempfile.TemporaryDirectory()
    root = args.out if args.out is not None else Path(scratch.name)
    warm_up(args.workers)
    rows: list[tuple[Any, ...]] = []
    stages: dict[str, float] = {}
    differences: list[str] = []
    figures: list[tuple[str, float, str]] = []
    for seed in args.seeds:
        started = time.perf_counter()
        content = blindtest(root / f"seed-{seed}", suite="real_world", n_per_effect=1, seed=seed,
                            workers=args.workers, report=False)
        print(f"seed {seed}: {len(content['campaigns'])} campaigns in {time.perf_counter() - started:.0f} s; "
              f"load average {_load()}", flush=True)
        for campaign in content["campaigns"]:
            timing = campaign.get("timing_s", {})
            rows.append((seed, campaign["id"], campaign["verdict"], campaign["expected_verdict"],
                         campaign["effects_named"], campaign["seconds"], timing, campaign["truth_effects"]))
            for stage, seconds in timing.items():
                if stage not in ("total_cpu", "workers"):
                    stages[stage] = stages.get(stage, 0.0) + float(seconds)
        sets = content["effect_sets"]
        print(f"  sets exact {sets['set_exact']:.2f}, two-effect campaigns exact {sets['set_exact_multi_effect']}, "
              f"controls with an effect named {sets['controls_with_an_effect_named']} of {sets['n_controls']}",
              flush=True)
        if args.compare is not None:
            decided, moved = compare(content["campaigns"], args.compare / f"seed-{seed}" / "blindtest.json")
            differences += [f"seed {seed}: {note}" for note in decided]
            figures += [(f"seed {seed}: {name}", change, f"seed {seed}: {line}") for name, change, line in moved]
    print()
    print(f"{'seed':>4s} {'campaign':52s} {'verdict':14s} {'diag s':>7s} {'CPU s':>7s} {'suite s':>7s}  stages (s)")
    for seed, ident, verdict, _expected, _named, seconds, timing, _ in rows:
        shown = {k: v for k, v in timing.items() if k not in ("total_wall", "total_cpu", "workers") and v >= 0.5}
        stage_text = ", ".join(f"{k} {v:.0f}" for k, v in sorted(shown.items(), key=lambda kv: -kv[1]))
        print(f"{seed:4d} {ident:52s} {verdict:14s} {timing.get('total_wall', math.nan):7.1f} "
              f"{timing.get('total_cpu', math.nan):7.0f} {seconds:7.0f}  {stage_text}")
    diagnosis_walls = [float(row[6].get("total_wall", math.nan)) for row in rows]
    slowest = max(range(len(rows)), key=lambda index: diagnosis_walls[index])
    print()
    print(f"campaigns: {len(rows)}; the diagnosis's wall time per campaign: median "
          f"{statistics.median(diagnosis_walls):.1f} s, slowest {diagnosis_walls[slowest]:.1f} s "
          f"({rows[slowest][1]}, seed {rows[slowest][0]}); {sum(diagnosis_walls):.0f} s for all (aims: median "
          "15 s, every campaign 30 s)")
    walls = [row[5] for row in rows]
    print(f"each campaign in the suite (with the virtual rig's generation and the judging): median "
          f"{statistics.median(walls):.0f} s, slowest {max(walls):.0f} s; total {sum(walls):.0f} s")
    total = sum(v for k, v in stages.items() if k != "total_wall")
    print("where the diagnosis's time goes (summed over the suite):")
    for stage, seconds in sorted(stages.items(), key=lambda kv: -kv[1]):
        if stage != "total_wall":
            print(f"  {stage:28s} {seconds:7.0f} s  {100 * seconds / max(total, 1e-9):5.1f} %")
    print(f"  {'(diagnosis wall, all)':28s} {stages.get('total_wall', math.nan):7.0f} s")
    own, children = _peak_memory_mb()
    print(f"largest resident memory: this process {own:.0f} MB, a worker process {children:.0f} MB")
    # a set is right when it names exactly the true effects; without one, when the verdict is the expected one
    wrong = [row for row in rows if set(row[4]) != set(row[7]) or (not row[7] and row[2] != row[3])]
    print(f"named sets right: {len(rows) - len(wrong)} / {len(rows)}"
          + "".join(f"\n  seed {r[0]} {r[1]}: {r[2]} {r[4]} (truth {r[7] or r[3]})" for r in wrong))
    if args.compare is not None:
        print(f"decisions that differ from {args.compare}: {len(differences)}"
              + "".join(f"\n  {d}" for d in differences))
        largest = max(figures, key=lambda entry: entry[1], default=("", 0.0, ""))
        listed = [line for _, change, line in figures if change > LISTED_CHANGE]
        print(f"figures that moved: {len(figures)} of {len(rows) * len(FIGURES)}, largest relative change "
              f"{largest[1]:.1e} ({largest[0] or 'none'}); moved by more than {LISTED_CHANGE:g}: {len(listed)}"
              + "".join(f"\n  {line}" for line in listed))
    if args.cli:
        command_line(root, rows, args.workers)
    if args.profile:
        # the slowest campaign diagnosed without a reference (the route a profile of rig.nc alone retraces)
        plain = max((row for row in rows if "reference" not in row[1]), key=lambda row: row[5])
        profile(root / f"seed-{plain[0]}" / "campaigns" / plain[1] / "rig.nc")
    print(f"load average at the end: {_load()}")
    scratch.cleanup()


#: Where a diagnosis's CPU time goes: the functions that spend it, by fragments of their module's path
#: (or, for compiled library functions, of their name). The FFTs are numpy's and scipy's, both called
#: by the band-limiting; the line fit is its own module.
PROFILE_PARTS = {
    "integration (compiled kernels)": ("uqgear/physics/_kernels.py", "uqgear/physics/_lanes.py",
                                       "uqgear/physics/_pair_lanes.py", "uqgear/physics/_pairs.py"),
    "FFT (band-limiting, resampling)": ("numpy/fft/", "scipy/fft/", "pypocketfft"),
    "line fits of the features": ("uqgear/rig/line_fit.py",),
    "least-squares solver": ("scipy/optimize/",),
    "cutting ramps into operating points": ("uqgear/rig/ramp_records.py",),
}


def _diagnose(rig: Path, out: Path, workers: int) -> float:
    """``uqgear diagnose RIG --out OUT --workers N`` in a fresh process, without progress bars; its wall time, s."""
    executable = shutil.which("uqgear")
    command = [executable] if executable else [sys.executable, "-m", "uqgear.cli"]
    started = time.perf_counter()
    subprocess.run([*command, "diagnose", str(rig), "--out", str(out), "--workers", str(workers)],
                   check=True, capture_output=True, env={**os.environ, "UQGEAR_PROGRESS": "0"})
    return time.perf_counter() - started


def warm_up(workers: int) -> None:
    """Diagnose a bundled rig file and a campaign with pitch errors once, untimed, so that every campaign is
    timed with the compiled kernels in numba's cache: the first diagnosis after an install or an edit of the
    kernels compiles them (tens of seconds), which is no campaign's cost. The bundled files show no pitch
    errors: the pitch-error allowance's kernels compile on the second, the suite's healthy control with
    class-7 pitch errors made with a seed (0) the suite's default seeds leave out."""
    rig = Path(__file__).resolve().parent.parent / "data" / "rig" / "tooth_damage.nc"
    with tempfile.TemporaryDirectory() as folder:
        seconds = _diagnose(rig, Path(folder) / "diagnosis", workers)
        started = time.perf_counter()
        spec, design, seed = next(planned for planned in planned_campaigns(0, suite="real_world", n_per_effect=1)
                                  if planned[0].identifier == "control_pitch_errors-0")
        diagnose_campaign(spec, design, seed, Path(folder) / "pitch", n_ops=8, duration=1.0, workers=workers)
    print(f"warm-up (untimed): 'uqgear diagnose {rig.name}' in {seconds:.0f} s, a campaign with pitch errors "
          f"in {time.perf_counter() - started:.0f} s", flush=True)


def command_line(root: Path, rows: list[tuple[Any, ...]], workers: int) -> None:
    """Time ``uqgear diagnose rig.nc`` in a fresh process on each campaign file; print median and slowest.

    Each command starts cold as a user's does (interpreter, imports, numba's
    cached kernels, reading the file) and writes ``report.html`` too. Its
    seed is the command's default, not the suite's, so its verdict may
    differ from the suite's where a decision is borderline: they are
    counted, not required to agree.
    """
    timed: list[tuple[float, str, str]] = []
    agree = 0
    print(f"\n'uqgear diagnose' in a fresh process, {workers} workers, on each campaign file "
          f"(load average {_load()}):", flush=True)
    for seed, ident, verdict, *_ in rows:
        if "reference" in ident:
            continue  # its healthy reference was made in memory and is not kept
        rig = root / f"seed-{seed}" / "campaigns" / ident / "rig.nc"
        with tempfile.TemporaryDirectory() as folder:
            out = Path(folder) / "diagnosis"
            seconds = _diagnose(rig, out, workers)
            answer = json.loads((out / "diagnosis.json").read_text())["verdict"]
        agree += answer == verdict
        timed.append((seconds, f"seed {seed} {ident}", answer))
        print(f"  {seconds:6.1f} s  seed {seed} {ident:52s} {answer}", flush=True)
    if not timed:
        return
    walls = [seconds for seconds, _, _ in timed]
    slowest = max(timed)
    print(f"the command per campaign: median {statistics.median(walls):.1f} s, slowest {slowest[0]:.1f} s "
          f"({slowest[1]}); its verdict the suite's on {agree} of {len(timed)}")


def profile(rig: Path) -> None:
    """Diagnose ``rig`` again under cProfile on one process and print the CPU shares of :data:`PROFILE_PARTS`."""
    import cProfile
    import pstats

    from uqgear.diagnosis import Diagnosis

    profiler = cProfile.Profile(time.process_time)  # CPU time: a loaded machine does not inflate it
    started = time.process_time()
    profiler.enable()
    Diagnosis(workers=1).fit(rig)
    profiler.disable()
    total = time.process_time() - started
    stats = pstats.Stats(profiler).stats  # type: ignore[attr-defined]
    print(f"\nprofile of {rig} on one process: {total:.1f} s CPU")
    counted = 0.0
    for label, fragments in PROFILE_PARTS.items():
        own = sum(entry[2] for (file, _, function), entry in stats.items()
                  if any(fragment in file.replace("\\", "/") or fragment in function for fragment in fragments))
        counted += own
        print(f"  {label:34s} {own:6.1f} s  {100 * own / max(total, 1e-9):5.1f} %")
    rest = total - counted
    print(f"  {'everything else':34s} {rest:6.1f} s  {100 * rest / max(total, 1e-9):5.1f} %")


def foreign(args: argparse.Namespace) -> None:
    """The differential route on the foreign-rig suite: per campaign its verdict, wall time and stages."""
    print(f"cpus available: {os.cpu_count()}, workers: {args.workers}, load average: "
          f"{_load()}", flush=True)
    scratch = tempfile.TemporaryDirectory()
    root = args.out if args.out is not None else Path(scratch.name)
    rows = []
    for seed in args.seeds:
        started = time.perf_counter()
        content = run_foreign_suite(seed=seed, n_per_effect=1, workers=args.workers)
        (root / f"seed-{seed}").mkdir(parents=True, exist_ok=True)
        (root / f"seed-{seed}" / "blindtest.json").write_text(json.dumps(content, indent=1, default=str))
        print(f"seed {seed}: {len(content['campaigns'])} campaigns in {time.perf_counter() - started:.0f} s, "
              f"exactly right {content['exactly_right']:.3f}; load average "
              f"{_load()}", flush=True)
        for campaign in content["campaigns"]:
            truth = (campaign.get("truth") or {}).get("effect", "none")
            rows.append((seed, campaign["campaign"], campaign["verdict"], truth, campaign["exactly_right"],
                         campaign["seconds"], campaign.get("timing_s") or {}, campaign.get("visibility"),
                         campaign.get("right_where_visible", campaign["exactly_right"])))
    print()
    print(f"{'seed':>4s} {'campaign':28s} {'truth':20s} {'verdict':20s} {'right':>5s} {'seen':>5s} {'wall s':>7s} "
          f"{'CPU s':>7s}  stages (s)")
    for seed, ident, verdict, truth, right, seconds, timing, visibility, _ in rows:
        shown = {k: v for k, v in timing.items() if k not in ("total_wall", "total_cpu", "workers") and v >= 0.1}
        stage_text = ", ".join(f"{k} {v:.1f}" for k, v in sorted(shown.items(), key=lambda kv: -kv[1]))
        seen = "" if visibility is None else f"{visibility:.2f}"
        print(f"{seed:4d} {ident:28s} {truth:20s} {verdict:20s} {'yes' if right else 'NO':>5s} {seen:>5s} "
              f"{seconds:7.1f} {timing.get('total_cpu', math.nan):7.1f}  {stage_text}")
    walls = [row[5] for row in rows]
    changed = [row[5] for row in rows if row[2] != "none"]
    slowest = max(rows, key=lambda row: row[5])
    print()
    print(f"campaigns: {len(rows)}; wall time per campaign: median {statistics.median(walls):.1f} s, "
          f"slowest {slowest[5]:.1f} s ({slowest[1]}, seed {slowest[0]})"
          + (f"; with a change named or unexplained: median {statistics.median(changed):.1f} s" if changed else ""))
    own, children = _peak_memory_mb()
    print(f"largest resident memory: this process {own:.0f} MB, a worker process {children:.0f} MB")
    print(f"exactly right: {sum(row[4] for row in rows)} / {len(rows)}; counting 'none' as right where an effect's "
          f"noise-free change stays below the change test's thresholds ('seen' under 1): "
          f"{sum(row[8] for row in rows)} / {len(rows)}")
    print(f"load average at the end: {_load()}")
    scratch.cleanup()


def _steady_kind(identifier: str) -> str:
    """The real-world campaign of a run-up campaign's kind: its identifier without the suite's prefix."""
    return identifier.removeprefix("runup-")


def runup(args: argparse.Namespace) -> None:
    """The run-up suite's figures and diagnosis times against the steady real-world campaigns of the same kinds."""
    print(f"cpus available: {os.cpu_count()}, workers: {args.workers}, load average: {_load()}", flush=True)
    scratch = tempfile.TemporaryDirectory()
    root = args.out if args.out is not None else Path(scratch.name)
    rig = Path(__file__).resolve().parent.parent / "data" / "rig" / "tooth_damage.nc"
    with tempfile.TemporaryDirectory() as folder:
        seconds = _diagnose(rig, Path(folder) / "d", args.workers)
    print(f"warm-up (untimed): 'uqgear diagnose {rig.name}' in {seconds:.0f} s", flush=True)
    pairs: list[tuple[int, str, float, float]] = []
    runup_walls: list[tuple[float, str]] = []
    for seed in args.seeds:
        steady = {spec.identifier: (spec, design, one)
                  for spec, design, one in planned_campaigns(seed, suite="real_world", n_per_effect=1)}
        planned = planned_campaigns(seed, suite="runup", n_per_effect=1)
        started = time.perf_counter()
        campaigns = []
        for index, (spec, design, one) in enumerate(planned):
            entry = diagnose_campaign(spec, design, one, root / f"runup-seed-{seed}" / spec.identifier, n_ops=8,
                                      duration=1.0, workers=args.workers)
            campaigns.append(entry)
            wall = float(entry["timing_s"]["total_wall"])
            runup_walls.append((wall, f"seed {seed} {spec.identifier}"))
            line = (f"  {spec.identifier:58s} {entry['verdict']:14s} {str(entry['effects_named']):36s} "
                    f"diagnosis {wall:6.1f} s (campaign {entry['seconds']:5.0f} s)")
            counterpart = steady.get(_steady_kind(spec.identifier))
            if args.steady_every > 0 and index % args.steady_every == 0 and counterpart is not None:
                other = diagnose_campaign(*counterpart, root / f"steady-seed-{seed}" / counterpart[0].identifier,
                                          n_ops=8, duration=1.0, workers=args.workers)
                steady_wall = float(other["timing_s"]["total_wall"])
                pairs.append((seed, spec.identifier, wall, steady_wall))
                line += f"; steady {steady_wall:6.1f} s, ratio {wall / steady_wall:4.2f}"
            print(line + f"; load {_load()}", flush=True)
        names = tuple(dict.fromkeys(name for spec, _, _ in planned for name in spec.truth_set()))
        content = summarise(campaigns, names, seconds=time.perf_counter() - started, seed_text=str(seed))
        (root / f"runup-seed-{seed}").mkdir(parents=True, exist_ok=True)
        (root / f"runup-seed-{seed}" / "blindtest.json").write_text(json.dumps(content, indent=1, default=str))
        _runup_figures(seed, campaigns, content)
    walls = [wall for wall, _ in runup_walls]
    slowest = max(runup_walls)
    steady_walls = [pair[3] for pair in pairs]
    print(f"\nrun-up diagnosis per campaign ({len(walls)}): median {statistics.median(walls):.1f} s, slowest "
          f"{slowest[0]:.1f} s ({slowest[1]})")
    if pairs:
        print(f"steady real-world campaigns of the same kinds ({len(pairs)}): median "
              f"{statistics.median(steady_walls):.1f} s, slowest {max(steady_walls):.1f} s")
        print(f"ratios run-up / steady: median {statistics.median(walls) / statistics.median(steady_walls):.2f}, "
              f"slowest {slowest[0] / max(steady_walls):.2f}, per pair median "
              f"{statistics.median(pair[2] / pair[3] for pair in pairs):.2f} "
              f"(range {min(p[2] / p[3] for p in pairs):.2f}-{max(p[2] / p[3] for p in pairs):.2f})")
    if args.profile:
        profile(root / f"runup-seed-{slowest[1].split()[1]}" / slowest[1].split()[2] / "rig.nc")
    print(f"load average at the end: {_load()}")
    scratch.cleanup()


def _runup_figures(seed: int, campaigns: list[dict[str, Any]], content: dict[str, Any]) -> None:
    """Per family named / campaigns it acts in, controls, and the exact sets of a run-up seed."""
    sets = content["effect_sets"]
    families: dict[str, list[int]] = {}
    for campaign in campaigns:
        for name in campaign["truth_effects"]:
            named = families.setdefault(name, [0, 0, 0])
            named[0] += name in campaign["effects_named"]
            named[1] += name in campaign.get("identifiable_effects", [])
            named[2] += 1
    exact = [c for c in campaigns if (set(c["effects_named"]) == set(c["truth_effects"])
                                      and (c["truth_effects"] or c["verdict"] == c["expected_verdict"]))]
    controls = [c for c in campaigns if not c["truth_effects"]]
    print(f"seed {seed}: sets exact {len(exact)} / {len(campaigns)} (set_exact {sets['set_exact']:.2f}); "
          f"controls with an effect named {sets['controls_with_an_effect_named']} of {sets['n_controls']}; "
          f"controls with the right verdict {sum(c['verdict'] == c['expected_verdict'] for c in controls)} of "
          f"{len(controls)}", flush=True)
    for name, counts in families.items():
        print(f"  {name:14s} named {counts[0]} / {counts[2]} (visible to the oracle in {counts[1]})")
    for campaign in campaigns:
        if campaign not in exact:
            print(f"  miss: {campaign['id']}: {campaign['verdict']} {campaign['effects_named']} (truth "
                  f"{campaign['truth_effects'] or campaign['expected_verdict']}); {campaign['reason']}")


if __name__ == "__main__":
    main()
