"""Physics check: table radiance against the independent Monte Carlo path tracer (clsky.montecarlo).

For a handful of (altitude, view, sun) cases in the solar vertical plane (azimuth 0, where the 3D
table's canonical frame is exact for single scattering), compares the table's radiance with the Monte
Carlo estimate and its standard error, for both scattering modes, at converged quadrature settings
(the physics) and at the default settings (what the defaults cost). Prints the table and writes it
into README.md.

Usage: python bench/bench_montecarlo.py [--photons N] [--no-readme] [--smoke]

``--smoke``: 8 x 32 x 8 tables, a few hundred paths per case, print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime

import numpy as np

from _report import description_of
from _report import SMOKE, add_output_arguments, machine, parse_arguments, write_readme_section
from _report import photon_count

import clsky
from clsky import montecarlo

#: (altitude [m], cos view zenith, sun zenith [deg]); azimuth 0 (sun and view in one vertical plane)
CASES = [(0.0, 1.0, 30.0), (0.0, 0.5, 60.0), (0.0, 0.1, 80.0), (0.0, 0.7, 0.0), (5000.0, -0.3, 45.0),
         (0.0, 0.2, 70.0)]
#: Quadrature at which the table no longer depends on it: halving every count (100 view steps, 300 sun
#: steps, 64 x 256 transmittance table) changes these cases' radiance by at most 0.11 % (measured).
CONVERGED = dict(view_steps=200, multiple_view_steps=None, sun_steps=600, sun_transmittance="table",
                 transmittance_size=(128, 512),
                 sampling="keller_bohn")
#: The "default" rows' quadrature: TableSettings' own.
DEFAULT = clsky.TableSettings()


#: Most paths per channel of one tracer run (about 0.9 kB each alive at once): --photons beyond it runs in
#: batches, pooled (one run of 5 M paths took more than 3 GB).
BATCH = 200_000


def tracer(atmosphere, case, photons, seed):
    """(radiance, standard error) of the tracer for ``case`` (altitude, cos view, sun zenith [deg]) over
    ``photons`` paths per channel, in batches of at most :data:`BATCH` paths (seeds seed, seed + 1, ...),
    pooled: the paths' mean, and its standard error from each batch's (independent batches)."""
    altitude, cos_view, sun_zenith = case
    cos_sun = np.cos(np.radians(sun_zenith))
    counts = [min(BATCH, photons - start) for start in range(0, photons, BATCH)]
    if counts[-1] < 2:                                          # the tracer takes 2 paths at least
        counts[-2:] = [counts[-2] - 1, 2]
    means, variances = [], []
    for k, count in enumerate(counts):
        mean, error = montecarlo.sky_radiance(atmosphere, altitude, cos_view, cos_sun, 0.0, photons=count,
                                              seed=seed + k)
        means.append(count * mean)
        variances.append((count * error) ** 2)
    return np.sum(means, axis=0) / photons, np.sqrt(np.sum(variances, axis=0)) / photons


def compare(table, atmosphere, traced):
    """The rows of ``table`` against the tracer's ``traced`` {case: (radiance, standard error)}."""
    rows = []
    for (altitude, cos_view, sun_zenith), (mc, error) in traced.items():
        cos_sun = np.cos(np.radians(sun_zenith))
        nu = cos_view * cos_sun + np.sqrt((1 - cos_view**2) * (1 - cos_sun**2))
        value = table.radiance(altitude, cos_view, cos_sun, nu) / atmosphere.incident_light
        rows.append(((altitude, cos_view, sun_zenith), value, mc, error))
    return rows


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--photons", type=photon_count, default=200_000, help="paths per channel and case")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("montecarlo",))
    size = SMOKE.table if args.smoke else clsky.TableSettings().size
    if args.smoke:
        args.photons = SMOKE.photons

    lines = [f"Monte Carlo: {args.photons} paths per channel and case; measured {datetime.date.today()} on "
             f"{machine()}. Deviation = table / MC - 1 per channel (r, g, b) [%], and in units of the MC "
             f"standard error. Converged quadrature: {CONVERGED}; default: TableSettings(), "
             f"{DEFAULT.view_steps} + {DEFAULT.sun_steps} {DEFAULT.sampling} trapezoid steps. Every table: "
             f"{' x '.join(map(str, size))}, orders until 1e-4.", "",
             "| mode (preset) | quadrature | altitude [m] | cos view | sun zenith [deg] | deviation [%] | "
             "deviation [SE] |", "|---|---|---:|---:|---:|---|---|"]
    for mode in ("physical", "atmosphere-plus"):
        atmosphere = clsky.preset(mode)
        # once a case, for both quadratures (it was run twice, with one seed for every case)
        traced = {case: tracer(atmosphere, case, args.photons, seed=1 + 10**6 * index)
                  for index, case in enumerate(CASES)}
        for label, settings in (("converged", CONVERGED), ("default", {})):
            table = clsky.ScatteringTable.build(atmosphere, clsky.TableSettings(mode=mode, size=size, **settings))
            for (altitude, cos_view, sun_zenith), value, mc, error in compare(table, atmosphere, traced):
                deviation = ", ".join(f"{d:+.1f}" for d in 100 * (value / mc - 1))
                sigmas = ", ".join(f"{s:+.1f}" for s in (value - mc) / error)
                lines.append(f"| {mode} | {label} | {altitude:.0f} | {cos_view:.2f} | {sun_zenith:.0f} | "
                             f"{deviation} | {sigmas} |")
                print(lines[-1], flush=True)
    markdown = "\n".join(lines)
    if not args.no_readme:
        write_readme_section("montecarlo", markdown)
    else:
        print(markdown)


if __name__ == "__main__":
    main()
