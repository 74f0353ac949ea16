"""Quality levels (clsky/quality.py): the budget picks the level, and each level keeps its promise on
reduced frames: 24 x 24 all-sky fisheyes from the ground at the accuracy benchmark's four sun elevations
(day 45, golden hour 8, sunset 1, civil twilight -4 deg), ray-marched over the table the scene plan
builds for that sun path, against the reference of anim/accuracy.py.

The promises are about the 95th percentile of the relative HDR luminance error (README "Quality
levels"); at 24 x 24 that percentile falls on ~20 pixels, so the test frames resolve it as well as the
benchmark's 64 x 64 frames, whose numbers the README shows. The 'default' and 'high' checks need the
'reference' level's four tables (minutes to build): they are marked slow and run in .ci/run.
"""

from __future__ import annotations

import pytest

import clsky
from clsky.anim import accuracy, metrics
from clsky.anim.cameras import FisheyeCamera, sun_direction
from clsky.planner import Scene, plan_scene
from clsky.quality import QUALITY_LEVELS, level_for_budget, quality_level
from clsky.render import SkyRenderer

SIZE = 24
PATH = (min(accuracy.SUN_ELEVATIONS.values()), max(accuracy.SUN_ELEVATIONS.values()))


@pytest.mark.parametrize("budget, name", [(1.0, "draft"), (0.1, "draft"), (0.05, "default"), (0.01, "default"),
                                          (0.002, "high"), (1e-3, "high"), (5e-4, "reference"),
                                          (1e-9, "reference")])
def test_budget_picks_the_fastest_level_within_it(budget, name):
    assert level_for_budget(budget).name == name


def test_a_budget_no_level_promises_is_said_so_in_the_plan():
    """Below the reference level's 0.05 % the plan takes that level and says that it does not promise the
    budget (it said 'the fastest level within 1e-07 %')."""
    from clsky.planner import Scene, plan_scene

    def quality_line(budget):
        return plan_scene(Scene(sun_elevations_deg=(20.0, 30.0), error_budget=budget)).describe().splitlines()[1]

    assert quality_line(1e-9).split() == ["quality", "reference", "(promises", "0.05", "%", "or", "better;", "no",
                                          "level", "promises", "1e-07", "%:", "the", "most", "accurate", "one)"]
    assert quality_line(5e-4).endswith("(promises 0.05 % or better; the fastest level within 0.05 %)")


@pytest.mark.parametrize("budget", [0.0, -0.1, 1.5, float("nan"), "1%", None, True])
def test_bad_budgets_and_names_are_refused(budget):
    with pytest.raises(ValueError, match="error_budget"):
        level_for_budget(budget)
    with pytest.raises(ValueError, match="quality must be one of"):
        quality_level("best")


def test_levels_get_finer_in_every_setting():
    levels = list(QUALITY_LEVELS.values())
    assert [level.name for level in levels] == ["draft", "default", "high", "reference"]
    for coarse, fine in zip(levels, levels[1:]):
        assert fine.budget < coarse.budget
        assert fine.sun_node_spacing < coarse.sun_node_spacing
        assert fine.ray.view_steps > coarse.ray.view_steps
        assert fine.table.view_steps >= coarse.table.view_steps
        assert fine.table.order_tolerance <= coarse.table.order_tolerance
        assert all(f >= c for f, c in zip(fine.table.size[:2], coarse.table.size[:2]))
    for level in levels:
        # the level's own table is the whole axis at its spacing
        assert level.table.size[2] == level.sun_nodes(0.0, 1.0)
        assert (level.table.size[2] - 1) * level.sun_node_spacing >= 1.0
        assert level.table.mode == "physical" and level.ray.orders == 1
        # the azimuth harmonics of twilight (clsky/planner.py), and the reference's at every sun
        assert level.twilight_harmonics == 2
        assert level.table.azimuth_harmonics == (2 if level.name == "reference" else 0)


def planned_frames(name, ctx=None):
    """The four frames ray-marched over the table planned for their sun path at quality ``name``."""
    plan = plan_scene(Scene(PATH, quality=name), ctx=ctx)
    table = clsky.ScatteringTable.build(plan.atmosphere, plan.table, ctx=ctx)
    directions, valid = FisheyeCamera(SIZE).directions()
    with SkyRenderer(table, plan.level.ray, ctx=ctx) as renderer:
        return accuracy.render_frames(renderer, "raymarch", renderer.prepare(directions, valid))


def worst_error(reference, frames, valid):
    return max(metrics.compare_frames(reference[n], frames[n], valid)["p95_rel"] for n in reference)


@pytest.mark.slow      # the 'default' stand-in reference carries M = 2: ~170 s to build at load 3
def test_draft_keeps_its_promise(stand_in_reference, cl_context):
    """Against the 'default' level as a stand-in reference (it promises 1 %, so it moves the measured
    error by at most 1 % of the 10 % budget: bound 9 %). Measured against the real reference: 4.6 % at
    64 x 64, in twilight (README)."""
    reference, valid = stand_in_reference
    assert worst_error(reference, planned_frames("draft", cl_context), valid) < 0.09


@pytest.fixture(scope="module")
def reference_frames():
    return accuracy.render_reference(SIZE)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["default", "high"])
def test_level_keeps_its_promise(reference_frames, cl_context, name):
    """Each level's frames against the reference, on the four frames (down to civil twilight), held to the
    level's budget: the measurement the scene planner's figures come from. The reference's own estimated error
    (0.09 % in civil twilight, 0.02 % by day: README "Quality levels") is not added here, where it would fail
    the high level in civil twilight by construction; the planner adds it, and takes the high level's promise
    to hold down to +1 deg only (clsky.planner.promise_measured_down_to). Measured at 64 x 64 against the
    reference with the azimuth harmonics: default 0.62 % (2026-12-02; 0.70 % since its table's 128 view nodes,
    2026-12-05), high 0.081 %, worst frame (civil twilight)."""
    reference, valid = reference_frames
    assert worst_error(reference, planned_frames(name, cl_context), valid) < QUALITY_LEVELS[name].budget


@pytest.mark.slow
def test_reference_day_frame_has_converged():
    """The 'reference' level, on the day frame (its cheapest table: 58 sun nodes): doubling each group
    of its counts changes the frame by less than the level's promise of 0.05 % (measured at 64 x 64: at
    most 0.007 %; the other frames, up to 0.035 % in twilight: README)."""
    directions, valid = FisheyeCamera(SIZE).directions()
    elevation = accuracy.SUN_ELEVATIONS["day"]
    sun = sun_direction(90.0 - elevation, accuracy.SUN_AZIMUTH)

    def frame(doubled):
        with accuracy.reference_renderer(elevation, doubled) as renderer:
            return renderer.render_raymarch(renderer.prepare(directions, valid), sun, 0.0)

    base = frame(())
    for group in accuracy.REFERENCE_GROUPS:
        change = metrics.compare_frames(frame((group,)), base, valid)["p95_rel"]
        assert change < QUALITY_LEVELS["reference"].budget, group
