"""Benchmark: the per-frame sky-view map (clsky/skyview.py) beside the 3D table lookup and the ray march.

For fisheye frames from the ground of 512 x 512 and 1024 x 1024 pixels and the sun at +30, +5, 0 and
-4 deg: the cost of one frame (wall and process CPU time, best of ``--repeat`` after a warm-up; the
sky-view split into its map's ray march and the per-pixel sampling) and the 95th percentile of the
relative luminance error against the per-pixel ray march of the same renderer (48 samples, the
default table's higher orders; :func:`clsky.anim.metrics.compare_frames`). The table is the default
``TableSettings(mode='physical')`` of the physical preset, built once. The load average is printed
beside the times. Writes the table into README.md ("Sky-view table").

Then the errors the scene planner takes for the map (clsky.renderer_choice's sky-view row): the default map
against the per-pixel ray march of the table the planner gives each observer it takes the map for (the
default level, sun path -12 to 45 deg, ray-marched as planned): 64 x 64 fisheyes from the ground, and from
10 km looking up and tilted 0.8 rad (46 deg) down toward the sun's side, as tests/test_skyview.py's, the
sun from +45 down to -12 deg. Writes README.md's "skyview-plan".

Usage: python bench/bench_skyview.py [--repeat N] [--no-readme] [--smoke]

``--smoke``: an 8 x 32 x 8 table, 16 x 16 frames, a 16 x 32 map, one repetition; the planned tables cut to
8 x 32 x 8; print only.
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
from clsky.planner import Scene, plan_scene
from clsky.render import SkyRenderer

ELEVATIONS = (30.0, 5.0, 0.0, -4.0)
SUN_AZIMUTH = 200.0
#: Map sizes measured (W, H); the default first.
MAP_SIZES = (skyview.DEFAULT_SIZE, (32, 64))
#: The planned tables' suns [deg], their sun path, and the observers: (label, altitude [m], tilt [rad] of the
#: fisheye's axis from the zenith toward the sun's side).
PLAN_ELEVATIONS = (45.0, 30.0, 10.0, 5.0, 1.0, 0.0, -4.0, -6.0, -8.0, -10.0, -12.0)
PLAN_PATH = (-12.0, 45.0)
PLAN_OBSERVERS = (("ground", 0.0, 0.0), ("10 km", 10e3, 0.0), ("10 km, 46 deg down", 10e3, 0.8))
PLAN_FRAME = 64


def best(function, repeat):
    """(result, wall [s], CPU [s]) of the call with the least wall time among ``repeat`` calls."""
    runs = [timed_with_cpu(function) for _ in range(repeat)]
    return min(runs, key=lambda run: run[1])


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--repeat", type=positive_integer, default=3)
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("skyview", "skyview-plan"))
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
    plan_frame = SMOKE.frame if args.smoke else PLAN_FRAME
    planned = plan_report(plan_errors(plan_frame, args.smoke), plan_frame)
    print(planned)
    if not args.no_readme:
        write_readme_section("skyview", markdown)
        write_readme_section("skyview-plan", planned)


def tilted(directions, tilt):
    """``directions`` (..., 3) turned by ``tilt`` [rad] about the x axis: a fisheye's axis from the zenith
    toward -y (tests/test_skyview.py's turn; the sun at azimuth 200 deg is on that side)."""
    c, s = np.cos(tilt), np.sin(tilt)
    return directions @ np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]).T


def plan_errors(size, smoke=False):
    """{observer label: (table size 'W x H x D', {sun elevation [deg]: p95})}: the default sky-view map against
    the ray march of the table the planner gives each of :data:`PLAN_OBSERVERS` (the default level,
    :data:`PLAN_PATH`), ``size`` x ``size`` fisheyes. ``smoke``: the tables cut to at most SMOKE.table nodes per
    axis."""
    found = {}
    for label, altitude, tilt in PLAN_OBSERVERS:
        directions, valid = FisheyeCamera(size).directions()
        directions = tilted(directions, tilt)
        scene = Scene(PLAN_PATH, altitudes_m=(altitude, altitude), quality="default",
                      view_elevations_deg=(-float(np.degrees(tilt)), 90.0))
        plan = plan_scene(scene, ray_march=True)
        settings = plan.table
        if smoke:
            settings = settings.replace(size=tuple(min(n, m) for n, m in zip(settings.size, SMOKE.table)))
        with SkyRenderer(clsky.ScatteringTable.build(plan.atmosphere, settings), plan.ray) as renderer:
            prepared = renderer.prepare(directions, valid)
            errors = {}
            for elevation in PLAN_ELEVATIONS:
                sun = sun_direction(90.0 - elevation, SUN_AZIMUTH)
                march = renderer.render_raymarch(prepared, sun, altitude)
                frame = renderer.render_skyview(prepared, sun, altitude)
                errors[elevation] = metrics.compare_frames(march, frame, valid)["p95_rel"]
        found[label] = (" x ".join(map(str, settings.size)), errors)
    return found


def plan_report(found, size):
    """The Markdown table of :func:`plan_errors` (``size`` x ``size`` frames): one line per observer, and the
    worst of them per sun."""
    lines = [f"Measured {datetime.date.today()} on {machine()}, {describe_device(default_device())} (load average "
             f"{load_average():.2f} after it; `bench/bench_skyview.py`, the same run): the default sky-view map "
             f"({skyview.DEFAULT_SIZE[0]} x {skyview.DEFAULT_SIZE[1]}) against the ray march of the table the planner "
             f"gives each observer (default level, sun path {PLAN_PATH[0]:g} to {PLAN_PATH[1]:g} deg), "
             f"{size} x {size} fisheyes looking up or tilted toward the sun's side: 95th percentile of "
             "the relative luminance error [%]. The last line is what the scene planner takes "
             "(`clsky.renderer_choice`).", "",
             "| observer | table | " + " | ".join(f"{e:+g} deg" for e in PLAN_ELEVATIONS) + " |",
             "|---|---|" + "---:|" * len(PLAN_ELEVATIONS)]
    for label, (table, errors) in found.items():
        lines.append(f"| {label} | {table} | " + " | ".join(f"{100 * errors[e]:.3f}" for e in PLAN_ELEVATIONS) + " |")
    lines.append("| **worst** | | " + " | ".join(
        f"{100 * max(errors[e] for _, errors in found.values()):.3f}" for e in PLAN_ELEVATIONS) + " |")
    return "\n".join(lines)


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
