"""Benchmark: the full default table (32 x 256 x 32, float64, single scattering + every order until
1e-4) through OpenCL and through the NumPy twins, side by side in one run, for both modes; and the
share of each order at a few sun angles. Prints both tables and writes them into README.md.

Usage: python bench/bench_orders.py [--repeat N] [--no-readme] [--smoke]

``--smoke``: 8 x 32 x 8 tables, one repetition, print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime
import time

import numpy as np

from _report import SMOKE, add_output_arguments, machine, parse_arguments, write_readme_section

import clsky
from clsky.mapping import grid_coordinates
from clsky.orders import compute_orders

SUN_ZENITHS = (0.0, 60.0, 80.0, 90.0, 96.0)   # [deg], looked up at the nearest sun node


def timed(function):
    start = time.perf_counter()
    result = function()
    return result, time.perf_counter() - start


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
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="OpenCL repetitions (NumPy runs once)")
    add_output_arguments(parser)
    args = parse_arguments(parser)
    size = SMOKE.table if args.smoke else clsky.TableSettings().size
    if args.smoke:
        args.repeat = SMOKE.repeat

    timing = [f"Full default table ({' x '.join(map(str, size))}, float64, default settings: orders until 1e-4), "
              f"measured {datetime.date.today()} on {machine()}. OpenCL: best of {args.repeat} after a warm-up "
              f"(kernel compilation excluded); NumPy twins: one run, same process.", "",
              "| mode | orders | OpenCL [s] | NumPy twins [s] | NumPy / OpenCL |", "|---|---:|---:|---:|---:|"]
    shares = ["Share of each order in the table (sum over altitudes and view directions at the sun node "
              "nearest the given zenith; r / g / b, in %). The physical mode's order 1 counts Rayleigh + "
              "Mie with phase 1 (their mean over the sphere).", "",
              "| mode | sun zenith [deg] | order 1 | order 2 | order 3 | order 4 | orders 5+ |",
              "|---|---:|---|---|---|---|---|"]
    for mode in ("atmosphere-plus", "physical"):
        atmosphere = clsky.preset(mode)
        settings = clsky.TableSettings(mode=mode, size=size)
        compute_orders(atmosphere, settings)                                     # warm-up
        best = min(timed(lambda: compute_orders(atmosphere, settings))[1] for _ in range(args.repeat))
        result = compute_orders(atmosphere, settings)
        twins, numpy_seconds = timed(lambda: compute_orders(atmosphere, settings, backend="numpy"))
        difference = max(np.abs(a - b).max() / np.abs(b).max() for a, b in zip(result.orders, twins.orders))
        timing.append(f"| {mode} | {result.record['orders']} | {best:.2f} | {numpy_seconds:.1f} | "
                      f"{numpy_seconds / best:.1f}x |")
        print(timing[-1], f"(max difference of any order: {difference:.1e} of its maximum)", flush=True)
        for zenith, share in shares_at_sun_nodes(result, settings, atmosphere):
            columns = [share[0], share[1], share[2], share[3], share[4:].sum(axis=0)]
            cells = " | ".join("/".join(f"{100 * v:.1f}" for v in column) for column in columns)
            shares.append(f"| {mode} | {zenith:.1f} | {cells} |")
    print("\n".join(timing + [""] + shares))
    if not args.no_readme:
        write_readme_section("orders", "\n".join(timing))
        write_readme_section("shares", "\n".join(shares))


if __name__ == "__main__":
    main()
