"""Benchmark (picture): one dusk, sun 3 deg below the horizon, shown with and without ozone, with three
and with N = 15 wavelengths, and through the old and the new display.

The old display is the one before issue 10: the relative three-wavelength frames (the notes' I_I, the
same table rendered with the preset's incident light) taken as linear Rec. 709 r, g, b, through the
notes' curve at EV 0 (three wavelengths only). The others show the frames the animation now renders, in
cd/m^2 (three wavelengths converted through clsky.colorimetry, or N = 15): the notes' curve at the
auto-exposure's EV without white balance, then the new display, the defaults (``luminance-reinhard``,
auto-exposure, white balance ``sun``; anim/display.py). Each sky
is the physical preset's (ozone 300 DU, ground albedo 0.1; "without ozone": the same with
``--ozone-column 0``), ray-marched on an all-sky fisheye from the ground at the default quality level
over a table planned for this sun, as ``clsky render --method raymarch --sun-elevation -3`` does.
Prints the zenith's 8-bit sRGB and its linear ratios, writes the composite picture into docs/ and the
table into README.md.

Usage: python bench/bench_dusk.py [--size PX] [--no-readme] [--smoke]

``--smoke``: 16-pixel frames and an 8 x 32 x 8 table per sky; print only (bench/_report.py).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import pathlib
import time

import numpy as np

from _report import description_of
from _report import SMOKE, add_output_arguments, machine, parse_arguments, write_readme_section
from _report import frame_side

from clsky.anim import metrics, writers
from clsky.anim.animate import (AnimationConfig, display, display_frames, make_renderer, planned_animation,
                                ray_settings, render_frame)
from clsky.anim.display import Display
from clsky.render import SkyRenderer
from clsky.anim.cameras import sun_direction
from clsky.anim.sunpath import SunPosition

#: The dusk of the issue: the sun 3 deg below the horizon, in the south.
SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG = -3.0, 180.0
#: Radius [deg] of the disc around the zenith whose mean pixel is reported (a few pixels at 128 px).
ZENITH_RADIUS_DEG = 5.0
#: (label, AnimationConfig fields) of the skies.
SKIES = [("with ozone, 3 wavelengths", "O3, 3 wl", {}),
         ("with ozone, N = 15", "O3, 15 wl", {"wavelengths": 15}),
         ("without ozone, 3 wavelengths", "no O3, 3 wl", {"ozone_column_du": 0.0}),
         ("without ozone, N = 15", "no O3, 15 wl", {"ozone_column_du": 0.0, "wavelengths": 15})]
#: (label, AnimationConfig fields) of the displays.
#: The old display (the notes' curve at EV 0) exists for the relative frames of three wavelengths only:
#: frames in cd/m^2 need an exposure, so they get the notes' curve at the metered EV.
DISPLAYS = [("old: relative r, g, b, notes' curve, EV 0", "old",
             {"tone_map": "atmosphere-plus", "exposure": 0.0, "auto_exposure": False, "white_balance": "d65"}),
            ("notes' curve, auto-exposure", "curve",
             {"tone_map": "atmosphere-plus", "auto_exposure": True, "white_balance": "d65"}),
            ("new (defaults): luminance-reinhard, auto-exposure, white balance sun", "new",
             {"tone_map": "luminance-reinhard", "auto_exposure": True, "white_balance": "sun"})]
#: "Blue" means b > g > r in the linear values by at least 2 % each: about the Weber fraction (1-2 %) of
#: a just visible difference, so that r = g within rounding (a grey-violet) does not count as blue.
BLUE_MARGIN = 1.02
PICTURE = pathlib.Path(__file__).resolve().parent.parent / "docs" / "dusk.png"


def zenith_mean(values, directions, valid):
    """Mean of ``values`` (H, W, C) over the valid pixels within ZENITH_RADIUS_DEG of the zenith (at
    least the 4 nearest, on frames too coarse to have a pixel that close)."""
    z = np.where(valid, directions[..., 2], -2.0)
    near = z >= min(np.cos(np.radians(ZENITH_RADIUS_DEG)), np.sort(z, axis=None)[-4])
    return values[near].astype(np.float64).mean(axis=0)


def render_sky(fields, size, smoke):
    """(HDR ray-marched frame, directions, valid, build seconds, table, config, relative frame) of one
    sky; the relative frame (three wavelengths only, else None) is the same table rendered with the
    preset's incident light I_I, as before issue 10."""
    config = AnimationConfig(size=size, method="raymarch", dither=False, table_size=SMOKE.table if smoke else None,
                             **fields)
    position = SunPosition(90.0 - SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG)
    start = time.perf_counter()
    planned = planned_animation(config, [position])                 # no plan with the smoke's table size
    directions, valid = planned.directions, planned.valid
    renderer, table = make_renderer(config, planned.plan)
    seconds = time.perf_counter() - start
    sun = sun_direction(90.0 - SUN_ELEVATION_DEG, SUN_AZIMUTH_DEG)
    hdr = render_frame(renderer, renderer.prepare(directions, valid), sun, config)["raymarch"]
    relative = None
    if config.wavelengths is None:
        with SkyRenderer(dataclasses.replace(table, atmosphere=config.atmosphere), ray_settings(config)) as notes:
            relative = notes.render_raymarch(directions, sun, valid=valid)
    return hdr, directions, valid, seconds, table, config, relative


def main():
    parser = argparse.ArgumentParser(description=description_of(__doc__))
    parser.add_argument("--size", type=frame_side, default=128, help="fisheye side [px] (default: 128)")
    add_output_arguments(parser)
    args = parse_arguments(parser, sections=("dusk",))
    size = SMOKE.frame if args.smoke else args.size
    load = os.getloadavg()[0]
    cpu_start, wall_start = time.process_time(), time.perf_counter()
    rows, panels, labels = [], [], []
    for sky, sky_short, fields in SKIES:
        hdr, directions, valid, seconds, table, config, relative = render_sky(fields, size, args.smoke)
        for shown, shown_short, options in DISPLAYS:
            if shown_short == "old" and relative is None:
                continue
            shown_config = AnimationConfig(**{**config.__dict__, **options})
            if shown_short == "old":          # the display before issue 10: the notes' curve of I_I r, g, b
                frame, pipeline = relative, Display(tone_map="atmosphere-plus")
            else:
                frame, pipeline = hdr, display(shown_config, table)
            linear = zenith_mean(frame, directions, valid)
            _, images, _ = display_frames(pipeline, {"raymarch": frame}, valid, shown_config)
            image = images["raymarch"]
            pixel = zenith_mean(image, directions, valid)
            rows.append((sky, shown, pixel, linear))
            panels.append(image)
            labels.append(f"{sky_short}, {shown_short}")
        print(f"{sky}: built in {seconds:.1f} s, zenith linear {np.round(zenith_mean(hdr, directions, valid), 4)}",
              flush=True)
    cpu, wall = time.process_time() - cpu_start, time.perf_counter() - wall_start

    lines = [f"Dusk, sun {SUN_ELEVATION_DEG:g} deg, physical preset, all-sky fisheye of {size} px from the ground "
             f"(ray march, default quality, table planned for this sun); zenith = mean over {ZENITH_RADIUS_DEG:g} "
             f"deg around it; blue = b > g > r by at least {100 * (BLUE_MARGIN - 1):.0f} % each in the linear values. Measured {datetime.date.today()} on {machine()}: {wall:.0f} s wall, {cpu:.0f} s "
             f"process CPU, load average {load:.2f} before (bench/bench_dusk.py). Linear values: linear sRGB "
             f"[cd/m^2] (three wavelengths through clsky.colorimetry's power-law reconstruction, or N = 15); "
             f"the old display's: the relative r, g, b at 650, 510, 475 nm (I_I units).", "",
             "| sky | display | zenith sRGB (8 bit) | blue: b > g > r | linear b / g | linear g / r |",
             "|---|---|---|---|---:|---:|"]
    for sky, shown, pixel, linear in rows:
        r, g, b = pixel
        blue = linear[2] > BLUE_MARGIN * linear[1] and linear[1] > BLUE_MARGIN * linear[0]
        lines.append(f"| {sky} | {shown} | ({r:.0f}, {g:.0f}, {b:.0f}) | {'yes' if blue else 'no'} | "
                     f"{linear[2] / linear[1]:.3f} | {linear[1] / linear[0]:.3f} |")
    table = "\n".join(lines)
    print(table)
    if args.no_readme:
        return
    per_row = 5                                          # one ozone setting per row: 3 + 2 panels
    rows_of_panels = [metrics.composite(panels[i:i + per_row], labels[i:i + per_row])
                      for i in range(0, len(panels), per_row)]
    width = max(p.shape[1] for p in rows_of_panels)
    picture = np.concatenate([np.pad(p, ((0, 0), (0, width - p.shape[1]), (0, 0))) for p in rows_of_panels])
    PICTURE.parent.mkdir(exist_ok=True)
    writers.write_png(PICTURE, picture, force=True)
    write_readme_section("dusk", table + f"\n\n![dusk: ozone, wavelengths, display](docs/{PICTURE.name})")


if __name__ == "__main__":
    main()
