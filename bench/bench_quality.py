"""Benchmark: the quality levels and the scene plan, measured against the converged reference, in one run.

1. The reference (anim/accuracy.py: the 'reference' quality level, one table per frame on the sun
   range that frame needs) and its convergence: each group of its counts doubled in turn.
2. Each quality level, planned for the four frames' sun path (-4 to 45 deg): table build, frame render,
   and the error of its ray-marched frames against the reference.
3. The scene plan of the default animation (sun from -6 to 60 deg, all-sky fisheye from the ground,
   1 % budget) against the full table of the same quality: cells, build time side by side, and the
   error of both against the reference.

Writes the README sections "quality" and "plan", and docs/quality.csv.

Usage: python bench/bench_quality.py [--size 64] [--groups GROUP ...] [--reference-cache FILE] [--no-readme]
[--docs DIR] [--smoke]

``--groups`` names the reference's count groups to double (clsky.anim.accuracy.REFERENCE_GROUPS; default all;
each costs a rebuild of the four reference tables, 5 to 15 min); ``--reference-cache FILE`` keeps the
reference frames and their convergence in an .npz, read back by later runs (and by
bench/bench_accuracy.py) instead of being computed again.

``--docs DIR``: where quality.csv goes. Default: docs/ when the run writes the README; with
``--no-readme``, nowhere (print only), so that a trial run never overwrites the published data unless
asked.

``--smoke``: 16 x 16 frames, the 'draft' quality level as the reference with one group doubled ("ray
march", unless ``--groups`` names others), every table cut to at most 8 x 32 x 8 nodes, each build
once; quality.csv goes to a temporary directory (or ``--docs DIR``); print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime
import json
import pathlib
import tempfile

import numpy as np
from _report import description_of
from _report import (SMOKE, add_output_arguments, best_timing, load_average, load_note, machine,
                     parse_arguments, timed_with_cpu, write_readme_section)
from _report import integer_in, load_reference_cache, npz_file, save_reference_cache

import clsky
from clsky.anim import accuracy, animate, metrics, writers
from clsky.anim.cameras import FisheyeCamera
from clsky._cl import default_device, describe_device
from clsky.planner import Scene, plan_scene
from clsky.quality import QUALITY_LEVELS
from clsky.render import SkyRenderer

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"
NAMES = list(accuracy.SUN_ELEVATIONS)
#: The four frames' sun path.
FRAMES_PATH = (min(accuracy.SUN_ELEVATIONS.values()), max(accuracy.SUN_ELEVATIONS.values()))


def frames_of(table, ray, size, method="raymarch"):
    """{frame name: HDR} of the four frames, and the mean wall and process CPU time of one frame [s]."""
    directions, valid = FisheyeCamera(size).directions()
    with SkyRenderer(table, ray) as renderer:
        prepared = renderer.prepare(directions, valid)
        accuracy.render_frames(renderer, method, prepared)                  # warm-up
        frames, wall, cpu = timed_with_cpu(lambda: accuracy.render_frames(renderer, method, prepared))
        return frames, wall / len(frames), cpu / len(frames)


def errors(reference, frames, valid):
    return {name: metrics.compare_frames(reference[name], frames[name], valid)["p95_rel"] for name in NAMES}


def built(atmosphere, settings, repeat=1, smoke=False):
    """The table and its build's wall and process CPU time [s]: the least of each over ``repeat`` builds
    (the least noisy figures). ``smoke``: cut the table to at most SMOKE.table nodes per axis, and build
    it once."""
    if smoke:
        settings = settings.replace(size=tuple(min(n, m) for n, m in zip(settings.size, SMOKE.table)))
        repeat = SMOKE.repeat
    table, wall, cpu, _ = best_timing(lambda: clsky.ScatteringTable.build(atmosphere, settings), repeat)
    return table, wall, cpu


def percent(values):
    return " | ".join(f"{100 * values[n]:.2f}" for n in NAMES)


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--size", type=integer_in(16, 2048), default=64)
    parser.add_argument("--groups", nargs="*", choices=list(accuracy.REFERENCE_GROUPS),
                        help="default: all (with --smoke: ray march)")
    parser.add_argument("--reference-cache", type=npz_file, metavar="FILE.npz")
    parser.add_argument("--docs", type=pathlib.Path, metavar="DIR",
                        help="write quality.csv into DIR (default: docs/ when writing the README; none with "
                             "--no-readme; a temporary directory with --smoke)")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("quality", "plan"))
    reference_name = "reference"
    if args.smoke:
        args.size, reference_name = SMOKE.frame, SMOKE.reference_level
    if args.groups is None:
        args.groups = ["ray march"] if args.smoke else list(accuracy.REFERENCE_GROUPS)
    with tempfile.TemporaryDirectory() as temporary:
        if args.docs is None and args.smoke:
            args.docs = pathlib.Path(temporary)
        elif args.docs is None and not args.no_readme:
            args.docs = DOCS
        run(args, reference_name)


def run(args, reference_name):
    stamp = (f"Measured {datetime.date.today()} on {machine()}, {describe_device(default_device())} (load average "
             f"{load_average():.2f} at the start)")
    loads = []

    if args.reference_cache and args.reference_cache.exists():
        cached = load_reference_cache(args.reference_cache, reference_name, args.size, NAMES)
        reference, valid = {name: cached[name] for name in NAMES}, cached["valid"]
        reference_seconds, change = float(cached["seconds"]), json.loads(str(cached["convergence"]))
        reference_cpu = float(cached["cpu_seconds"]) if "cpu_seconds" in cached else None
        args.groups = [g for g in change if g != "sum"]
    else:
        if args.reference_cache:    # where the cache goes, checked before the minutes of the reference
            from clsky._files import check_output

            try:
                check_output(args.reference_cache, force=True, option="--reference-cache")
            except (OSError, ValueError) as error:
                raise SystemExit(str(error)) from None
        (reference, valid), reference_seconds, reference_cpu = timed_with_cpu(
            lambda: accuracy.render_reference(args.size, level=reference_name))
        loads.append(load_average())
        if args.reference_cache:    # kept even if the convergence fails (a doubled group may not fit in memory)
            save_reference_cache(args.reference_cache, reference_name, reference, valid, seconds=reference_seconds,
                                 cpu_seconds=reference_cpu, convergence="{}")
        change = accuracy.reference_convergence(reference, valid, groups=args.groups, level=reference_name)
        if args.reference_cache:
            save_reference_cache(args.reference_cache, reference_name, reference, valid, seconds=reference_seconds,
                                 cpu_seconds=reference_cpu, convergence=json.dumps(change))
    print(f"reference: {reference_seconds:.0f} s", flush=True)
    for group, values in change.items():
        print(f"reference, {group} doubled: {percent(values)} %", flush=True)

    rows = []
    for name, level in QUALITY_LEVELS.items():
        if name == "reference":
            continue
        plan = plan_scene(Scene(FRAMES_PATH, quality=name))
        table, build, build_cpu = built(plan.atmosphere, plan.table, smoke=args.smoke)
        frames, render, render_cpu = frames_of(table, level.ray, args.size)
        lut, _, _ = frames_of(table, level.ray, args.size, method="lut")
        loads.append(load_average())
        error = errors(reference, frames, valid)
        rows.append({"level": name, "budget": level.budget, "table": "x".join(map(str, table.settings.size)),
                     "samples": level.ray.view_steps, "build_s": build, "build_cpu_s": build_cpu,
                     "render_s": render, "render_cpu_s": render_cpu, "load": loads[-1],
                     **{f"p95_rel {n}": error[n] for n in NAMES}, "worst": max(error.values()),
                     "lut_worst": max(errors(reference, lut, valid).values())})
        print(rows[-1], flush=True)
    if args.docs is not None:
        args.docs.mkdir(parents=True, exist_ok=True)
        writers.write_csv(args.docs / "quality.csv", rows, force=True)
        print(f"wrote {args.docs / 'quality.csv'}", flush=True)

    lines = [f"{stamp}: {args.size} x {args.size} fisheye frames from the ground (`bench/bench_quality.py`). "
             "Each level is planned for the four frames' sun path (-4 to 45 deg); error: 95th percentile of "
             "the relative HDR luminance error of its ray-marched frames against the reference. Build: the "
             "table, its wall and process CPU time (every thread, PoCL's workers included); render: one frame "
             "by ray march, the mean of the four. The lookup column is the same table's lookup (worst frame); "
             "load: the 1-minute load average after the row." + load_note(max(loads)),
             "", "| level | promise | table | samples | build [s] | CPU [s] | render [ms] | CPU [ms] | "
             + " | ".join(f"{n} [%]" for n in NAMES) + " | lookup, worst [%] | load |",
             "|---|---:|---|---:|---:|---:|---:|---:|" + "---:|" * len(NAMES) + "---:|---:|"]
    for r in rows:
        lines.append(f"| {r['level']} | {100 * r['budget']:g} % | {r['table']} | {r['samples']} | {r['build_s']:.2f} | "
                     f"{r['build_cpu_s']:.2f} | {1e3 * r['render_s']:.1f} | {1e3 * r['render_cpu_s']:.1f} | "
                     + percent({n: r[f"p95_rel {n}"] for n in NAMES})
                     + f" | {100 * r['lut_worst']:.0f} | {r['load']:.2f} |")
    reference_level = accuracy.reference_level(level=reference_name)
    lines += ["", f"The reference ('{reference_name}' level: " + "{} x {} altitude x view ".format(*reference_level.table.size[:2])
              + f"nodes, sun nodes every {reference_level.sun_node_spacing:g} in w on each frame's sun range, "
              f"{reference_level.ray.view_steps} samples; {reference_seconds:.0f} s"
              + ("" if reference_cpu is None else f" and {reference_cpu:.0f} CPU-s") + " for the four frames) "
              "changes this much when each group of its counts is doubled; their sum bounds the change of "
              "doubling them all"
              + ("" if len(args.groups) == len(accuracy.REFERENCE_GROUPS) else
                 " (groups not doubled in this run: " + "; ".join(accuracy.REFERENCE_GROUPS[g] for g in
                                                                accuracy.REFERENCE_GROUPS if g not in args.groups)
                 + ")") + ":", "",
              "| doubled | " + " | ".join(f"{n} [%]" for n in NAMES) + " |", "|---|" + "---:|" * len(NAMES)]
    for group, values in change.items():
        label = accuracy.REFERENCE_GROUPS.get(group, "**sum**")
        lines.append(f"| {label} | " + " | ".join(f"{100 * values[n]:.3f}" for n in NAMES) + " |")
    quality_markdown = "\n".join(lines)

    # The default animation's plan (exactly as `clsky animate` makes it) against the full table of the
    # same quality, side by side.
    config = animate.AnimationConfig(size=SMOKE.frame) if args.smoke else animate.AnimationConfig()
    plan = animate.planned_animation(config).plan
    planned, planned_build, planned_cpu = built(plan.atmosphere, plan.table, repeat=3, smoke=args.smoke)
    full, full_build, full_cpu = built(plan.atmosphere, plan.full_table, repeat=3, smoke=args.smoke)
    plan_load = load_average()
    planned_frames, _, _ = frames_of(planned, plan.level.ray, args.size)
    full_frames, _, _ = frames_of(full, plan.level.ray, args.size)
    planned_error, full_error = errors(reference, planned_frames, valid), errors(reference, full_frames, valid)
    between = errors(full_frames, planned_frames, valid)
    cells = [int(np.prod(t.settings.size)) for t in (planned, full)]
    lines = [f"{stamp}. The plan of the README's main job (`clsky animate`: sun from -6 to 60 deg, all-sky "
             "fisheye from the ground, 1 % budget), as `clsky animate` prints it:", "", "```",
             plan.describe(), "```", "",
             "| table | sun axis | cells | build [s] | CPU [s] | " + " | ".join(f"{n} [%]" for n in NAMES) + " |",
             "|---|---|---:|---:|---:|" + "---:|" * len(NAMES),
             f"| planned | {planned.settings.size[2]} nodes, elevations {np.degrees(np.arcsin(plan.table.sun_cos_range[0])):.1f} "
             f"to {np.degrees(np.arcsin(plan.table.sun_cos_range[1])):.1f} deg | {cells[0]} | {planned_build:.2f} | "
             f"{planned_cpu:.2f} | "
             + percent(planned_error) + " |",
             f"| full, same quality | {full.settings.size[2]} nodes, whole axis | {cells[1]} | {full_build:.2f} | "
             f"{full_cpu:.2f} | "
             + percent(full_error) + " |",
             f"| planned vs full | | {cells[0] / cells[1]:.2f} x | {planned_build / full_build:.2f} x | "
             f"{planned_cpu / full_cpu:.2f} x | "
             + percent(between) + " |", "",
             "Errors: 95th percentile against the reference (planned vs full: between the two), ray march "
             f"{plan.level.ray.view_steps} samples, {args.size} x {args.size} frames. Build times: the least wall "
             f"and the least process CPU time of three builds each, in the same run (load average "
             f"{plan_load:.2f} after them)."]
    plan_markdown = "\n".join(lines)
    print(quality_markdown)
    print(plan_markdown)
    if not args.no_readme:
        write_readme_section("quality", quality_markdown)
        write_readme_section("plan", plan_markdown)


if __name__ == "__main__":
    main()
