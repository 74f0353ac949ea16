"""The scene plan's choice of renderer (clsky/renderer_choice.py, clsky/planner.py): the cheapest whose
measured error over the sun path fits the budget."""

from __future__ import annotations

import dataclasses
import math

import pytest

from clsky.planner import Scene, plan_scene
from clsky.renderer_choice import LOOKUP_ERROR, RAY_MARCH_ERROR, RENDERERS, RendererRow, choose_renderer, error_over


def row(method):
    return next(r for r in RENDERERS if r.method == method)


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


def test_rows_are_measured_and_ordered_by_cost():
    methods = [r.method for r in RENDERERS]
    assert methods == ["lut", "skyview", "lut4d", "raymarch"]
    # the rows that read the plan's table or none: ordered by their cost per frame
    costs = [r.frame_cpu_ms for r in RENDERERS if r.build_cpu_s == 0.0]
    assert costs == sorted(costs) and all(r.frame_cpu_ms > 0 for r in RENDERERS)
    # the 4D lookup: cheaper per frame than either lookup, but its own table costs 15 CPU-s (README "The 4D table")
    assert row("lut4d").frame_cpu_ms < row("lut").frame_cpu_ms and row("lut4d").build_cpu_s == 15.0
    assert all(r.source for r in RENDERERS)
    assert set(RAY_MARCH_ERROR) == {"draft", "default", "high", "reference"}


@pytest.mark.parametrize("path, budget, level, expected", [
    ((20.0, 60.0), 0.1, "draft", "lut"),           # by day the lookup is within 4.2 % (measured at +8 deg)
    ((-6.0, 60.0), 0.01, "default", "skyview"),    # the lookup's 1026 % fails; 0.62 % + the map's fits
    ((-6.0, 60.0), 1e-3, "high", "raymarch"),      # 0.08 % + the map's 0.16 % exceeds 0.1 %
    ((-6.0, 60.0), 0.1, "draft", "skyview"),       # 6.0 % + the map's fits 10 %
])
def test_choice_is_the_cheapest_that_fits(path, budget, level, expected):
    chosen, estimate, estimates = choose_renderer(path, budget, level)
    assert chosen.method == expected
    assert estimate == estimates[expected]
    cheaper = [r for r in RENDERERS if r.frame_cpu_ms < chosen.frame_cpu_ms and r.build_cpu_s == 0.0]
    assert all(estimates[r.method] > budget for r in cheaper)
    if expected != "raymarch":
        assert estimate <= budget


def test_a_new_renderer_is_one_row():
    """A renderer without a table of its own enters as one row and wins where it is the cheapest that
    fits: here, cheaper than the sky-view map and within the budget in twilight."""
    other = RendererRow("other", "another lookup", 0.5 * (row("lut").frame_cpu_ms + row("skyview").frame_cpu_ms),
                        ((-4.0, 0.02), (45.0, 0.005)), False, "a test row")
    rows = RENDERERS + (other,)
    assert choose_renderer((-6.0, 60.0), 0.03, "default", rows)[0].method == "other"
    assert choose_renderer((-6.0, 60.0), 0.01, "default", rows)[0].method == "skyview"
    assert choose_renderer((20.0, 60.0), 0.1, "draft", rows)[0].method == "lut"


def test_the_4d_lookup_counts_its_table_build():
    """Down to -6 deg the 4D lookup's 3.9 % plus the default ray march's 0.70 % fits a 5 % budget, and its
    33 ms per frame beat the sky-view map's 74.4 ms; but its table costs 15 CPU-s, so it wins only from
    15 / (0.0744 - 0.033) = 362 frames on. Without a frame count (the scene plan) it is left out."""
    path, budget = (-6.0, 60.0), 0.05
    chosen, _, estimates = choose_renderer(path, budget, "default")
    assert estimates["lut4d"] == pytest.approx(0.039 + 0.0070, rel=1e-12) and estimates["lut4d"] <= budget
    assert chosen.method == "skyview"                                    # frames unknown: no build counted
    assert choose_renderer(path, budget, "default", frames=120)[0].method == "skyview"     # 19 s against 9 s
    assert choose_renderer(path, budget, "default", frames=350)[0].method == "skyview"
    assert choose_renderer(path, budget, "default", frames=370)[0].method == "lut4d"
    assert row("lut4d").cost_cpu_s(370) == pytest.approx(15.0 + 370 * 0.033, rel=1e-12)
    # where it does not fit (1 %: its own 3.9 % at -6 deg), no frame count makes it win
    assert choose_renderer(path, 0.01, "default", frames=100000)[0].method == "skyview"


def test_nothing_fits_falls_back_to_the_ray_march():
    chosen, estimate, _ = choose_renderer((-6.0, 60.0), 1e-5, "reference")
    assert chosen.method == "raymarch" and estimate == pytest.approx(3.0e-4)


# The plan ------------------------------------------------------------------------------------------

def test_the_default_animation_plan_picks_the_skyview_map(cl_context):
    """The README's main job (sun -6 to 60 deg, 1 %): the sky-view map fits (0.70 % + 0.16 % at -4 deg and
    below), keeping the ray march's quadrature for its nodes; an animation that renders the ray march
    anyway (compare) still gets the ray march's line, saying the map would do."""
    plan = plan_scene(Scene((-6.0, 60.0)), ctx=cl_context)
    assert plan.renderer == "skyview" and plan.ray is not None and plan.ray.view_steps == 48
    line = dict((topic, (decision, reason)) for topic, decision, reason in plan.decisions)["renderer"]
    assert line[0].startswith("sky-view map 64 x 128 (--method skyview), ray march, 48 samples")
    assert "table lookup's 1026 %" in line[1]
    asked = plan_scene(Scene((-6.0, 60.0)), ctx=cl_context, ray_march=True)
    line = dict((topic, (decision, reason)) for topic, decision, reason in asked.decisions)["renderer"]
    assert asked.renderer == "skyview" and line[0] == "ray march, 48 samples per ray"
    assert line[1].startswith("asked for; the sky-view map 64 x 128's 0.86 % (estimated")
    # the sun axis is the ray march's: the map's nodes are ray-marched
    assert asked.table == plan.table


def test_a_tight_budget_plan_keeps_the_ray_march(cl_context):
    plan = plan_scene(Scene((-6.0, 60.0), error_budget=1e-3, components=("rayleigh", "mie")), ctx=cl_context)
    assert plan.renderer == "raymarch" and plan.level.name == "high"
    assert dataclasses.replace(plan, renderer="x").renderer == "x"      # a plain field of the frozen Plan


def test_a_day_plan_with_a_loose_budget_picks_the_lookup(cl_context):
    plan = plan_scene(Scene((20.0, 60.0), error_budget=0.1, components=("rayleigh", "mie")), ctx=cl_context)
    assert plan.renderer == "lut" and plan.ray is None
