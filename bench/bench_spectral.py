"""Benchmark: three wavelengths against the spectral mode, and the cost of a spectral build.

- builds the physical preset (ozone, three wavelengths 650 / 510 / 475 nm, lit by the solar spectrum:
  absolute units), a spectral table of N = 15 wavelengths and the reference of 47 wavelengths (the
  midpoints of 10 nm cells, as Bruneton's CPU reference), all at the same TableSettings; wall time,
  this process' CPU time and the load average for each build;
- renders a fisheye from the ground by ray march at sun zenith 65, 88 and 94 deg and compares each
  mode's colour with the 47-wavelength reference's: the three-wavelength radiance through each
  conversion of :func:`clsky.colorimetry.three_wavelength_to_xyz`, and the N = 15 spectrum through
  :func:`clsky.colorimetry.spectral_to_xyz`.

Metrics. PSNR as Bruneton's model_test.cc computes it, on display images of linear sRGB (XYZ ->
linear sRGB, then v = (1 - exp(-e c))^(1/2.2) per channel, clipped to [0, 1], over every pixel and
channel, peak 1), with the exposure e = 1 / mean reference luminance of the frame (his fixed e = 1e-4 m^2/cd
is this for a sky of 10 kcd/m^2; a fixed exposure would turn the frame with the sun 4 deg below the
horizon black). Mean Delta E 2000 (colour-science's ``delta_E(..., method='CIE 2000')``) over the
pixels, CIE Lab of XYZ / Y_w with the D65 white and Y_w the reference frame's 99th-percentile luminance.
Bruneton's anchors (3 wavelengths against 47 in luminance): >= 40 dB at 65 deg, >= 35 dB at 88 deg.

Usage: python bench/bench_spectral.py [--size W H D] [--frame PIXELS] [--spectral N] [--no-readme] [--smoke]

``--smoke``: an 8 x 32 x 8 table, 16 x 16 frames, 4 and 6 wavelengths instead of 15 and 47; print only.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import time

import numpy as np

from _report import description_of
from _report import SMOKE, add_output_arguments, machine, parse_arguments, write_readme_section
from _report import frame_side, integer_in, table_nodes

import clsky
from clsky.anim.cameras import FisheyeCamera, sun_direction
from clsky import colorimetry, spectrum
from clsky._cl import describe_device, make_context
from clsky.render import SkyRenderer
from clsky.solar import with_solar_spectrum
from clsky.spectrum import MAX_WAVELENGTHS, MIN_COLOUR_WAVELENGTHS

SUN_ZENITHS = (65.0, 88.0, 94.0)
#: Sun zeniths of the twilight zenith's colour (93 deg: the dusk of issue 10, the sun 3 deg down).
DUSK_ZENITHS = (93.0, 94.0)
#: Bruneton's PSNR anchors (model_test.cc, luminance, 3 wavelengths on the GPU vs 47 on the CPU) [dB].
ANCHORS = {65.0: 40.0, 88.0: 35.0}


def display(rgb, exposure):
    """Bruneton's display values of linear sRGB (module docstring), in [0, 1]."""
    return np.clip(1.0 - np.exp(-exposure * np.maximum(rgb, 0.0)), 0.0, 1.0) ** (1.0 / 2.2)


def psnr(test_xyz, reference_xyz, valid):
    """PSNR [dB] of the display images of two XYZ frames (module docstring)."""
    exposure = 1.0 / float(np.mean(reference_xyz[valid][:, 1]))
    a = display(colorimetry.xyz_to_linear_srgb(test_xyz[valid]), exposure)
    b = display(colorimetry.xyz_to_linear_srgb(reference_xyz[valid]), exposure)
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(1.0 / mse)


def mean_delta_e_2000(test_xyz, reference_xyz, valid):
    """Mean CIEDE2000 over the valid pixels (module docstring)."""
    import colour

    white_y = float(np.percentile(reference_xyz[valid][:, 1], 99))
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    lab = [colour.XYZ_to_Lab(np.maximum(x[valid], 0.0) / white_y, white) for x in (test_xyz, reference_xyz)]
    return float(np.mean(colour.delta_E(lab[0], lab[1], method="CIE 2000")))


def timed(function):
    """(result, wall [s], process CPU [s], load average after)."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = function()
    return result, time.perf_counter() - wall, time.process_time() - cpu, os.getloadavg()[0]


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--size", type=table_nodes, nargs=3, default=list(clsky.TableSettings().size),
                        metavar=("W", "H", "D"))
    parser.add_argument("--frame", type=frame_side, default=96, help="fisheye side [px]")
    parser.add_argument("--spectral", type=integer_in(MIN_COLOUR_WAVELENGTHS, MAX_WAVELENGTHS), default=15,
                        help="N of the spectral mode")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("spectral",))
    reference_count = spectrum.MAX_WAVELENGTHS
    if args.smoke:
        args.size, args.frame, args.spectral, reference_count = list(SMOKE.table), SMOKE.frame, 4, 6
    try:                        # each axis in [2, 4096] passed argparse, their product is checked here
        settings = clsky.TableSettings(size=tuple(args.size), mode="physical")
    except ValueError as error:
        parser.error(f"--size: {error}")
    ctx = make_context()
    load_before = os.getloadavg()[0]
    three_atmosphere = with_solar_spectrum(clsky.preset("physical"))
    clsky.ScatteringTable.build(three_atmosphere, settings.replace(size=(8, 16, 8)), ctx=ctx)   # compile, warm up
    three, *three_time = timed(lambda: clsky.ScatteringTable.build(three_atmosphere, settings, ctx=ctx))
    spectral, *spectral_time = timed(lambda: spectrum.SpectralTable.build("physical", args.spectral, settings, ctx=ctx))
    reference, *reference_time = timed(lambda: spectrum.SpectralTable.build("physical", reference_count, settings,
                                                                            ctx=ctx))
    timing_rows = []
    for label, count, batches, (wall, cpu, load) in (
            ("three wavelengths (650, 510, 475 nm)", 3, 1, three_time),
            (f"spectral, N = {args.spectral}", args.spectral, spectral.record["batches"], spectral_time),
            (f"spectral reference, N = {reference_count}", reference_count, reference.record["batches"],
             reference_time)):
        timing_rows.append(f"| {label} | {batches} | {wall:.2f} | {cpu:.2f} | {wall / three_time[0]:.2f} | {load:.2f} |")
        print(timing_rows[-1], flush=True)

    directions, valid = FisheyeCamera(args.frame).directions()
    frames = {}
    with SkyRenderer(three, ctx=ctx) as renderer_3, spectrum.SpectralRenderer(spectral, ctx=ctx) as renderer_n, \
            spectrum.SpectralRenderer(reference, ctx=ctx) as renderer_ref:
        prepared = [r.prepare(directions, valid) for r in (renderer_3, renderer_n, renderer_ref)]
        for zenith in SUN_ZENITHS:
            sun = sun_direction(zenith, 180.0)
            frames[zenith] = [r.render_raymarch(p, sun, 0.0) for r, p in zip((renderer_3, renderer_n, renderer_ref),
                                                                               prepared)]
        up = np.array([[0.0, 0.0, 1.0]])
        zenith_pixels = {z: [r.render_raymarch(up, sun_direction(z, 180.0), 0.0)[0]
                             for r in (renderer_3, renderer_n, renderer_ref)] for z in DUSK_ZENITHS}
    rows = []
    for zenith in SUN_ZENITHS:
        rgb3, spectral_frame, reference_frame = frames[zenith]
        reference_xyz = colorimetry.spectral_to_xyz(reference_frame, reference.wavelengths)
        candidates = [(f"3 wavelengths, {method}", colorimetry.three_wavelength_to_xyz(rgb3, three.atmosphere.wavelengths,
                                                                                      method))
                      for method in colorimetry.THREE_WAVELENGTH_METHODS]
        candidates.append((f"N = {args.spectral}", colorimetry.spectral_to_xyz(spectral_frame, spectral.wavelengths)))
        for label, xyz in candidates:
            anchor = ANCHORS.get(zenith)
            rows.append(f"| {label} | {zenith:.0f} | {psnr(xyz, reference_xyz, valid):.1f} | "
                        f"{mean_delta_e_2000(xyz, reference_xyz, valid):.2f} | "
                        f"{'>= %.0f dB' % anchor if anchor else '(none)'} |")
            print(rows[-1], flush=True)
        luminance = float(np.mean(reference_xyz[valid][:, 1]))
        rows.append(f"| (reference mean luminance: {luminance:.4g} cd/m^2) | {zenith:.0f} | | | |")

    dusk_rows = []
    for zenith in DUSK_ZENITHS:
        rgb3, spectral_pixel, reference_pixel = zenith_pixels[zenith]
        for label, xyz in ((f"3 wavelengths, {colorimetry.DEFAULT_THREE_WAVELENGTH_METHOD}",
                            colorimetry.three_wavelength_to_xyz(rgb3, three.atmosphere.wavelengths)),
                           (f"N = {args.spectral}", colorimetry.spectral_to_xyz(spectral_pixel, spectral.wavelengths)),
                           (f"N = {reference_count}", colorimetry.spectral_to_xyz(reference_pixel,
                                                                                 reference.wavelengths))):
            r, g, b = colorimetry.xyz_to_linear_srgb(xyz)
            dusk_rows.append(f"| {label} | {zenith:.0f} | {r:.4g}, {g:.4g}, {b:.4g} | {b / g:.2f} | {g / r:.2f} |")
            print(dusk_rows[-1], flush=True)

    lines = [f"Spectral against three wavelengths, measured {datetime.date.today()} on {machine()}, OpenCL device "
             f"{describe_device(ctx.devices[0])}; physical preset (ozone), TableSettings(size={tuple(args.size)}, "
             f"mode='physical'), ray-marched {args.frame} x {args.frame} fisheye from the ground, sun azimuth 180 deg, "
             f"compared with N = {reference_count} (bench/bench_spectral.py; load average {load_before:.2f} before).", "",
             "| build | batches | wall [s] | CPU [s] | wall / three | load |", "|---|---:|---:|---:|---:|---:|",
             *timing_rows, "",
             f"| mode against N = {reference_count} | sun zenith [deg] | PSNR [dB] | mean Delta E 2000 | "
             f"Bruneton's anchor |", "|---|---:|---:|---:|---|", *rows, "",
             "The zenith from the ground at dusk, linear sRGB (blue when b/g > 1 and g/r > 1):", "",
             "| mode | sun zenith [deg] | zenith linear sRGB r, g, b [cd/m^2] | b / g | g / r |",
             "|---|---:|---|---:|---:|", *dusk_rows]
    markdown = "\n".join(lines)
    print(markdown)
    if not args.no_readme:
        write_readme_section("spectral", markdown)


if __name__ == "__main__":
    main()
