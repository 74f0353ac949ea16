"""Benchmark: node placement along view rays (TableSettings.sampling) against an adaptive quadrature.

For each preset, single scattering along rays from observers at 0 to 100 km, looking up and down, at
the default 30 view steps, for Keller & Bohn's nodes (the default) and 'ground_end', against
:mod:`clsky.ray_quadrature` (independent of clsky). Errors are those of the NumPy twin, which the
table, scatter and ray-march kernels match to ~1e-14 (tests/test_single_twin.py, test_multiple.py,
test_view_nodes.py). Also times the OpenCL single-scattering table and a ray-marched frame with each
placement, and gives per observer altitude the placement the scene planner picks there
(clsky.planner.view_sampling). Prints the tables and writes them into README.md ("Views from altitude").

Usage: python bench/bench_view_nodes.py [--repeat N] [--no-readme] [--smoke]

``--smoke``: a handful of rays, an 8 x 32 x 8 table and a 16 x 16 frame, print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import datetime

import numpy as np

from _report import description_of
from _report import (SMOKE, add_output_arguments, load_average, load_note, machine, parse_arguments,
                     timed_with_cpu, write_readme_section)
from _report import positive_integer

from clsky import ScatteringTable, TableSettings, preset, reference
from clsky._cl import describe_device
from clsky.phase import mie_phase, rayleigh_phase
from clsky.planner import view_sampling
from clsky.ray_quadrature import single_scattering_ray
from clsky.render import RAYMARCH_DEFAULTS, SkyRenderer
from clsky.single import SingleScatteringEngine

ALTITUDES = (0.0, 1e3, 5e3, 10e3, 20e3, 32.7e3, 50e3, 75e3, 100e3)
COS_VIEWS = (1.0, 0.5, 0.2, 0.05, 0.0, -0.02, -0.05, -0.1, -0.125, -0.2, -0.3, -0.5, -0.8, -1.0)
COS_SUNS = (1.0, 0.5, 0.1)
SAMPLINGS = ("keller_bohn", "ground_end")


def sweep(smoke):
    """(h0, mu_v, mu_s, nu) rays, sun and view in one vertical plane (the table's canonical frame)."""
    altitudes, views, suns = ((0.0, 32.7e3, 100e3), (1.0, -0.125, -0.5), (1.0,)) if smoke else (
        ALTITUDES, COS_VIEWS, COS_SUNS)
    rays = [(h, mu, ms, mu * ms + np.sqrt((1 - mu * mu) * (1 - ms * ms)))
            for h in altitudes for mu in views for ms in suns if not (h == 0.0 and mu < 0.0)]
    return np.array(rays)


def groups(atmosphere, rays):
    h, mu = rays[:, 0], rays[:, 1]
    hits = mu < reference.horizon_cos(h, atmosphere.planet_radius)
    return {"ground, looking up": h == 0.0, "altitude, looking up": (h > 0.0) & (mu >= 0.0),
            "altitude, looking down, past the horizon": (mu < 0.0) & ~hits, "altitude, hitting the ground": hits}


def errors(atmosphere, rays, exact, sampling):
    """Worst-channel relative error of Ibar and of radiance (I / I_I, r, g, b) per ray."""
    settings = TableSettings(sampling=sampling)
    sun_table = reference.transmittance_table(atmosphere, settings.transmittance_size, settings.sun_steps,
                                              settings.sampling)
    h, mu, ms, nu = rays.T
    ibar = reference._single_scattering_cells(atmosphere, settings, h, mu, ms, sun_table, nu)
    f_r, f_m = rayleigh_phase(atmosphere, nu)[:, None], mie_phase(atmosphere, nu)[:, None]
    radiance, radiance_exact = (f_r * i[:, :3] + f_m * i[:, 3:] for i in (ibar, exact))
    return (np.max(np.abs(ibar / exact - 1), axis=1), np.max(np.abs(radiance / radiance_exact - 1), axis=1))


def accuracy_rows(smoke):
    """(rows by ray group, rows by observer altitude): the first per preset, sampling and group of
    :func:`groups`; the second per preset and altitude, over the rays that hit the ground, with the
    node placement the scene planner picks for an observer there (clsky.planner.view_sampling)."""
    rows, altitude_rows = [], []
    for name in ("atmosphere-plus", "physical"):
        atmosphere = preset(name)
        rays = sweep(smoke)
        exact = np.array([single_scattering_ray(atmosphere, *ray) for ray in rays])
        lit = np.all(exact > 0.0, axis=1)        # rays that see any sunlit air (100 km looking up: none)
        rays, exact = rays[lit], exact[lit]
        found = {sampling: errors(atmosphere, rays, exact, sampling) for sampling in SAMPLINGS}
        for sampling in SAMPLINGS:
            ibar_error, radiance_error = found[sampling]
            for group, mask in groups(atmosphere, rays).items():
                if mask.any():
                    stats = [100 * f(e[mask]) for e in (ibar_error, radiance_error)
                             for f in (np.median, lambda x: np.percentile(x, 95), np.max)]
                    rows.append((name, sampling, group, int(mask.sum()), stats))
                    print(name, sampling, group, int(mask.sum()), np.round(stats, 2), flush=True)
        hits = groups(atmosphere, rays)["altitude, hitting the ground"]
        for altitude in np.unique(rays[:, 0]):
            mask = hits & (rays[:, 0] == altitude)
            stats = [100 * f(found[sampling][kind][mask]) if mask.any() else None
                     for kind in (0, 1) for sampling in SAMPLINGS for f in (lambda x: np.percentile(x, 95), np.max)]
            picked = view_sampling((altitude, altitude))[0]
            altitude_rows.append((name, altitude, picked, int(mask.sum()), stats))
            print(name, altitude, picked, int(mask.sum()), stats, flush=True)
    return rows, altitude_rows


def cost_rows(size, frame, repeat):
    atmosphere = preset("atmosphere-plus")
    rows = []
    directions = np.stack(np.meshgrid(np.linspace(-0.9, 0.9, frame), np.linspace(-0.9, 0.9, frame)), axis=-1)
    directions = np.concatenate([directions, -np.sqrt(np.maximum(1.0 - (directions**2).sum(-1), 0.01))[..., None]], -1)
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    sun = np.array([0.0, 0.6, 0.8])
    table = ScatteringTable.build(atmosphere, TableSettings(size=SMOKE.table, orders=1))
    engines = {s: SingleScatteringEngine(TableSettings(size=size, sampling=s)) for s in SAMPLINGS}
    renderers = {s: SkyRenderer(table, RAYMARCH_DEFAULTS.replace(sampling=s)) for s in SAMPLINGS}
    # least wall and least process CPU time of the table and of the frame, per sampling
    best = {s: [np.inf] * 4 for s in SAMPLINGS}
    for round_ in range(repeat + 1):            # interleaved, so that load changes hit both; round 0: warm-up
        for sampling in SAMPLINGS:
            _, table_wall, table_cpu = timed_with_cpu(lambda: engines[sampling].compute(atmosphere))
            _, march_wall, march_cpu = timed_with_cpu(
                lambda: renderers[sampling].render_raymarch(directions, sun, 32.7e3))
            if round_ > 0:
                best[sampling] = [min(b, t) for b, t in zip(best[sampling],
                                                            (table_wall, table_cpu, march_wall, march_cpu))]
    for sampling in SAMPLINGS:
        renderers[sampling].close()
        rows.append((sampling, *best[sampling]))
        print(sampling, f"table {best[sampling][0]:.3f} s ({best[sampling][1]:.3f} CPU-s), ray march "
              f"{best[sampling][2] * 1e3:.1f} ms ({best[sampling][3] * 1e3:.1f} CPU-ms)", flush=True)
    engine = engines[SAMPLINGS[0]]
    return rows, describe_device(engine.device)


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--repeat", type=positive_integer, default=3, help="timing repetitions")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("view_nodes",))
    size, frame = (SMOKE.table, SMOKE.frame) if args.smoke else (TableSettings().size, 256)
    if args.smoke:
        args.repeat = SMOKE.repeat
    accuracy, by_altitude = accuracy_rows(args.smoke)
    cost, device = cost_rows(size, frame, args.repeat)
    load = load_average()

    rays = sweep(args.smoke)
    lines = [f"Single scattering along {len(rays)} rays per preset (observers at "
             f"{', '.join(f'{h / 1e3:g}' for h in np.unique(rays[:, 0]))} km, view cosines "
             f"{', '.join(f'{m:g}' for m in np.unique(rays[:, 1])[::-1])}, sun cosines "
             f"{', '.join(f'{m:g}' for m in np.unique(rays[:, 2])[::-1])}, sun and view in one vertical plane; "
             "rays that see no sunlit air left out), 30 view steps, sun transmittance from the default 2D table, "
             "against the adaptive quadrature of clsky/ray_quadrature.py. Error [%]: the worst of the six "
             "Ibar channels (Rayleigh and Mie, r, g, b), and of the radiance's r, g, b (phase functions "
             f"applied). Measured {datetime.date.today()} on {machine()}.", "",
             "| preset | sampling | rays | n | Ibar median | Ibar p95 | Ibar max | radiance median | "
             "radiance p95 | radiance max |", "|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    lines += [f"| {name} | {sampling} | {group} | {n} | " + " | ".join(f"{v:.2f}" for v in stats) + " |"
              for name, sampling, group, n, stats in accuracy]
    lines += ["", "By observer altitude: the node placement the scene planner picks for an observer there "
              "(clsky.planner.view_sampling, table and ray march), and the error [%] of the rays from there that "
              "hit the ground (the only rays the two placements treat differently), 95th percentile / maximum "
              "of the worst channel.", "",
              "| preset | observer [km] | planner picks | rays hitting the ground | Ibar keller_bohn | "
              "Ibar ground_end | radiance keller_bohn | radiance ground_end |",
              "|---|---:|---|---:|---:|---:|---:|---:|"]
    for name, altitude, picked, n, stats in by_altitude:
        pairs = ["none" if stats[i] is None else f"{stats[i]:.2f} / {stats[i + 1]:.2f}" for i in range(0, 8, 2)]
        lines.append(f"| {name} | {altitude / 1e3:g} | {picked} | {n} | " + " | ".join(pairs) + " |")
    lines += ["", f"Cost, atmosphere-plus, OpenCL device {device}, best of {args.repeat} interleaved runs after a "
              f"warm-up (load average {load:.2f} after them): the single-scattering table "
              f"{' x '.join(map(str, size))} and a {frame} x {frame} ray-marched frame (48 samples, single "
              "scattering) looking down from 32.7 km; the least wall and the least process CPU time (every "
              "thread, PoCL's workers included)." + load_note(load), "",
              "| sampling | table [s] | CPU [s] | ray march [ms] | CPU [ms] |", "|---|---:|---:|---:|---:|"]
    lines += [f"| {sampling} | {t:.3f} | {tc:.3f} | {m * 1e3:.1f} | {mc * 1e3:.1f} |"
              for sampling, t, tc, m, mc in cost]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("view_nodes", markdown)


if __name__ == "__main__":
    main()
