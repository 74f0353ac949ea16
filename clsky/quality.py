"""Named quality levels: table and ray-march settings for an error budget (``--quality``).

Each level is a promise about rendered frames: the 95th percentile of the relative HDR luminance error
of ray-marched frames, against the reference of :mod:`clsky.anim.accuracy`, on an all-sky fisheye from the
ground at four sun elevations (day, golden hour, sunset, civil twilight). The numbers come from
``bench/bench_quality.py`` and ``bench/bench_accuracy.py`` (README "Quality levels" and "Speed versus
accuracy"); ``tests/test_quality.py`` checks each level at a reduced size.

What sets a level apart (measured, README):

* The ray march's samples per ray set the error by day: 16 samples 2.5 %, 32 samples 0.7 %,
  48 samples 0.4 %, 96 samples 0.2 % (README "Speed versus accuracy", against the reference level).
* The higher orders come from the table, and in twilight they are most of the light. Their error is set
  by the spacing of the sun axis' nodes in texture coordinate w (mapping.cl): over the default
  TableSettings' whole axis of 32 nodes (0.032 apart) the ray march is 11 to 13 % off in civil twilight
  (sun 4 deg down; README "Speed versus accuracy"). Trial levels measured at 32 x 32 were 12.6 % off
  there at 0.03 (draft's other settings), 1.3 % at 0.01 (default's) and 0.17 % at 0.004 (high's, with 96
  samples): the error falls about as the spacing to the power 2.2. So a level fixes that spacing
  (:attr:`QualityLevel.sun_node_spacing`) rather than the node count: the planner (:mod:`clsky.planner`)
  spreads as many nodes as it needs over the sun angles a scene reaches. Against the reference with
  azimuth harmonics (2026-12-02, 64 x 64 frames) the default level's former 0.006 gave 1.07 % in civil
  twilight, over its promise; the other counts barely move it (96 samples 0.91 %, table steps 60 / 60
  1.14 %, order tolerance 1e-5 1.07 %, transmittance 128 x 512 1.10 %), 1.5 times the sun nodes 0.62 %:
  hence 0.004, for about 1.5 times the table build (the default animation's plan: 42.9 against 28.8 s
  wall).
* The table's view axis barely matters to the ray march, which reads only the higher orders' gathered
  source from it, a smooth function of the view cosine: doubling the reference's (with the gather's
  steps) changes its frames by 0.010-0.019 %. The default level's 128 view nodes instead of 256 (since
  2026-12-05) change its frames by 0.005-0.024 % (p95; 0.70 % against 0.67 % in civil twilight) for half
  the table build (the four frames' plan: 4.7 against 9.6 s wall); 64 view nodes with a 128 x 64 gather
  gave 0.79 % there (README "Quality levels").
* The higher orders carry the view-sun azimuth (:attr:`QualityLevel.twilight_harmonics`, M = 2) where
  the sun goes below +30 deg (the scene planner decides, :func:`clsky.planner.azimuth_harmonics`), and
  the 'reference' level carries them at every sun: the azimuth average (M = 0) is +6 % too bright at
  sunset and +134 % at -6 deg against the Monte Carlo, M = 2 within its noise (README, "Twilight
  against Monte Carlo"), so a reference without them measured convergence, not truth.
* A table lookup cannot meet these budgets below golden hour whatever its size (the 3D table has no
  azimuth: 36 % at sunset, about 1000 % in civil twilight): the levels are for the ray march, and the
  planner allows the lookup alone only where its measured error fits the budget.
"""

from __future__ import annotations

import dataclasses
import math

from .errors import ParameterError, is_real_number
from .render import RAYMARCH_DEFAULTS
from .settings import TableSettings

__all__ = ["QualityLevel", "QUALITY_LEVELS", "quality_level", "level_for_budget"]


@dataclasses.dataclass(frozen=True)
class QualityLevel:
    """A named quality: its error budget and the settings that meet it.

    Attributes
    ----------
    name : str
    budget : float
        The relative error (95th percentile of the HDR luminance error) the level promises.
    table : TableSettings
        The scattering table's settings; its sun axis' node count (``size[2]``) is the one of a whole
        sun axis at :attr:`sun_node_spacing` (a planned table covers less and needs fewer); its scatter of
        the orders takes the higher orders' source on every ``table.source_stride``-th view node (as
        ``ray``; a scene plan whose sun goes below :data:`clsky.planner.SOURCE_EVERY_NODE_BELOW_DEG` reads it
        at every node: with the stride the default and draft levels' frames were 1.2 and 10.7 % off the
        reference at -6 deg, 0.88 and 9.2 % without, README "Quality levels"), and that of the orders
        k >= 3 computes every ``table.orders_sun_stride``-th sun node (2 for
        'default' and 'high': 14-16 % less of their build's CPU time for a change of their frames of at most
        3.4e-4 and 8.3e-5; 'draft', whose build of half a second it left unchanged, and 'reference' 1).
    sun_node_spacing : float
        Largest spacing of the sun axis' nodes in texture coordinate w.
    ray : TableSettings
        The ray march's quadrature (samples per ray = ``ray.view_steps``; the higher orders' source on
        every ``ray.source_stride``-th of them: 2 for 'draft' and 'default', 1 for the others).
    twilight_harmonics : int
        The azimuth harmonics M of the higher orders (``TableSettings.azimuth_harmonics``,
        :mod:`clsky.azimuth`) that the scene planner gives a table whose sun goes below
        :data:`clsky.planner.HARMONICS_BELOW_DEG`; ``table.azimuth_harmonics`` is the level's choice at
        every sun (the 'reference' level's 2; the others' 0, the azimuth average, right by day).
    """

    name: str
    budget: float
    table: TableSettings
    sun_node_spacing: float
    ray: TableSettings
    twilight_harmonics: int = 2

    def sun_nodes(self, w_low=0.0, w_high=1.0) -> int:
        """Sun-axis nodes that keep the spacing over [w_low, w_high] (at least 4)."""
        return max(4, math.ceil((w_high - w_low) / self.sun_node_spacing - 1e-9) + 1)


def _level(name, budget, size_wh, spacing, samples, source_stride=1, **table):
    base = TableSettings(mode="physical", source_stride=source_stride, **table)
    ray = RAYMARCH_DEFAULTS.replace(view_steps=samples, source_stride=source_stride)
    level = QualityLevel(name, budget, base, spacing, ray)
    return dataclasses.replace(level, table=base.replace(size=size_wh + (level.sun_nodes(),)))


#: The levels, fastest first.
QUALITY_LEVELS = {
    level.name: level for level in (
        _level("draft", 0.10, (16, 128), 0.015, 16, source_stride=2, view_steps=15, multiple_view_steps=10,
               sun_steps=15, gather_theta_steps=64, gather_phi_steps=32, order_tolerance=1e-2),
        _level("default", 0.01, (32, 128), 0.004, 48, source_stride=2, orders_sun_stride=2),
        _level("high", 1e-3, (32, 256), 0.002, 128, view_steps=60, multiple_view_steps=40, sun_steps=60,
               order_tolerance=1e-5, orders_sun_stride=2),
        _level("reference", 5e-4, (32, 256), 0.0015, 256, view_steps=120, multiple_view_steps=None,
               sun_steps=240, transmittance_size=(128, 512), order_tolerance=1e-5, azimuth_harmonics=2),
    )
}


def quality_level(name: str) -> QualityLevel:
    """The level called ``name``; ValueError lists the valid names."""
    if not isinstance(name, str) or name not in QUALITY_LEVELS:
        raise ParameterError("quality", f"one of {list(QUALITY_LEVELS)}", name)
    return QUALITY_LEVELS[name]


def level_for_budget(budget: float) -> QualityLevel:
    """The fastest level whose promised error fits ``budget`` (a relative error in (0, 1]); the reference
    level, the most accurate, where none does (the scene plan says so)."""
    if not is_real_number(budget) or not 0.0 < budget <= 1.0:
        raise ParameterError("error_budget", "a relative error in (0, 1]", budget)
    fitting = [level for level in QUALITY_LEVELS.values() if level.budget <= budget]
    return fitting[0] if fitting else QUALITY_LEVELS["reference"]
