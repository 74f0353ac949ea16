"""Benchmark: how fast the tables build, side by side in one run, and the share of each order.

Three measurements (issue 10: the default physical table within 2 s; issue 12: the default quality's
planned table within 4 s, the full default table 10x or more faster than its NumPy twins):

1. **Table builds**, ``ScatteringTable.build`` (single scattering, every order until 1e-4, the table's
   combination): the default physical table (``preset("physical")``: ozone, ground albedo 0.1, three
   wavelengths, 32 x 256 x 32) and the default quality's table planned for the default animation's
   scene (``plan_animation`` -> ``clsky.planner.plan_scene``, as ``clsky animate`` plans it). Each twice:
   *first build*, in a fresh Python process after ``import clsky`` (the kernels come from the warm
   PyOpenCL / PoCL disk caches, which a warm-up process fills first; the in-process caches, the compiled
   programs and the gather matrices, are empty), the least of ``--fresh-runs`` such processes; and
   *repeated build*, the least of ``--repeat`` builds after one in the same process. The two tables take
   their turns (a fresh process of each, then the next round; a repeated build of each, then the next
   round): measured one after the other, each caught a state of the machine of its own, and the physical
   table's repeated build moved by 26 % between two runs of 2026-12-06 (docs/speed-log.md).
2. **OpenCL against the NumPy twins**: ``clsky.orders.compute_orders`` on the full default table
   (32 x 256 x 32), ``backend="opencl"`` (best of ``--twin-runs`` batches of ``--repeat`` after a
   warm-up) against ``backend="numpy"`` (best of ``--twin-runs``), the two in turn: a batch, a twin run,
   a batch, a twin run (the twins take about 30 s a run, long enough for the machine's state to change
   under one side only: the ratios of single runs moved by 20-22 % between runs of 2026-12-06); for both
   modes; ratios in wall and in CPU time.
3. The share of each order at a few sun angles (from the same OpenCL results).

Every timing has its wall time, this process' CPU time (all threads: PoCL's workers included) and the
load average; a load above the core count is warned about (the wall times are then inflated). Each row
also has the machine's exp() rate read just before and just after it (bench/_report.py, exp_reading):
in the machine's slow state a half to two thirds of the fast state's reading (1500-1700 M per CPU-second
on the AMD EPYC with AVX-512, 540-618 on the one without), where CPU times run up to a third higher.

Usage: python bench/bench_orders.py [--repeat N] [--fresh-runs N] [--twin-runs N] [--no-readme] [--smoke]

``--smoke``: 8 x 32 x 8 tables (the planned one too), one repetition, one fresh process, one twin run, print only
(bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys

import numpy as np

from _report import description_of
from _report import (SMOKE, add_output_arguments, best_timing, exp_reading, load_average, load_note, machine,
                     parse_arguments, positive_integer, state_note, timed_in_turn, timed_with_cpu,
                     write_readme_section)

import clsky
from clsky import ground
from clsky.mapping import grid_coordinates
from clsky.orders import compute_orders

SUN_ZENITHS = (0.0, 60.0, 80.0, 90.0, 96.0)   # [deg], looked up at the nearest sun node

#: Run by a fresh interpreter (``python -c``): one build of the atmosphere and settings given as JSON in
#: its argument, timed after the imports; prints the timings as JSON.
FRESH_BUILD = """
import json, sys, time
wall, cpu = time.perf_counter(), time.process_time()
import clsky
from clsky.atmosphere import AtmosphereParameters
imported = (time.perf_counter() - wall, time.process_time() - cpu)
case = json.loads(sys.argv[1])
atmosphere, settings = AtmosphereParameters.from_dict(case["atmosphere"]), clsky.TableSettings.from_dict(case["settings"])
wall, cpu = time.perf_counter(), time.process_time()
table = clsky.ScatteringTable.build(atmosphere, settings)
print(json.dumps({"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu, "import_wall": imported[0],
                  "import_cpu": imported[1], "orders": table.orders_record["orders"]}))
"""


def fresh_process_build(atmosphere, settings):
    """{wall, cpu, import_wall, import_cpu, orders} of the first build in a new Python process."""
    case = json.dumps({"atmosphere": atmosphere.to_dict(), "settings": settings.to_dict()})
    output = subprocess.run([sys.executable, "-c", FRESH_BUILD, case], check=True, capture_output=True, text=True)
    return json.loads(output.stdout.strip().splitlines()[-1])


def build_cases(smoke):
    """[(label, atmosphere, settings)]: the default physical table and the default quality's planned one."""
    from clsky.anim import animate

    physical = clsky.preset("physical")
    default = ground.default_settings(physical)
    config = animate.AnimationConfig(size=SMOKE.frame) if smoke else animate.AnimationConfig()
    plan = animate.planned_animation(config).plan
    planned = plan.table
    if smoke:
        default, planned = default.replace(size=SMOKE.table), planned.replace(size=SMOKE.table)
    return [("default physical table", physical, default),
            (f"default quality, planned for `clsky animate` ({plan.level.name})", plan.atmosphere, planned)]


def shares_at_sun_nodes(result, settings, atmosphere):
    """Per chosen sun zenith: each order's share of the total (sum over altitude and view, per r, g, b)."""
    _, _, cos_sun = grid_coordinates(settings.size, atmosphere.atmosphere_height, settings.mapping)
    rows = []
    for zenith in SUN_ZENITHS:
        z = int(np.argmin(np.abs(np.degrees(np.arccos(cos_sun)) - zenith)))
        totals = []
        for order in result.orders:
            layer = order[z]
            per_wavelength = layer[..., :3] + layer[..., 3:6] if layer.shape[-1] == 6 else layer
            totals.append(per_wavelength.reshape(-1, 3).sum(axis=0))
        totals = np.array(totals)
        rows.append((np.degrees(np.arccos(cos_sun[z])), totals / totals.sum(axis=0)))
    return rows


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--repeat", type=positive_integer, default=3,
                        help="repeated OpenCL builds of each table (rounds, in turn), and of the full table (a batch)")
    parser.add_argument("--fresh-runs", type=positive_integer, default=3,
                        help="fresh processes timing each table's first build (rounds, in turn)")
    parser.add_argument("--twin-runs", type=positive_integer, default=2,
                        help="runs of the NumPy twins, each after a batch of OpenCL runs (in turn)")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("builds", "orders", "shares"))
    size = SMOKE.table if args.smoke else clsky.TableSettings().size
    if args.smoke:
        args.repeat, args.fresh_runs, args.twin_runs = SMOKE.repeat, 1, 1
    start_load = load_average()
    stamp = f"measured {datetime.date.today()} on {machine()} (load average {start_load:.2f} at the start)"

    builds = [f"Table builds (`ScatteringTable.build`: single scattering, every order until 1e-4, the table), {stamp}. "
              "*First build*: in a fresh Python process, timed after `import clsky`, with the PyOpenCL / PoCL "
              "disk caches warm (a warm-up process ran first) and the in-process caches (compiled programs, "
              f"gather matrices) empty: the least of {args.fresh_runs} such processes. *Repeated*: the least of "
              f"{args.repeat} builds after one in the same process. The tables take turns (a build of each, then "
              "the next round), so that both see the same mix of the machine's states. Wall and process CPU time "
              "(all threads) [s]; load: the highest 1-minute load average seen after a round; exp(): the "
              "machine's double8 exp() rate read before and after the table builds [M per CPU-second] (its slow state "
              "reads a half to two thirds of its fast one: README \"This machine runs at two speeds\").", "",
              "| table | W x H x D | orders | first build: wall | CPU | repeated: wall | CPU | load | exp() |",
              "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    cases = build_cases(args.smoke)
    fresh_process_build(*cases[0][1:])                                        # warm-up: fills the disk caches
    before, loads = exp_reading(), [start_load]
    firsts = [[] for _ in cases]
    for _ in range(args.fresh_runs):
        for runs, (_, atmosphere, settings) in zip(firsts, cases):
            runs.append(fresh_process_build(atmosphere, settings))
        loads.append(load_average())
    builders = [lambda atmosphere=atmosphere, settings=settings: clsky.ScatteringTable.build(atmosphere, settings)
                for _, atmosphere, settings in cases]
    repeated = timed_in_turn(builders, args.repeat, after_round=lambda: loads.append(load_average()))
    after = exp_reading()
    readings, highest = [before, after], max(loads)
    for (label, atmosphere, settings), runs, timed in zip(cases, firsts, repeated):
        first_wall, first_cpu = min(run["wall"] for run in runs), min(run["cpu"] for run in runs)
        wall, cpu = min(w for w, _ in timed), min(c for _, c in timed)
        builds.append(f"| {label} | {' x '.join(map(str, settings.size))} | {runs[0]['orders']} | "
                      f"{first_wall:.2f} | {first_cpu:.2f} | {wall:.2f} | {cpu:.2f} | {highest:.2f} | "
                      f"{before:.0f} / {after:.0f} |")
        print(builds[-1], f"(import clsky: {min(run['import_wall'] for run in runs):.2f} s wall)", flush=True)

    timing = [f"Full default table ({' x '.join(map(str, size))}, float64, default settings: orders until 1e-4), "
              f"`clsky.orders.compute_orders` with `backend=\"opencl\"` (the least of {args.twin_runs} x "
              f"{args.repeat} runs after a warm-up; kernel compilation excluded) and `backend=\"numpy\"` (the NumPy "
              f"twins, the least of {args.twin_runs} runs, same process; each twin run after a batch of "
              f"{args.repeat} OpenCL runs, so that both sides see the same mix of the machine's states), {stamp}. "
              "Wall and process CPU time [s]; load: the highest 1-minute load average seen after the runs of the "
              "row; exp(): the machine's double8 exp() rate read before and after the row [M per CPU-second].", "",
              "| mode | orders | OpenCL wall | CPU | NumPy twins wall | CPU | NumPy / OpenCL: wall | CPU | load | "
              "exp() |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    shares = ["Share of each order in the table (sum over altitudes and view directions at the sun node "
              "nearest the given zenith; r / g / b, in %). The physical mode's order 1 counts Rayleigh + "
              "Mie with phase 1 (their mean over the sphere).", "",
              "| mode | sun zenith [deg] | order 1 | order 2 | order 3 | order 4 | orders 5+ |",
              "|---|---:|---|---|---|---|---|"]
    for mode in ("atmosphere-plus", "physical"):
        atmosphere = clsky.preset(mode)
        settings = clsky.TableSettings(mode=mode, size=size)
        compute_orders(atmosphere, settings)                                     # warm-up
        before = exp_reading()
        opencl_runs, twin_runs, loads = [], [], []
        for _ in range(args.twin_runs):             # in turn: each side sees the same mix of the machine's states
            result, wall, cpu, load = best_timing(lambda: compute_orders(atmosphere, settings), args.repeat)
            opencl_runs.append((wall, cpu))
            twins, numpy_wall, numpy_cpu = timed_with_cpu(lambda: compute_orders(atmosphere, settings,
                                                                                 backend="numpy"))
            twin_runs.append((numpy_wall, numpy_cpu))
            loads.append(load)
        (wall, cpu), (numpy_wall, numpy_cpu) = (tuple(min(column) for column in zip(*runs))
                                                for runs in (opencl_runs, twin_runs))
        load = max(loads)
        after = exp_reading()
        readings += [before, after]
        load = max(load, load_average())
        highest = max(highest, load)
        difference = max(np.abs(a - b).max() / np.abs(b).max() for a, b in zip(result.orders, twins.orders))
        timing.append(f"| {mode} | {result.record['orders']} | {wall:.2f} | {cpu:.2f} | {numpy_wall:.1f} | "
                      f"{numpy_cpu:.1f} | {numpy_wall / wall:.1f}x | {numpy_cpu / cpu:.1f}x | {load:.2f} | "
                      f"{before:.0f} / {after:.0f} |")
        print(timing[-1], f"(max difference of any order: {difference:.1e} of its maximum)", flush=True)
        for zenith, share in shares_at_sun_nodes(result, settings, atmosphere):
            columns = [share[0], share[1], share[2], share[3], share[4:].sum(axis=0)]
            cells = " | ".join("/".join(f"{100 * v:.1f}" for v in column) for column in columns)
            shares.append(f"| {mode} | {zenith:.1f} | {cells} |")
    builds[0] += load_note(highest) + state_note(readings)
    timing[0] += load_note(highest) + state_note(readings)
    print("\n".join(builds + [""] + timing + [""] + shares))
    if not args.no_readme:
        write_readme_section("builds", "\n".join(builds))
        write_readme_section("orders", "\n".join(timing))
        write_readme_section("shares", "\n".join(shares))


if __name__ == "__main__":
    main()
