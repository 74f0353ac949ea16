"""The scene plan's choice of renderer (clsky/renderer_choice.py, clsky/planner.py): the cheapest whose
measured error over the sun path fits the budget."""

from __future__ import annotations

import dataclasses
import math
import pathlib

import numpy as np
import pytest

from clsky.anim.cameras import FisheyeCamera
from clsky.planner import Scene, plan_scene
from clsky.renderer_choice import (DEFAULT_PIXELS, LOOKUP_ERROR, RAY_MARCH_ERROR, REFERENCE_RESOLUTION, RENDERERS,
                                   SKYVIEW_ON_REFERENCE, RendererRow, choose_renderer, error_at, error_over,
                                   estimate_basis, estimated_error, renderer_row, with_resolution)


row = renderer_row


def more(percent):
    """What the plan's words add to a figure measured against the reference (:func:`with_resolution`): the
    reference's own estimated error at the worst sun, in per cent to 2 digits."""
    return f", + the reference's own estimated error, {percent} %"


def test_error_over_takes_the_worst_of_the_path_interpolated_in_log_error():
    # inside the measured range: log-linear between the two neighbours
    middle = math.exp(0.5 * (math.log(0.361) + math.log(0.0419)))
    assert error_over(LOOKUP_ERROR, 4.5, 4.5) == pytest.approx(middle, rel=1e-12)
    # the path's worst: the lowest sun for the lookup (its error falls as the sun rises)
    assert error_over(LOOKUP_ERROR, 1.0, 60.0) == pytest.approx(0.361, rel=1e-12)
    # beyond the measured elevations: the nearest value
    assert error_over(LOOKUP_ERROR, -10.0, -6.0) == pytest.approx(10.26, rel=1e-12)
    # a measured elevation inside the path counts even when both ends are lower
    bump = ((0.0, 0.01), (10.0, 0.05), (20.0, 0.01))
    assert error_over(bump, 5.0, 15.0) == pytest.approx(0.05, rel=1e-12)


#: Rendered pixels of the 1024 x 1024 all-sky fisheye (clsky.anim.cameras.FisheyeCamera).
FISHEYE_1024 = 823592


def test_rows_are_measured_lines_in_the_frame_pixels():
    """Each row's cost a frame is a part per frame and a part per pixel (bench/bench_renderer_costs.py):
    the sky-view map's map costs more than a 512 x 512 fisheye's 3D lookup, its reading less a pixel,
    so the 3D lookup is the cheaper on the default frames and the map on 1024 x 1024 ones."""
    methods = [r.method for r in RENDERERS]
    assert methods == ["lut", "skyview", "lut4d", "raymarch"]
    assert all(r.fixed_cpu_ms >= 0.0 and r.pixel_cpu_ns > 0.0 and r.source for r in RENDERERS)
    lut, skyview, lut4d, march = (row(m) for m in methods)
    assert lut.frame_cpu_ms(1000) == pytest.approx(lut.fixed_cpu_ms + 1000 * lut.pixel_cpu_ns * 1e-6, rel=1e-12)
    assert lut.frame_cpu_ms(DEFAULT_PIXELS) < skyview.frame_cpu_ms(DEFAULT_PIXELS) < march.frame_cpu_ms(DEFAULT_PIXELS)
    assert skyview.frame_cpu_ms(FISHEYE_1024) < lut.frame_cpu_ms(FISHEYE_1024) < march.frame_cpu_ms(FISHEYE_1024)
    crossover = (skyview.fixed_cpu_ms - lut.fixed_cpu_ms) / ((lut.pixel_cpu_ns - skyview.pixel_cpu_ns) * 1e-6)
    assert DEFAULT_PIXELS < crossover < FISHEYE_1024           # about 630 000 pixels (the module docstring)
    # the 4D lookup reads more a pixel than the 3D one, and its own table costs 12.4 CPU-s (the default scene's)
    assert lut4d.pixel_cpu_ns > lut.pixel_cpu_ns and lut4d.build_cpu_s == 12.4
    assert all(r.build_cpu_s == 0.0 for r in (lut, skyview, march))
    assert set(RAY_MARCH_ERROR) == {"draft", "default", "high", "reference"}


def test_the_default_pixels_are_the_default_animations_fisheye():
    from clsky.anim.animate import AnimationConfig, _camera

    _, valid = _camera(AnimationConfig()).directions()
    assert int(valid.sum()) == DEFAULT_PIXELS
    _, valid = FisheyeCamera(1024).directions()
    assert int(valid.sum()) == FISHEYE_1024


@pytest.mark.parametrize("path, budget, level, pixels, expected", [
    ((20.0, 60.0), 0.1, "draft", DEFAULT_PIXELS, "lut"),   # by day the lookup is within 4.2 % (measured at +8 deg)
    ((20.0, 60.0), 0.1, "draft", FISHEYE_1024, "skyview"),  # both fit; the map costs less a 1024^2 frame
    ((-6.0, 60.0), 0.01, "default", DEFAULT_PIXELS, "skyview"),  # the lookup's 1026 % fails; the map's 0.83 % fits
    ((-6.0, 60.0), 0.01, "default", 1000, "raymarch"),      # the map fits, but its 8192 rays cost more than 1000
    ((-8.0, 60.0), 0.01, "default", DEFAULT_PIXELS, "raymarch"),  # the map measured 1.01 % at -8 deg
    ((-6.0, 60.0), 1e-3, "high", DEFAULT_PIXELS, "raymarch"),  # the map measured 0.18 % at -6 deg, over 0.1 %
    ((-4.0, 60.0), 0.1, "draft", FISHEYE_1024, "skyview"),  # the map measured 6.6 % at -4 deg fits 10 %
    ((-6.0, 60.0), 0.1, "draft", FISHEYE_1024, "raymarch"),  # the map measured 14 % at -6 deg (the ray march too)
])
def test_choice_is_the_cheapest_that_fits(path, budget, level, pixels, expected):
    chosen, estimate, estimates = choose_renderer(path, budget, level, pixels=pixels)
    assert chosen.method == expected
    assert estimate == estimates[expected]
    cheaper = [r for r in RENDERERS if r.frame_cpu_ms(pixels) < chosen.frame_cpu_ms(pixels) and r.build_cpu_s == 0.0]
    assert all(estimates[r.method] > budget for r in cheaper)
    if expected != "raymarch":
        assert estimate <= budget


def test_a_new_renderer_is_one_row():
    """A renderer without a table of its own enters as one row and wins where it is the cheapest that
    fits: here, between the 3D lookup and the sky-view map a frame, and within the budget in twilight."""
    other = RendererRow("other", "another lookup", 0.5 * (row("lut").fixed_cpu_ms + row("skyview").fixed_cpu_ms),
                        0.5 * (row("lut").pixel_cpu_ns + row("skyview").pixel_cpu_ns),
                        ((-4.0, 0.02), (45.0, 0.005)), False, "a test row")
    assert row("lut").frame_cpu_ms(DEFAULT_PIXELS) < other.frame_cpu_ms(DEFAULT_PIXELS) \
        < row("skyview").frame_cpu_ms(DEFAULT_PIXELS)
    rows = RENDERERS + (other,)
    assert choose_renderer((-6.0, 60.0), 0.03, "default", rows)[0].method == "other"
    assert choose_renderer((-6.0, 60.0), 0.01, "default", rows)[0].method == "skyview"
    assert choose_renderer((20.0, 60.0), 0.1, "draft", rows)[0].method == "lut"


def test_the_4d_lookup_counts_its_table_build():
    """Down to -6 deg the 4D lookup's 3.9 % plus the default ray march's 0.80 % (and the reference's own
    resolution there, REFERENCE_RESOLUTION) fits a 5 % budget; on the
    default frames it costs less than the sky-view map, but its table costs 12.4 CPU-s, so it wins only from
    12.4 s / (the map's cost - its own) frames on, about 1700; on 1024 x 1024 frames it costs more than the
    map and never wins. Without a frame count (the scene plan) it is left out."""
    path, budget = (-6.0, 60.0), 0.05
    chosen, _, estimates = choose_renderer(path, budget, "default")
    resolution = dict(REFERENCE_RESOLUTION)[-6.0]
    assert estimates["lut4d"] == pytest.approx(0.039 + 0.0080 + resolution, rel=1e-12) and estimates["lut4d"] <= budget
    assert chosen.method == "skyview"                                    # frames unknown: no build counted
    saved_ms = row("skyview").frame_cpu_ms(DEFAULT_PIXELS) - row("lut4d").frame_cpu_ms(DEFAULT_PIXELS)
    pays_from = 1000.0 * row("lut4d").build_cpu_s / saved_ms
    assert 1000 < pays_from < 3000                                      # about 1700 (the module docstring)
    assert choose_renderer(path, budget, "default", frames=120)[0].method == "skyview"
    assert choose_renderer(path, budget, "default", frames=math.floor(pays_from))[0].method == "skyview"
    assert choose_renderer(path, budget, "default", frames=math.ceil(pays_from))[0].method == "lut4d"
    assert row("lut4d").cost_cpu_s(370, DEFAULT_PIXELS) == pytest.approx(
        12.4 + 370 * row("lut4d").frame_cpu_ms(DEFAULT_PIXELS) / 1000.0, rel=1e-12)
    # on larger frames it costs more than the map a frame: no frame count makes it win
    assert row("lut4d").frame_cpu_ms(FISHEYE_1024) > row("skyview").frame_cpu_ms(FISHEYE_1024)
    assert choose_renderer(path, budget, "default", frames=100000, pixels=FISHEYE_1024)[0].method == "skyview"
    # where it does not fit (1 %: its own 3.9 % at -6 deg), no frame count makes it win
    assert choose_renderer(path, 0.01, "default", frames=100000)[0].method == "skyview"


def test_a_bound_adds_the_references_resolution():
    """with_resolution: a figure measured against the reference plus the reference's own estimated error
    (REFERENCE_RESOLUTION: 0.0216 % at 45 deg, 0.0182 % at +1, 0.0902 % at -4, 0.14 % at -6, 0.278 % at -12) at
    the elevations of both, the measured figure interpolated in log error between its own (at -4 deg, 2/7 of
    the way from -6 to +1: 0.8 % * 0.25^(2/7)) and its nearest value beyond them; the figures of the reference
    level's ray march as they are (they are that estimate already), those of a row of its own (level None) not."""
    measured = ((-6.0, 0.008), (1.0, 0.002), (45.0, 0.003))
    bound = dict(with_resolution(measured, "default"))
    assert list(bound) == [-12.0, -10.0, -8.0, -6.0, -4.0, 1.0, 8.0, 45.0]
    expected = {-12.0: 0.008 + 0.00278, -6.0: 0.008 + 0.0014, -4.0: 0.008 * 0.25 ** (2 / 7) + 0.000902,
                1.0: 0.002 + 0.000182, 45.0: 0.003 + 0.000216}
    for sun, value in expected.items():
        assert bound[sun] == pytest.approx(value, rel=1e-12), sun
    assert with_resolution(measured, None) == with_resolution(measured, "high") == tuple(bound.items())
    assert with_resolution(measured, "reference") == measured


def test_nothing_fits_falls_back_to_the_ray_march():
    """The reference level's ray-march estimate is the reference's own estimated error (nothing added), worst at -6
    deg on this path."""
    chosen, estimate, _ = choose_renderer((-6.0, 60.0), 1e-5, "reference")
    assert chosen.method == "raymarch" and estimate == pytest.approx(dict(REFERENCE_RESOLUTION)[-6.0], rel=1e-12)
    assert max(e for sun, e in REFERENCE_RESOLUTION if sun >= -6.0) == dict(REFERENCE_RESOLUTION)[-6.0]


def test_the_map_measured_against_the_reference_replaces_the_sum_from_the_ground():
    """The sky-view map was measured against the reference from the ground (SKYVIEW_ON_REFERENCE, -12 to 45
    deg): from the ground its estimate is that measurement, no better than the level's ray march (default, -6
    deg: 0.83 %, where the sum says 0.80 % + 0.31 %; draft, -8 deg: its ray march's 0.123 % over the map's
    0.122 %); from above the ground, even 1 m, where nothing was measured against the reference, the sum."""
    skyview = row("skyview")
    for level in ("draft", "default", "high"):
        ground, above, mast = (estimated_error(skyview, level, h) for h in (0.0, 10e3, 1.0))
        suns = np.array([sun for sun, _ in ground])
        direct, march = SKYVIEW_ON_REFERENCE[level], RAY_MARCH_ERROR[level]
        assert [sun for sun, _ in above] == suns.tolist() and above == mast
        assert [e for _, e in ground] == pytest.approx(np.maximum(error_at(direct, suns), error_at(march, suns)),
                                                       rel=1e-12)
        assert [e for _, e in above] == pytest.approx(error_at(march, suns) + error_at(skyview.error, suns),
                                                      rel=1e-12)
        # never better than the ray march, at any sun, measured or between
        between = np.linspace(-14.0, 50.0, 257)
        assert np.all(error_at(ground, between) >= error_at(march, between))
    assert dict(estimated_error(skyview, "default"))[-6.0] == pytest.approx(0.00826, rel=1e-12)
    assert dict(estimated_error(skyview, "default", 10e3))[-6.0] == pytest.approx(0.0080 + 0.00314, rel=1e-12)
    assert dict(estimated_error(skyview, "draft"))[-8.0] == pytest.approx(0.123, rel=1e-12)
    assert choose_renderer((-6.0, 60.0), 0.01, "default")[0].method == "skyview"
    for height in (1.0, 10e3):
        assert choose_renderer((-6.0, 60.0), 0.01, "default", altitude_m=height)[0].method == "raymarch"
    with pytest.raises(ValueError, match=r"^altitude_m must be a number in \[0, 1e\+08\]"):
        choose_renderer((-6.0, 60.0), 0.01, altitude_m=-1.0)


def test_a_measurement_over_part_of_the_path_meets_the_sum_without_a_step():
    """A row measured against the reference over part of the suns only (here -8 to -6 deg, worse than the sum
    at -4): there the measurement, elsewhere the ray march's error plus its own, and between -6 deg and the
    next measured sun (-4) the two interpolated in log error; the plan's words name both."""
    part = dataclasses.replace(row("skyview"), on_reference=(("default", ((-8.0, 0.0101), (-6.0, 0.012))),))
    estimate = dict(estimated_error(part, "default"))
    summed = error_at(RAY_MARCH_ERROR["default"], -4.0) + error_at(part.error, -4.0)
    assert estimate[-6.0] == pytest.approx(0.012, rel=1e-12) and estimate[-4.0] == pytest.approx(summed, rel=1e-12)
    assert error_at(estimated_error(part, "default"), -5.0) == pytest.approx(np.sqrt(0.012 * summed), rel=1e-12)
    # the reference's own estimated error interpolated in log error between its suns: at -5 deg between 0.14 (-6)
    # and 0.090 % (-4), sqrt(0.14 * 0.090) = 0.11 %; at -7 deg sqrt(0.14 * 0.18) = 0.16 %
    assert estimate_basis(part, "default", (-5.0, 10.0)) == (
        "interpolated at -5 deg between its measurement against the reference and the ray march's + its own"
        + more("0.11"))
    assert estimate_basis(part, "default", (-8.0, -7.0)) == ("measured against the reference, interpolated at -7 deg"
                                                            + more("0.16"))
    assert estimate_basis(part, "default", (-12.0, -7.0)) == ("estimated: the ray march's + its own, measured at -12 "
                                                             "deg" + more("0.28"))
    # 0 deg is a node of the map's own error, not of the ray march's: interpolated, not 'measured at 0 deg'
    assert estimate_basis(part, "default", (-3.0, 10.0)) == ("estimated: the ray march's + its own, measured, "
                                                            "interpolated at -3 deg" + more("0.065"))


@pytest.mark.parametrize("level, path, altitude, words, reference", [
    ("default", (-6.0, 60.0), 0.0, "measured against the reference at -6 deg", "0.14"),
    ("default", (-12.0, -7.0), 0.0, "measured against the reference at -12 deg", "0.28"),
    ("default", (-30.0, -20.0), 0.0, "measured against the reference at -12 deg", "0.28"),   # the nearest measured
    ("default", (-2.0, 60.0), 0.0, "measured against the reference, interpolated at -2 deg", "0.048"),  # not 0 deg
    ("draft", (-8.0, -8.0), 0.0, "the ray march's, measured (the map measured less) at -8 deg", "0.18"),  # the floor
    ("default", (-12.0, -7.0), 10e3, "estimated: the ray march's + its own, measured at -12 deg", "0.28"),
    ("default", (-5.0, 10.0), 10e3, "estimated: the ray march's + its own, measured, interpolated at -5 deg", "0.11"),
])
def test_the_plans_words_say_which_figure_made_the_worst(level, path, altitude, words, reference):
    """estimate_basis: at the worst sun over the path, the measurement against the reference, the ray march's
    where that was lower, or the sum; 'measured at' a measured sun, 'interpolated at' a path end between; and
    the reference's own estimated error there, which the estimate adds (REFERENCE_RESOLUTION: at -2 deg
    interpolated in log error between 0.090 % at -4 and 0.018 % at +1, 0.090 * 0.2^0.4 = 0.048 %)."""
    assert estimate_basis(row("skyview"), level, path, altitude) == words + more(reference)


def test_the_plans_words_for_the_other_rows():
    """The 3D lookup's error is its own measured one, with the reference's own estimated error added at any
    level; the ray march's row adds nothing to the level's; the reference level's ray-march figures are the
    reference's own estimated error already, so nothing is added to them."""
    assert estimate_basis(row("lut"), "default", (-6.0, 60.0)) == "measured" + more("0.14")
    assert estimate_basis(row("lut"), "reference", (-6.0, 60.0)) == "measured" + more("0.14")
    assert estimate_basis(row("raymarch"), "default", (-6.0, 60.0)) == ("the ray march's, measured at -6 deg"
                                                                        + more("0.14"))
    assert estimate_basis(row("skyview"), "reference", (-6.0, 60.0)) == ("estimated: the ray march's + its own, "
                                                                         "measured at -6 deg")
    # the reference level's ray march: its figure is the reference's own estimated error, not a measurement
    assert estimate_basis(row("raymarch"), "reference", (-6.0, 60.0)) == ("the reference's own estimated error, at "
                                                                          "-6 deg")


def test_the_maps_estimate_from_the_ground_takes_the_measured_figures():
    """Figures taken from docs/quality.csv and docs/quality_dusk.csv through the estimate: the default map at -4
    deg 0.785 %, at +1 deg its ray march's 0.178 % (the map measured 0.177 %), the high map at 45 deg 0.113 %;
    from 10 km at -4 deg the default ray march's 0.676 % + the map's own 0.292 %."""
    skyview = row("skyview")
    assert dict(estimated_error(skyview, "default"))[-4.0] == pytest.approx(0.00785, rel=1e-12)
    assert dict(estimated_error(skyview, "default"))[1.0] == pytest.approx(0.00178, rel=1e-12)
    assert dict(estimated_error(skyview, "high"))[45.0] == pytest.approx(0.00113, rel=1e-12)
    assert dict(estimated_error(skyview, "default", 10e3))[-4.0] == pytest.approx(0.00676 + 0.00292, rel=1e-12)
    assert [sun for sun, _ in estimated_error(skyview, "default")] == [
        -12.0, -10.0, -8.0, -6.0, -4.0, 0.0, 1.0, 5.0, 8.0, 10.0, 30.0, 45.0]


def test_every_measured_table_ascends_in_sun_elevation():
    """error_at interpolates with np.interp, which takes its elevations ascending and returns nonsense, not an
    error, otherwise: every measured table the renderer choice and the planner read must ascend strictly, with
    positive figures (interpolated in their logarithm)."""
    from clsky.renderer_choice import LOOKUP4D_ERROR

    tables = {"LOOKUP_ERROR": LOOKUP_ERROR, "LOOKUP4D_ERROR": LOOKUP4D_ERROR,
              "REFERENCE_RESOLUTION": REFERENCE_RESOLUTION,
              **{f"RAY_MARCH_ERROR[{k!r}]": v for k, v in RAY_MARCH_ERROR.items()},
              **{f"SKYVIEW_ON_REFERENCE[{k!r}]": v for k, v in SKYVIEW_ON_REFERENCE.items()},
              **{f"{r.method} row": r.error for r in RENDERERS if any(e for _, e in r.error)}}
    for name, table in tables.items():
        suns = [sun for sun, _ in table]
        assert suns == sorted(set(suns)), name
        assert all(error > 0.0 for _, error in table), name


def test_renderer_rows_are_hashable():
    """A row is a frozen dataclass: its measurement against the reference is kept as pairs, not a dict, which
    made hash(row) raise."""
    assert len({hash(r) for r in RENDERERS}) == len(RENDERERS)


def test_the_measured_tables_are_the_benchmarks():
    """RAY_MARCH_ERROR's level rows and SKYVIEW_ON_REFERENCE are docs/quality.csv's (bench/bench_quality.py, the
    four frames, -4 to 45 deg) and docs/quality_dusk.csv's (bench/bench_quality_dusk.py, -6 to -12 deg) figures to
    three significant digits, and the sky-view row's own error README "Sky-view table"'s worst line
    (bench/bench_skyview.py): a rerun of either shows here where the code's figures are no longer the
    benchmark's."""
    import csv

    from clsky.anim.accuracy import DUSK_ELEVATIONS, SUN_ELEVATIONS

    root = pathlib.Path(__file__).parents[1]
    measured = {}                   # {level: ({sun: ray march p95}, {sun: sky-view map p95})}
    for name, suns in (("quality.csv", SUN_ELEVATIONS), ("quality_dusk.csv", DUSK_ELEVATIONS)):
        with open(root / "docs" / name, newline="") as handle:
            for r in csv.DictReader(handle):
                march, skyview = measured.setdefault(r["level"], ({}, {}))
                march.update({sun: float(f"{float(r[f'p95_rel {frame}']):.3g}") for frame, sun in suns.items()})
                skyview.update({sun: float(f"{float(r[f'skyview p95_rel {frame}']):.3g}")
                                for frame, sun in suns.items()})
    assert set(measured) == {"draft", "default", "high"}
    for level, (march, skyview) in measured.items():
        assert RAY_MARCH_ERROR[level] == tuple(sorted(march.items())), level
        assert SKYVIEW_ON_REFERENCE[level] == tuple(sorted(skyview.items())), level
    # the reference's own estimated error: the "sum" row of its doubled groups, docs/quality_reference.csv and
    # docs/quality_dusk_reference.csv (the same runs); its suns among every level's (estimate_basis counts on it)
    resolution = {}
    for name, suns in (("quality_reference.csv", SUN_ELEVATIONS), ("quality_dusk_reference.csv", DUSK_ELEVATIONS)):
        with open(root / "docs" / name, newline="") as handle:
            rows = {r["doubled"]: r for r in csv.DictReader(handle)}
        assert set(rows) == {"sun nodes", "view axis, gather", "table quadrature", "ray march", "sum"}, name
        resolution.update({sun: float(f"{float(rows['sum'][f'change {frame}']):.3g}") for frame, sun in suns.items()})
    assert REFERENCE_RESOLUTION == tuple(sorted(resolution.items())) == RAY_MARCH_ERROR["reference"]
    for level in ("draft", "default", "high"):
        assert set(resolution) <= {sun for sun, _ in RAY_MARCH_ERROR[level]}, level
    readme = (root / "README.md").read_text(encoding="utf-8")
    section = readme.split("<!-- bench:skyview-plan -->")[1].split("<!-- /bench:skyview-plan -->")[0]
    header = next(line for line in section.splitlines() if line.startswith("| observer |"))
    worst = next(line for line in section.splitlines() if line.startswith("| **worst** |"))
    suns = [float(cell.split()[0]) for cell in header.strip("|").split("|")[2:]]
    values = [float(cell) / 100.0 for cell in worst.strip("|").split("|")[2:]]
    measured = sorted(zip(suns, values))
    assert [sun for sun, _ in row("skyview").error] == [sun for sun, _ in measured]
    assert [error for _, error in row("skyview").error] == pytest.approx([error for _, error in measured], rel=1e-12)


# The plan ------------------------------------------------------------------------------------------

def test_the_default_animation_plan_picks_the_skyview_map(cl_context):
    """The README's main job (sun -6 to 60 deg, 1 %): the sky-view map fits (0.83 % measured against the
    reference at -6 deg, 0.79 % at -4, + the reference's own estimated error: 0.97 % at -6 deg), keeping the ray
    march's quadrature for its nodes; an animation that renders the ray march anyway (compare) still gets the
    ray march's line, saying the map would do."""
    plan = plan_scene(Scene((-6.0, 60.0)), ctx=cl_context)
    assert plan.renderer == "skyview" and plan.ray is not None and plan.ray.view_steps == 48
    line = dict((topic, (decision, reason)) for topic, decision, reason in plan.decisions)["renderer"]
    assert line[0].startswith("sky-view map 64 x 128 (--method skyview), ray march, 48 samples")
    assert "table lookup's 1026 %" in line[1]
    asked = plan_scene(Scene((-6.0, 60.0)), ctx=cl_context, ray_march=True)
    line = dict((topic, (decision, reason)) for topic, decision, reason in asked.decisions)["renderer"]
    assert asked.renderer == "skyview" and line[0] == "ray march, 48 samples per ray"
    assert line[1].startswith("asked for; the sky-view map 64 x 128's 0.966 % (measured against the reference at -6 "
                              "deg, + the reference's own estimated error, 0.14 %) fits")
    # the sun axis is the ray march's: the map's nodes are ray-marched
    assert asked.table == plan.table


def test_a_tight_budget_plan_keeps_the_ray_march(cl_context):
    """By day the high level fits 0.1 % (0.052 % + the reference's 0.022 % at 45 deg), its sky-view map does not
    (0.113 % measured against the reference at 45 deg)."""
    plan = plan_scene(Scene((1.0, 60.0), error_budget=1e-3, components=("rayleigh", "mie")), ctx=cl_context)
    assert plan.renderer == "raymarch" and plan.level.name == "high"
    assert dataclasses.replace(plan, renderer="x").renderer == "x"      # a plain field of the frozen Plan


def test_a_day_plan_with_a_loose_budget_picks_the_lookup(cl_context):
    plan = plan_scene(Scene((20.0, 60.0), error_budget=0.1, components=("rayleigh", "mie")), ctx=cl_context)
    assert plan.renderer == "lut" and plan.ray is None


def test_a_day_plan_of_large_frames_picks_the_skyview_map(cl_context):
    """Both lookups fit a loose budget by day; on 1024 x 1024 fisheyes the sky-view map costs less a
    frame than the 3D table lookup (bench/bench_renderer_costs.py), so the plan takes it, with the ray
    march's quadrature for its nodes, and says why."""
    scene = Scene((20.0, 60.0), error_budget=0.1, components=("rayleigh", "mie"), pixels=FISHEYE_1024)
    plan = plan_scene(scene, ctx=cl_context)
    assert plan.renderer == "skyview" and plan.ray is not None
    decision, reason = dict((topic, (d, r)) for topic, d, r in plan.decisions)["renderer"]
    assert decision.startswith("sky-view map 64 x 128 (--method skyview)")
    lut, skyview = row("lut").frame_cpu_ms(FISHEYE_1024), row("skyview").frame_cpu_ms(FISHEYE_1024)
    assert reason.endswith(f"so does the table lookup, but it costs more a frame of {FISHEYE_1024} pixels "
                           f"({lut:.3g} against {skyview:.3g} CPU-ms, measured)")


@pytest.mark.parametrize("pixels", [0, -5, 2 ** 31, 1.5, True])
def test_scene_pixels_are_checked(pixels):
    with pytest.raises(ValueError, match=r"pixels must be an integer in \[1, 2147483647\], got"):
        Scene((20.0, 60.0), pixels=pixels)


def test_a_plan_of_tiny_frames_marches_every_pixel(cl_context):
    """Where the 3D lookup fails, the sky-view map's 64 x 128 rays cost more than marching a frame of a
    few thousand pixels: the plan takes the ray march (no error of its own beyond the level's) and says
    that the map would fit."""
    tiny = 1000
    assert row("raymarch").frame_cpu_ms(tiny) < row("skyview").frame_cpu_ms(tiny)
    plan = plan_scene(Scene((-6.0, 60.0), pixels=tiny), ctx=cl_context)
    assert plan.renderer == "raymarch" and plan.ray is not None
    reason = dict((topic, r) for topic, _, r in plan.decisions)["renderer"]
    assert "table lookup's 1026 %" in reason
    march, skyview = row("raymarch").frame_cpu_ms(tiny), row("skyview").frame_cpu_ms(tiny)
    assert reason.endswith(f"; the sky-view map's 0.966 % fits, but it costs more a frame of {tiny} pixels "
                           f"({skyview:.3g} against {march:.3g} CPU-ms, measured)")


@pytest.mark.parametrize("arguments, message", [
    (dict(level="bogus"), r"^level must be one of \['draft', 'default', 'high', 'reference'\], got 'bogus'"),
    (dict(sun_elevations_deg=(math.nan, 10.0)), r"^sun_elevations_deg must be two numbers low <= high in \[-90, 90\]"),
    (dict(sun_elevations_deg=(10.0, -6.0)), r"^sun_elevations_deg must be two numbers low <= high"),
    (dict(sun_elevations_deg=5.0), r"^sun_elevations_deg must be two numbers low <= high in \[-90, 90\], got 5"),
    (dict(budget=-1), r"^budget must be a number in \(0, 1\], got -1"),
    (dict(budget="0.1"), r"^budget must be a number in \(0, 1\]"),
    (dict(frames=-5), r"^frames must be None or an integer in \[1, 1000000000\], got -5"),
    (dict(pixels=-10**9), r"^pixels must be an integer in \[1, 2147483647\]"),
])
def test_choose_renderer_refuses_what_it_cannot_rank(arguments, message):
    """Public and in the README: a bad level was a KeyError, a NaN sun chose the ray march with a NaN
    estimate, a negative count of frames or pixels made the dearest row the cheapest."""
    with pytest.raises(ValueError, match=message):
        choose_renderer(**{"sun_elevations_deg": (0.0, 10.0), "budget": 0.01, **arguments})
    with pytest.raises(ValueError, match=r"^method must be one of \['lut', 'skyview', 'lut4d', 'raymarch'\]"):
        renderer_row("nope")                                         # was StopIteration
