"""Benchmark: the per-frame sky-view map (clsky/skyview.py) beside the 3D table lookup and the ray march.

For fisheye frames from the ground of 512 x 512 and 1024 x 1024 pixels and the sun at +30, +5, 0 and
-4 deg: the cost of one frame (wall and process CPU time, best of ``--repeat`` after a warm-up; the
sky-view split into its map's ray march and the per-pixel sampling) and the 95th percentile of the
relative luminance error against the per-pixel ray march of the same renderer (48 samples, the
default table's higher orders; :func:`clsky.anim.metrics.compare_frames`). The table is the default
``TableSettings(mode='physical')`` of the physical preset, built once. The load average is printed
beside the times. Writes the table into README.md ("Sky-view table").

Usage: python bench/bench_skyview.py [--repeat N] [--no-readme] [--smoke]

``--smoke``: an 8 x 32 x 8 table, 16 x 16 frames, a 16 x 32 map, one repetition; print only.
"""

from __future__ import annotations

import argparse
import datetime

import numpy as np

from _report import description_of
from _report import SMOKE, add_output_arguments, load_average, machine, parse_arguments, timed_with_cpu, \
    write_readme_section
from _report import positive_integer

import clsky
from clsky import skyview
from clsky._cl import default_device, describe_device
from clsky.anim import metrics
from clsky.anim.cameras import FisheyeCamera, sun_direction
from clsky.render import SkyRenderer

ELEVATIONS = (30.0, 5.0, 0.0, -4.0)
SUN_AZIMUTH = 200.0
#: Map sizes measured (W, H); the default first.
MAP_SIZES = (skyview.DEFAULT_SIZE, (32, 64))


def best(function, repeat):
    """(result, wall [s], CPU [s]) of the call with the least wall time among ``repeat`` calls."""
    runs = [timed_with_cpu(function) for _ in range(repeat)]
    return min(runs, key=lambda run: run[1])


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--repeat", type=positive_integer, default=3)
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("skyview",))
    frame_sizes, map_sizes, settings = (512, 1024), MAP_SIZES, clsky.TableSettings(mode="physical")
    if args.smoke:
        args.repeat, frame_sizes, map_sizes = SMOKE.repeat, (SMOKE.frame,), ((16, 32),)
        settings = settings.replace(size=SMOKE.table)
    table = clsky.ScatteringTable.build("physical", settings)
    rows = []
    with SkyRenderer(table) as renderer:
        for size in frame_sizes:
            directions, valid = FisheyeCamera(size).directions()
            prepared = renderer.prepare(directions, valid)
            loads = [load_average()]
            for elevation in ELEVATIONS:
                sun = sun_direction(90.0 - elevation, SUN_AZIMUTH)
                renderer.render_raymarch(prepared, sun)                                   # warm-up
                march, march_wall, march_cpu = best(lambda: renderer.render_raymarch(prepared, sun), args.repeat)
                renderer.render_table(prepared, sun)
                lut, lut_wall, lut_cpu = best(lambda: renderer.render_table(prepared, sun), args.repeat)
                found = [("ray march (48 samples)", march_wall, march_cpu, None, None, 0.0),
                         ("3D table lookup", lut_wall, lut_cpu, None, None,
                          metrics.compare_frames(march, lut, valid)["p95_rel"])]
                for map_size in map_sizes:
                    view = skyview.SkyViewSettings(map_size)
                    renderer.render_skyview(prepared, sun, settings=view)
                    _, map_wall, map_cpu = best(lambda: renderer.skyview_map(sun, settings=view), args.repeat)
                    frame, wall, cpu = best(lambda: renderer.render_skyview(prepared, sun, settings=view), args.repeat)
                    found.append((f"sky-view {map_size[0]} x {map_size[1]}", wall, cpu, map_wall, map_cpu,
                                  metrics.compare_frames(march, frame, valid)["p95_rel"]))
                for name, wall, cpu, map_wall, map_cpu, p95 in found:
                    rows.append({"size": size, "renderer": name, "elevation": elevation, "wall": wall, "cpu": cpu,
                                 "map_wall": map_wall, "map_cpu": map_cpu, "p95": p95})
            loads.append(load_average())
            for row in rows:
                if row["size"] == size:
                    row["load"] = loads
    markdown = report(rows, table, frame_sizes)
    print(markdown)
    if not args.no_readme:
        write_readme_section("skyview", markdown)


def report(rows, table, frame_sizes):
    """The Markdown table: one line per frame size and renderer, times at the sun's +30 deg (the
    costs do not depend on the sun: the same work every frame), errors per elevation."""
    w, h, d = table.settings.size
    renderer_device = default_device()
    lines = [f"Measured {datetime.date.today()} on {machine()}, {describe_device(renderer_device)}: fisheye frames from "
             f"the ground, physical preset, default table {w} x {h} x {d}; times: best of the repeats after a "
             "warm-up, sun at +30 deg (the work does not depend on the sun), HDR frame on the host; "
             "sky-view: whole frame (map + sampling), and its map's ray march alone in brackets. Error: "
             "95th percentile of the relative luminance error against the per-pixel ray march (48 samples) of "
             "the same renderer, per sun elevation. Load: 1-minute load average before and after each frame "
             "size.", "",
             "| frame | renderer | wall [ms] | CPU [ms] | frames/s (wall) | "
             + " | ".join(f"p95 {e:+g} deg [%]" for e in ELEVATIONS) + " | load |",
             "|---|---|---:|---:|---:|" + "---:|" * len(ELEVATIONS) + "---|"]
    for size in frame_sizes:
        names = list(dict.fromkeys(r["renderer"] for r in rows if r["size"] == size))
        for name in names:
            mine = {r["elevation"]: r for r in rows if r["size"] == size and r["renderer"] == name}
            first = mine[ELEVATIONS[0]]
            wall, cpu = f"{1e3 * first['wall']:.1f}", f"{1e3 * first['cpu']:.1f}"
            if first["map_wall"] is not None:
                wall += f" ({1e3 * first['map_wall']:.1f})"
                cpu += f" ({1e3 * first['map_cpu']:.1f})"
            errors = " | ".join("reference" if mine[e]["p95"] == 0.0 and name.startswith("ray march")
                                else f"{100 * mine[e]['p95']:.2f}" for e in ELEVATIONS)
            lines.append(f"| {size} x {size} | {name} | {wall} | {cpu} | {1.0 / first['wall']:.1f} | {errors} | "
                         f"{first['load'][0]:.1f} / {first['load'][1]:.1f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
