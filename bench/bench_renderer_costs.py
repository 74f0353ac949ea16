"""Benchmark: the renderer choice's costs (clsky/renderer_choice.py), every renderer side by side.

The scene plan picks the cheapest renderer whose error fits the budget (:mod:`clsky.renderer_choice`), so
its rows' costs decide which one a scene gets. A frame's cost has a part that does not depend on the
frame's size (the sky-view map's own ray march) and a part per pixel (every lookup and the ray march),
and which renderer is cheaper changes with the size. This benchmark measures the process CPU time of one
frame of each row's renderer (the 3D table lookup, the sky-view map with its map marched for the frame,
the 4D table lookup, the ray march) on fisheyes of 256, 512 and 1024 pixels a side, from the ground at a
sun of +40 deg, with the table and ray march that ``clsky animate`` plans for its default scene (sun -6
to 60 deg, 1 %) and, for the 4D lookup, the 4D table that ``clsky animate --method lut4d`` builds for that
scene (its build timed too). The renderers and sizes alternate within each round (the machine's speed
drifts between two states, README "This machine runs at two speeds"; alternating gives each row the same
mix); a row's figure is its least CPU time over the rounds. A line through a renderer's three sizes (least
squares of the relative residuals) gives its cost per frame and per pixel (``RendererRow.fixed_cpu_ms`` and
``RendererRow.pixel_cpu_ns``), printed with each size's largest residual and the constants the choice
holds.

Prints the table and writes it into README.md ("Scene plan").

Usage: python bench/bench_renderer_costs.py [--rounds N] [--no-readme] [--smoke]

``--smoke``: the tables of SMOKE's size, fisheyes of 8, 12 and 16 pixels a side, 2 rounds; print only.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime

import numpy as np

from _report import description_of
from _report import SMOKE, add_output_arguments, exp_reading, load_average, machine, parse_arguments, \
    positive_integer, state_note, timed_in_turn, timed_with_cpu, write_readme_section

from clsky._cl import default_device, describe_device
from clsky.anim import animate
from clsky.anim.animate import AnimationConfig
from clsky.anim.cameras import FisheyeCamera, sun_direction
from clsky.renderer_choice import RENDERERS

#: Fisheye sides [px] measured; the line of each renderer's cost goes through their pixel counts.
SIDES = (256, 512, 1024)
#: Rounds in which the ray march is measured (each round marches 1.1 M pixels: about 2.4 CPU-s here).
MARCH_ROUNDS = 3
SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG = 40.0, 160.0


def renderers(config, sides):
    """({method: render(prepared) -> frame}, {side: (prepared directions, marched pixels)}, the 4D
    table's (wall, CPU) build [s], the plan's table): the default scene's renderers, as ``clsky animate``
    makes them, and the 4D table of ``--method lut4d`` for the same scene."""
    plan = animate.planned_animation(config).plan
    renderer, table = animate.make_renderer(config, plan)
    config4d = dataclasses.replace(config, method="lut4d")
    plan4d = animate.planned_animation(config4d).plan
    table4d, wall4d, cpu4d = timed_with_cpu(lambda: animate.make_table(config4d, plan4d))
    renderer4d = animate.renderer_of(config4d, table4d)
    sun = sun_direction(90.0 - SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG)
    methods = {"lut": lambda p: renderer.render_table(p, sun),
               "skyview": lambda p: renderer.render_skyview(p, sun),
               "lut4d": lambda p: renderer4d.render_lut4d(p, sun),
               "raymarch": lambda p: renderer.render_raymarch(p, sun)}
    prepared = {}
    for side in sides:
        directions, valid = FisheyeCamera(side).directions()
        prepared[side] = (renderer.prepare(directions, valid), int(np.count_nonzero(valid)))
    return methods, prepared, (wall4d, cpu4d), table


def line_through(pixels, cpu):
    """(fixed [s], per pixel [s], residuals [relative]) of the line cpu = fixed + per_pixel x pixels that
    least-squares the relative residuals (a small frame's cost counts as much as a large one's)."""
    pixels, cpu = np.asarray(pixels, dtype=float), np.asarray(cpu, dtype=float)
    per_pixel, fixed = np.polyfit(pixels, cpu, 1, w=1.0 / cpu)
    return fixed, per_pixel, (cpu - (fixed + per_pixel * pixels)) / cpu


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--rounds", type=positive_integer, default=7)
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("renderer_costs",))
    config, sides, march_rounds = AnimationConfig(), SIDES, MARCH_ROUNDS
    if args.smoke:
        config = dataclasses.replace(config, table_size=SMOKE.table)
        sides, args.rounds, march_rounds = (8, 12, SMOKE.frame), 2, 1
    loads, readings = [load_average()], [exp_reading()]
    methods, prepared, (wall4d, cpu4d), table = renderers(config, sides)
    keys = [(method, side) for side in sides for method in methods]

    def machine_state():
        loads.append(load_average())
        readings.append(exp_reading())

    renders = [lambda render=methods[method], side=side: render(prepared[side][0]) for method, side in keys]
    timed = timed_in_turn(renders, [march_rounds if method == "raymarch" else args.rounds for method, _ in keys],
                          after_round=machine_state)
    times = {key: [cpu for _, cpu in calls] for key, calls in zip(keys, timed)}
    markdown = report(times, prepared, sides, table, (wall4d, cpu4d), loads, readings, args.rounds, march_rounds)
    print(markdown)
    if not args.no_readme:
        write_readme_section("renderer_costs", markdown)


def report(times, prepared, sides, table, build4d, loads, readings, rounds, march_rounds):
    """The Markdown table: per renderer, the least CPU time of a frame at each size (its median in
    brackets), the line through them and its largest residual, and the rows' current constants."""
    w, h, d = table.settings.size
    names = {row.method: row for row in RENDERERS}
    pixels = [prepared[side][1] for side in sides]
    lines = [f"Measured {datetime.date.today()} on {machine()}, {describe_device(default_device())}: process CPU "
             f"time of one frame (PoCL's workers included; HDR frame on the host), fisheyes from the ground, sun at "
             f"+{SUN_ELEVATION_DEG:g} deg, the default `clsky animate` scene's plan (table {w} x {h} x {d}, "
             f"M = {table.settings.azimuth_harmonics}, its ray march's quadrature); the least of {rounds} rounds "
             f"({march_rounds} for the ray march) in which the renderers and sizes alternate, the median in "
             f"brackets; the line: least squares of the relative residuals through the three least times. Load "
             f"average {min(loads):.1f}-{max(loads):.1f}; exp() readings (before, after each round) "
             f"{min(readings):.0f}-{max(readings):.0f} M per CPU-second.{state_note(readings)}", "",
             "| renderer (`--method`) | " + " | ".join(f"{s} x {s} ({n} px) [ms]" for s, n in zip(sides, pixels))
             + " | per frame [ms] | per pixel [ns] | largest residual | in `renderer_choice` [ms + ns] |",
             "|---|" + "---:|" * (len(sides) + 4)]
    for method in ("lut", "skyview", "lut4d", "raymarch"):
        least = [min(times[method, side]) for side in sides]
        median = [float(np.median(times[method, side])) for side in sides]
        fixed, per_pixel, residuals = line_through(pixels, least)
        row = names[method]
        lines.append(f"| {row.description} (`{method}`) | "
                     + " | ".join(f"{1e3 * a:.1f} ({1e3 * m:.1f})" for a, m in zip(least, median))
                     + f" | {1e3 * fixed:.1f} | {1e9 * per_pixel:.1f} | {100 * np.abs(residuals).max():.0f} % | "
                     f"{row.fixed_cpu_ms:g} + {row.pixel_cpu_ns:g} |")
    lines += ["", f"The 4D table of `clsky animate --method lut4d` for that scene took {build4d[0]:.1f} s wall and "
                  f"{build4d[1]:.1f} CPU-s to build (`renderer_choice`: {names['lut4d'].build_cpu_s:g} CPU-s)."]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
