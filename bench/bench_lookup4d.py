"""The 4D table's lookup at dusk: error, size, build time and frame rate (issue 11, items 3 and 4).

Builds one 4D table (parameterization '4d', clsky/table4d.py) whose sun axis covers the sun
elevations measured (+30, +5, 0 and -4 deg, plus the planner's margins), its higher orders with 2
azimuth harmonics, and for each sun elevation renders an all-sky fisheye from the ground by 4D
lookup (render_lut4d) and by the 3D lookup of the same orders (the 3D physical table those orders
make: its higher orders are their azimuth average), against a ray march of the same orders at the
'reference' quality level's ray march (256 samples per ray, 256 sun steps). The 95th percentile of
the relative luminance error is :func:`clsky.anim.metrics.compare_frames`' ``p95_rel``. Then times the
4D lookup of a 1024^2 fisheye (best of N, after a warm-up) beside the 3D lookup. Reports the table's
float32 size (``export_raw``'s), its build time (wall and process CPU) and the load average. Last,
the p95 errors with other azimuth node counts (``--azimuth-sweep``; the same orders, only the 4D
nodes recomputed) and with other sun node counts (``--sun-sweep``; tables built anew, each against
the ray march of its own orders).

Usage: python bench/bench_lookup4d.py [--size W H D] [--azimuth-size A] [--azimuth-sweep A ...] [--sun-sweep D ...]
       [--frame N] [--repeat N] [--no-readme] [--smoke]
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import math
import os

import numpy as np

from _report import description_of
from _report import SMOKE, add_output_arguments, best_of, load_average, machine, parse_arguments, \
    timed_with_cpu, write_readme_section
from _report import frame_side, integer_in, positive_integer, table_nodes

import clsky
from clsky.anim import metrics
from clsky.anim.accuracy import LOOKUP4D_AZIMUTHS, LOOKUP4D_SIZE, LOOKUP4D_SUN_DEG
from clsky.anim.cameras import FisheyeCamera, sun_direction
from clsky.quality import quality_level
from clsky.render import SkyRenderer
from clsky.table4d import compute_data

#: Sun elevations [deg] measured and the issue's targets for the p95 error.
ELEVATIONS = {"day": (30.0, 0.01), "golden hour": (5.0, 0.01), "sunset": (0.0, 0.01), "civil twilight": (-4.0, 0.03)}
#: Sun elevations [deg] the table's sun axis covers (the planner's margins: 10 deg below, 30 above): the
#: accuracy sweep's 4D candidate's, as its size and azimuth nodes are the defaults here.
SUN_RANGE_DEG = LOOKUP4D_SUN_DEG
SUN_AZIMUTH = 200.0


def three_d(table):
    """The 3D physical table of the same orders (single scattering + the azimuth average of the higher
    orders, :meth:`clsky.orders.OrdersResult.combined`), without rebuilding them."""
    orders = [np.asarray(o, dtype=np.float64) for o in table.orders]
    data = np.concatenate([orders[0], sum(orders[1:])], axis=-1) if len(orders) > 1 else orders[0]
    return dataclasses.replace(table, settings=table.settings.replace(parameterization="elek3d"), data=data)


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--size", type=table_nodes, nargs=3, default=LOOKUP4D_SIZE, metavar=("W", "H", "D"),
                        help="nodes along altitude, view (even), sun (default: 16 128 128)")
    parser.add_argument("--azimuth-size", type=integer_in(2, 1024), default=LOOKUP4D_AZIMUTHS,
                        help="azimuth nodes (default 16)")
    parser.add_argument("--azimuth-sweep", type=integer_in(2, 1024), nargs="*", default=(4, 8, 32),
                        help="other azimuth node counts to measure (default: 4 8 32)")
    parser.add_argument("--sun-sweep", type=table_nodes, nargs="*", default=(32, 64),
                        help="other sun node counts to measure (default: 32 64)")
    parser.add_argument("--frame", type=frame_side, default=256, help="side of the error frames [px] (default 256)")
    parser.add_argument("--repeat", type=positive_integer, default=5, help="timing repetitions of the 1024^2 frame")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("lookup4d",))
    speed_side, level = 1024, "reference"
    if args.smoke:
        args.size, args.azimuth_size, args.frame, args.repeat = (8, 32, 8), 5, SMOKE.frame, SMOKE.repeat
        args.azimuth_sweep, args.sun_sweep = (3,), (4,)
        speed_side, level = 64, SMOKE.reference_level
    ray = quality_level(level).ray
    low, high = (math.sin(math.radians(e)) for e in SUN_RANGE_DEG)
    settings = clsky.TableSettings(size=tuple(args.size), mode="physical", parameterization="4d",
                                   azimuth_size=args.azimuth_size, azimuth_harmonics=2, sun_cos_range=(low, high))
    atmosphere = clsky.preset("physical")
    load_before = load_average()
    table, build_wall, build_cpu = timed_with_cpu(lambda: clsky.ScatteringTable.build(atmosphere, settings))
    load_build = os.getloadavg()
    float32_mb = table.data.size * 4 / 1e6
    flat = three_d(table)

    directions, valid = FisheyeCamera(args.frame).directions()
    rows, references = [], {}
    with SkyRenderer(table, ray) as renderer, SkyRenderer(flat, ray) as renderer3d:
        prepared, prepared3d = renderer.prepare(directions, valid), renderer3d.prepare(directions, valid)
        for name, (elevation, target) in ELEVATIONS.items():
            sun = sun_direction(90.0 - elevation, SUN_AZIMUTH)
            reference = references[name] = renderer.render_raymarch(prepared, sun, 0.0)
            four = metrics.compare_frames(reference, renderer.render_lut4d(prepared, sun, 0.0), valid)
            three = metrics.compare_frames(reference, renderer3d.render_table(prepared3d, sun, 0.0), valid)
            met = four["p95_rel"] <= target
            rows.append(f"| {name} | {elevation:+g} | {100 * four['p95_rel']:.2f} % | {100 * target:g} % "
                        f"({'met' if met else 'missed'}) | {four['mean_delta_e']:.2f} | {100 * three['p95_rel']:.1f} % |")
            print(rows[-1], flush=True)
        speed_directions, speed_valid = FisheyeCamera(speed_side).directions()
        fast, fast3d = (r.prepare(speed_directions, speed_valid) for r in (renderer, renderer3d))
        sun = sun_direction(90.0 - ELEVATIONS["sunset"][0], SUN_AZIMUTH)
        renderer.render_lut4d(fast, sun, 0.0)
        renderer3d.render_table(fast3d, sun, 0.0)
        (best4d, median4d), cpu4d = best_of(lambda: renderer.render_lut4d(fast, sun, 0.0), args.repeat), None
        best3d, median3d = best_of(lambda: renderer3d.render_table(fast3d, sun, 0.0), args.repeat)
        _, _, cpu4d = timed_with_cpu(lambda: renderer.render_lut4d(fast, sun, 0.0))
    load_end = os.getloadavg()
    width, height, depth = settings.size
    sweep = []
    for count in args.azimuth_sweep:
        other = settings.replace(azimuth_size=count)
        data = compute_data(atmosphere, other, table.gathered, ground_irradiance=table.ground_irradiance)
        with SkyRenderer(dataclasses.replace(table, settings=other, data=data), ray) as renderer:
            prepared = renderer.prepare(directions, valid)
            errors = [metrics.compare_frames(references[name], renderer.render_lut4d(
                prepared, sun_direction(90.0 - elevation, SUN_AZIMUTH), 0.0), valid)["p95_rel"]
                for name, (elevation, _) in ELEVATIONS.items()]
        sweep.append(f"| {count} x {depth} | {data.size * 4 / 1e6:.0f} | "
                     + " | ".join(f"{100 * e:.2f} %" for e in errors) + " |")
        print(sweep[-1], flush=True)
    for count in args.sun_sweep:
        other = clsky.ScatteringTable.build(atmosphere, settings.replace(size=(width, height, count)))
        with SkyRenderer(other, ray) as renderer:
            prepared = renderer.prepare(directions, valid)
            errors = []
            for elevation, _ in ELEVATIONS.values():
                sun = sun_direction(90.0 - elevation, SUN_AZIMUTH)
                errors.append(metrics.compare_frames(renderer.render_raymarch(prepared, sun, 0.0),
                                                     renderer.render_lut4d(prepared, sun, 0.0), valid)["p95_rel"])
        sweep.append(f"| {args.azimuth_size} x {count} | {other.data.size * 4 / 1e6:.0f} | "
                     + " | ".join(f"{100 * e:.2f} %" for e in errors) + " |")
        print(sweep[-1], flush=True)
    lines = [
        f"Table: 4D, {width} x {height} x {depth} x {args.azimuth_size} (altitude x view x sun x azimuth), "
        f"sun elevations {SUN_RANGE_DEG[0]:g} to {SUN_RANGE_DEG[1]:g} deg, physical preset (ozone 300 DU, "
        f"ground albedo 0.1), higher orders with 2 azimuth harmonics ({table.orders_record['orders']} orders), "
        f"view steps {settings.view_steps}, sun steps {settings.sun_steps}. float32 size "
        f"{float32_mb:.0f} MB ({'within' if float32_mb <= 256 else 'over'} the 256 MB budget). Build "
        f"{build_wall:.0f} s wall, {build_cpu:.0f} s process CPU (orders on the 3D grid, then the 4D nodes), "
        f"load average {load_before:.1f} before, {load_build[0]:.1f} after. Measured {datetime.date.today()} "
        f"on {machine()}.", "",
        f"Errors: {args.frame}^2 fisheye from the ground, sun azimuth {SUN_AZIMUTH:g} deg, against the ray march "
        f"of the same higher orders at the '{level}' level's quadrature ({ray.view_steps} samples, "
        f"{ray.sun_steps} sun steps); the 3D column is the 3D physical lookup of the same orders.", "",
        "| frame | sun [deg] | 4D lookup p95 | target | 4D mean Delta E | 3D lookup p95 |",
        "|---|---:|---:|---|---:|---:|", *rows, "",
        f"Speed, {speed_side}^2 fisheye (sun at 0 deg), best of {args.repeat} (median): 4D lookup "
        f"{1000 * best4d:.0f} ms ({1 / best4d:.1f} fps; median {1000 * median4d:.0f} ms, one frame "
        f"{1000 * cpu4d:.0f} ms process CPU), 3D lookup {1000 * best3d:.0f} ms ({1 / best3d:.1f} fps; median "
        f"{1000 * median3d:.0f} ms), side by side; load average {load_end[0]:.1f} / {load_end[1]:.1f} / "
        f"{load_end[2]:.1f} (1 / 5 / 15 min) at the end.", "",
        "Other node counts, p95 error of the 4D lookup: azimuth nodes of the same table (the same orders); "
        "sun nodes of tables built anew (the ray march of each one's own orders as reference):", "",
        "| azimuth x sun nodes | float32 [MB] | " + " | ".join(f"{n} ({e:+g} deg)" for n, (e, _) in ELEVATIONS.items())
        + " |", "|---:|---:|" + "---:|" * len(ELEVATIONS), *sweep]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("lookup4d", markdown)


if __name__ == "__main__":
    main()
