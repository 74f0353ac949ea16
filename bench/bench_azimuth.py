"""Twilight against Monte Carlo with higher orders that carry azimuth (issue 11, item 2).

The ray march of clsky/twilight.py (the scene planner's table and quadrature at a quality level) with
the table's ``azimuth_harmonics`` set to each of ``--harmonics`` (clsky/azimuth.py; 0 is today's
azimuth-averaged scheme), against the path tracer clsky/montecarlo.py run until every channel's
standard error is below ``--target``, with the sun at +5, +2, 0, -2, -4 and -6 deg, black ground and
no ozone. Writes the summary (signed mean over the four views and three channels, worst in brackets,
and the 95th percentile of |deviation|, issue 11's measure), the per-view deviations and the table
build times into README.md.

Usage: python bench/bench_azimuth.py [--harmonics 0,2] [--quality LEVEL] [--target SE]
       [--elevations 5,2,0,-2,-4,-6] [--no-readme] [--smoke]
       python bench/bench_azimuth.py --cost [--no-readme] [--smoke]

``--cost``: what the harmonics cost in the default ``clsky animate`` (sun from -6 to 60 deg, 512^2
fisheye, default quality): its planned table built with the planner's M and with M = 0, side by side
in one process (one warm-up build of each first: the kernels compiled, the gather matrices cached),
and one ray-marched frame over each (sun 4 deg below the horizon). Wall and process CPU time, load
average; writes the README section "twilight-cost". With ``--smoke``: the smoke run's table and frame
sizes.
"""

from __future__ import annotations

import argparse
import datetime
import os
import time

import numpy as np

from _report import description_of
from _report import (SMOKE, add_output_arguments, load_average, load_note, machine, parse_arguments,
                     timed_with_cpu, write_readme_section)
from _report import integer_in, listed, photon_count, real_in, standard_error
from bench_twilight import BATCH, cells, summary

from clsky import twilight
from clsky.quality import QUALITY_LEVELS
from clsky.settings import MAX_AZIMUTH_HARMONICS


def p95(deviations):
    values = np.abs(np.concatenate([np.ravel(d) for d in deviations]))
    values = values[np.isfinite(values)]
    return f"{100 * np.percentile(values, 95):.1f} %" if values.size else "n/a"


def cost(args):
    """The ``--cost`` measurement (module docstring): markdown of the table builds and frames."""
    import dataclasses

    from clsky.anim import animate
    from clsky.anim.cameras import sun_direction
    from clsky.render import SkyRenderer

    config = animate.AnimationConfig(size=SMOKE.frame) if args.smoke else animate.AnimationConfig()
    planned = animate.planned_animation(config)
    directions, valid, plan = planned.directions, planned.valid, planned.plan
    rows, highest, start_load = [], load_average(), load_average()
    for harmonics in (plan.table.azimuth_harmonics, 0):
        settings = plan.table.replace(azimuth_harmonics=harmonics)
        if args.smoke:
            settings = settings.replace(size=SMOKE.table)
        case = dataclasses.replace(plan, table=settings)
        animate.build_table(config, case)                                          # warm-up
        table, wall, cpu = timed_with_cpu(lambda: animate.build_table(config, case))
        build_load = load_average()
        with SkyRenderer(dataclasses.replace(table, orders=()), animate.ray_settings(config)) as renderer:
            prepared = renderer.prepare(directions, valid)
            sun = sun_direction(94.0, 180.0)
            renderer.render_raymarch(prepared, sun, 0.0)                            # warm-up
            _, frame_wall, frame_cpu = timed_with_cpu(lambda: renderer.render_raymarch(prepared, sun, 0.0))
        frame_load = load_average()
        highest = max(highest, build_load, frame_load)
        rows.append(f"| {harmonics} | {' x '.join(map(str, settings.size))} | {table.orders_record['orders']} | "
                    f"{wall:.1f} | {cpu:.1f} | {build_load:.1f} | {frame_wall:.2f} | {frame_cpu:.2f} | {frame_load:.1f} |")
        print(rows[-1], flush=True)
    width, height = config.image_shape()
    lines = [f"The default `clsky animate` (sun from {config.start_elevation_deg:g} to {config.max_elevation_deg:g} "
             f"deg, {plan.level.name} quality): its planned table with the planner's azimuth harmonics and with "
             f"M = 0 (the azimuth average, the planner's choice before 2026-12-02), each built once after a "
             f"warm-up build in the same process, and one {width} x {height} fisheye frame ray-marched over it "
             f"with the sun 4 deg below the horizon. Measured {datetime.date.today()} on {machine()} (load "
             f"average {start_load:.2f} at the start); wall and process CPU time (all threads) [s], load: the "
             f"1-minute load average after each." + load_note(highest), "",
             "| M | table | orders | build: wall | CPU | load | frame: wall | CPU | load |",
             "|---:|---|---:|---:|---:|---:|---:|---:|---:|", *rows]
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--cost", action="store_true",
                        help="measure the cost of the harmonics in the default clsky animate instead")
    parser.add_argument("--harmonics", type=listed(integer_in(0, MAX_AZIMUTH_HARMONICS)), default="0,2",
                        help="comma-separated azimuth_harmonics to compare")
    parser.add_argument("--quality", default="default", choices=list(QUALITY_LEVELS),
                        help="quality level of the ray march (clsky/quality.py)")
    parser.add_argument("--target", type=standard_error, default=0.02,
                        help="relative standard error per channel to reach")
    parser.add_argument("--max-photons", type=photon_count, default=40_000_000, help="most paths per channel and case")
    parser.add_argument("--elevations", type=listed(real_in(-90.0, 90.0)),
                        default=",".join(f"{e:g}" for e in twilight.SUN_ELEVATIONS_DEG),
                        help="comma-separated sun elevations [deg]")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=lambda a: ("twilight-cost",) if a.cost else ("twilight-azimuth",))
    if args.cost:
        markdown = cost(args)
        print(markdown)
        if not args.no_readme:
            write_readme_section("twilight-cost", markdown)
        return
    harmonics, elevations = args.harmonics, args.elevations
    batch = min(BATCH, args.max_photons)             # a first batch above the cap is refused (twilight.monte_carlo)
    if args.smoke:
        args.quality, elevations, harmonics = SMOKE.reference_level, [-6.0], [0, 1]
        batch = args.max_photons = SMOKE.photons
    atmosphere = twilight.black_ground_without_ozone()

    wall, cpu = time.perf_counter(), time.process_time()
    deviations = {m: {} for m in harmonics}
    seconds = {m: {} for m in harmonics}
    rows, sizes = [], set()
    for elevation in elevations:
        marched = {}
        for m in harmonics:
            start = time.perf_counter()
            marched[m], settings = twilight.ray_march(atmosphere, elevation, quality=args.quality,
                                                      azimuth_harmonics=m)
            seconds[m][elevation] = time.perf_counter() - start
            sizes.add(settings.size)
            deviations[m][elevation] = []
        for i, view in enumerate(twilight.VIEWS):
            pooled = twilight.monte_carlo(atmosphere, elevation, view, target=args.target, batch=batch,
                                          max_photons=args.max_photons, seed=1000 * i)
            row = f"| {elevation:+.0f} | {view} | {pooled.photons / 1e6:g} M | {cells(100 * pooled.relative_error, 2, '')} |"
            for m in harmonics:
                relative, _ = twilight.deviation(marched[m][i], pooled)
                deviations[m][elevation].append(relative)
                row += f" {cells(100 * relative)} |"
            rows.append(row)
            print(row, flush=True)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    load = os.getloadavg()

    lines = [f"Ray march at the '{args.quality}' level as the scene planner sets it for each sun (tables "
             f"{', '.join(' x '.join(map(str, s)) for s in sorted(sizes))}), with the table's "
             f"`azimuth_harmonics` M set as shown; the physical preset without ozone and with a black ground. "
             f"Monte Carlo: batches of {batch} paths per channel until every channel's standard error is below "
             f"{100 * args.target:g} % or {args.max_photons / 1e6:g} M paths are spent. Measured "
             f"{datetime.date.today()} on {machine()}: {wall:.0f} s wall, {cpu:.0f} s CPU, load average "
             f"{load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (1 / 5 / 15 min) at the end.", "",
             "| | " + " | ".join(f"{e:+.0f} deg" for e in elevations) + " |",
             "|---|" + "---|" * len(elevations)]
    for m in harmonics:
        lines.append(f"| M = {m}: mean (worst) | " + " | ".join(summary(deviations[m][e]) for e in elevations) + " |")
        lines.append(f"| M = {m}: p95 of abs. deviation | " + " | ".join(p95(deviations[m][e]) for e in elevations)
                     + " |")
        lines.append(f"| M = {m}: table build + ray march [s] | "
                     + " | ".join(f"{seconds[m][e]:.0f}" for e in elevations) + " |")
    lines += ["", "Per view: deviation = ray march / Monte Carlo - 1 per channel (r, g, b) [%].", "",
              "| sun [deg] | view | paths | SE [%] | " + " | ".join(f"M = {m} [%]" for m in harmonics) + " |",
              "|---:|---|---:|---|" + "---|" * len(harmonics), *rows]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("twilight-azimuth", markdown)


if __name__ == "__main__":
    main()
