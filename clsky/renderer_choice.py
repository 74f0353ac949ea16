"""Which renderer a scene's frames need: the cheapest whose measured error fits the error budget.

One row per renderer (:data:`RENDERERS`): its ``--method`` name, its measured cost a frame (a part per
frame and a part per pixel) and its measured error against sun elevation, with where each figure comes
from. :func:`choose_renderer` takes
the cheapest row whose estimated error over the scene's sun path fits the budget; the ray march, the
plan's reference, when none does. A new renderer is one more row: its cost, its errors and whether they
add to the ray march's.

A row's cost is its own table's build (``build_cpu_s``: 0 for the rows that read the plan's 3D table or
none) plus ``frames`` times its cost per frame: a part per frame (``fixed_cpu_ms``: the sky-view map's own
ray march) and a part per rendered pixel (``pixel_cpu_ns``), measured side by side by
bench/bench_renderer_costs.py (README "Scene plan"). So which row is the cheaper depends on the frame's
pixels (:class:`clsky.planner.Scene`'s ``pixels``): the sky-view map's map costs about 14 ms whatever the
frame and its reading 18 ns a pixel, the 3D table lookup 39 ns a pixel, so the lookup is the cheaper below
about 630 000 pixels (an all-sky fisheye about 900 pixels a side) and the map above, where it is both
cheaper and closer to the ray march; the ray march, 1.6 us a pixel, costs less than the map's own march
below about 7900 pixels (a fisheye about 100 pixels a side). The 4D table lookup (``'lut4d'``) needs a
table of its own, 12 CPU-s to build for the default scene, and reads 46 ns a pixel: it saves 7.4 ms a frame
against the sky-view map on the default 512 x 512 fisheye, so it pays from about 1700 frames on there, and
it costs more than the map from about 470 000 pixels on. The scene plan does not know how many frames it
serves (:class:`clsky.planner.Scene` has no frame count), so it calls :func:`choose_renderer` with
``frames=None``, which leaves out every row with a build of its own: the plan never picks 'lut4d'
(``clsky animate --method lut4d`` / ``compare4d`` asks for it). A caller that knows the frame count passes
it and the build is counted.

A row's error is either its own error against the reference frames (``on_ray_march=False``: the 3D
lookup replaces the ray march; README "Speed versus accuracy") or what it adds to the ray march its
frames are made from (``on_ray_march=True``: the sky-view map is the ray march read at its nodes,
README "Sky-view table"). The latter is estimated as the quality level's measured ray-march error
(:data:`RAY_MARCH_ERROR`) plus the row's: errors of one sign in the worst case, so a bound.
Between the measured elevations the error is interpolated in log error; beyond them, the nearest
value; over a sun path, the worst of the path's ends and of the measured elevations inside it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .errors import check_choice, check_integer, check_range, check_real

__all__ = ["RendererRow", "RENDERERS", "DEFAULT_PIXELS", "LOOKUP4D_ERROR", "RAY_MARCH_ERROR", "LOOKUP_ERROR",
           "renderer_row", "choose_renderer", "error_over"]

#: Measured error of the 3D table lookup (95th percentile, relative, default table, 64 x 64 all-sky fisheye
#: from the ground, physical preset with ozone and ground, the harmonics M = 2 in the table and the
#: reference; README "Speed versus accuracy", 2026-12-02) by sun elevation [deg]: it grows toward the
#: horizon, where the missing azimuth of the 3D table dominates, whatever the table's size (the sweep
#: against the azimuth-averaged reference, earlier that day: 4.99, 0.381, 0.0417, 0.0105).
LOOKUP_ERROR = ((-4.0, 10.26), (1.0, 0.361), (8.0, 0.0419), (45.0, 0.0141))

#: Measured error of each quality level's ray march against the reference (p95, 64 x 64 fisheye from the
#: ground, the level planned for the sun path -4 to 45 deg; README "Quality levels", bench/bench_quality.py,
#: the reference with the azimuth harmonics at every sun and the levels with them below +30 deg) by sun
#: elevation [deg]: draft and default 2026-12-03, with their higher orders' source on every other node in
#: the ray march and in the table's scatter (0.0607 / 0.0169 / 0.0253 / 0.0289 and 0.0060 / 0.0020 / 0.0030 /
#: 0.0036 with the stride in the ray march alone; 0.0602 / 0.0176 / 0.0259 / 0.0289 and 0.0062 / 0.0021 /
#: 0.0031 / 0.0037 on every node), the default again 2026-12-05 with its table's 128 view nodes (0.0067 /
#: 0.0017 / 0.0028 / 0.0035 with 256), high 2026-12-02;
#: the reference level's: how far the reference converged (its ray march's counts doubled; the other
#: groups were not doubled in that run, README). Below -4 deg the nearest value is taken here: the
#: measurements there (:data:`clsky.planner.ERRORS_MEASURED_BELOW`, 2026-12-07) choose the quality level, not
#: yet the renderer (with the default level's 0.88 % at -6 deg, the default animation's sky-view map would be
#: estimated at 1.04 %, over its budget, and the plan would pick the ray march).
RAY_MARCH_ERROR = {
    "draft": ((-4.0, 0.0627), (1.0, 0.0158), (8.0, 0.0247), (45.0, 0.0286)),
    "default": ((-4.0, 0.0070), (1.0, 0.0018), (8.0, 0.0029), (45.0, 0.0035)),
    "high": ((-4.0, 0.0008), (1.0, 0.0003), (8.0, 0.0004), (45.0, 0.0005)),
    "reference": ((-4.0, 0.0003), (1.0, 0.00005), (8.0, 0.00007), (45.0, 0.00007)),
}


#: Measured error of the 4D table lookup (p95 against the ray march of the table's own orders, 1024^2 fisheye
#: from the ground, 16 x 128 x 128 x 16 table, physical preset; README "The 4D table", bench/bench_lookup4d.py,
#: 2026-12-02) by sun elevation [deg]: 0.58 % at +30, 0.34 % at +5, 0.32 % at 0, 2.13 % at -4, 3.9 % at -6.
LOOKUP4D_ERROR = ((-6.0, 0.039), (-4.0, 0.0213), (0.0, 0.0032), (5.0, 0.0034), (30.0, 0.0058))


#: Rendered pixels a frame when the caller does not say: the default animation's 512 x 512 fisheye
#: (its all-sky disc: :class:`clsky.anim.cameras.FisheyeCamera`).
DEFAULT_PIXELS = 205892


@dataclasses.dataclass(frozen=True)
class RendererRow:
    """One renderer the plan may pick.

    Attributes
    ----------
    method : str
        Its ``clsky animate --method`` name.
    description : str
        As the plan prints it.
    fixed_cpu_ms : float
        Process CPU time of a frame that does not depend on its pixels [ms] (the sky-view map's own march).
    pixel_cpu_ns : float
        Process CPU time per rendered pixel [ns]: a frame of N pixels costs fixed_cpu_ms + N pixel_cpu_ns
        (:meth:`frame_cpu_ms`; measured, bench/bench_renderer_costs.py).
    error : tuple of (sun elevation [deg], p95 relative error)
        Its measured error (see the module docstring), ascending in elevation.
    on_ray_march : bool
        True when ``error`` adds to the ray march's (its frames are made from the ray march).
    source : str
        Where the figures come from.
    build_cpu_s : float
        Process CPU time of the table of its own that it needs [s] (0: none, or the plan's 3D table,
        which every renderer's plan builds).
    """

    method: str
    description: str
    fixed_cpu_ms: float
    pixel_cpu_ns: float
    error: tuple
    on_ray_march: bool
    source: str
    build_cpu_s: float = 0.0

    def frame_cpu_ms(self, pixels):
        """Process CPU time [ms] of one frame of ``pixels`` rendered pixels."""
        return self.fixed_cpu_ms + pixels * self.pixel_cpu_ns * 1e-6

    def cost_cpu_s(self, frames, pixels):
        """Process CPU time [s] of ``frames`` frames of ``pixels`` pixels: the build plus the frames."""
        return self.build_cpu_s + frames * self.frame_cpu_ms(pixels) / 1000.0


#: The renderers, with their measured costs and errors. Costs: process CPU of a frame from the ground (HDR
#: frame on the host), bench/bench_renderer_costs.py (README "Scene plan"), 2026-12-06, Intel Xeon, 2 cores,
#: PoCL, the default animation's planned table (32 x 128 x 208, M = 2) and ray march; a line through
#: fisheyes of 256, 512 and 1024 pixels a side (within 2 % of each); one frame a call (an animation
#: marches its sky-view maps and ray march four suns a launch on a CPU, cheaper a frame). A run minutes
#: before, in the machine's slow state, measured every cost 10-25 % higher and the crossovers between rows
#: within 5 % of these. The sky-view map's errors: p95 against the per-pixel ray march, the worst of the
#: ground and 10 km (tests/test_skyview.py: 0.080 / 0.139 % at +30 deg, 0.077 / 0.141 % at +5, 0.094 /
#: 0.145 % at 0, 0.092 / 0.164 % at -4).
RENDERERS = (
    RendererRow("lut", "table lookup", 1.0, 38.5, LOOKUP_ERROR, False,
                "README 'Speed versus accuracy' (error) and 'Scene plan' (cost)"),
    RendererRow("skyview", "sky-view map 64 x 128", 13.8, 18.2,
                ((-4.0, 0.00164), (0.0, 0.00145), (5.0, 0.00141), (30.0, 0.00139)), True,
                "tests/test_skyview.py (error against the ray march); README 'Scene plan' (cost)"),
    RendererRow("lut4d", "4D table lookup", 0.8, 45.6, LOOKUP4D_ERROR, True,
                "README 'The 4D table' (error against the ray march of its orders); README 'Scene plan' (cost and "
                "build)", build_cpu_s=12.4),
    RendererRow("raymarch", "ray march", 1.5, 1574.3, ((0.0, 0.0),), True,
                "README 'Scene plan' (cost); the plan's reference: its error is the quality level's "
                "(RAY_MARCH_ERROR)"),
)


def error_over(error, low, high):
    """The worst of ``error`` ((elevation, p95), ...) over sun elevations [low, high] [deg]: at both ends
    and at the measured elevations between them, interpolated in log error (nearest value beyond)."""
    elevations, values = (np.asarray(v, dtype=float) for v in zip(*error))
    at = np.concatenate([[low, high], elevations[(elevations > low) & (elevations < high)]])
    if np.all(values > 0.0):
        return float(np.exp(np.interp(at, elevations, np.log(values))).max())
    return float(np.interp(at, elevations, values).max())


def renderer_row(method, rows=RENDERERS) -> RendererRow:
    """The row of ``rows`` whose ``--method`` name is ``method`` (ParameterError for a name of none)."""
    check_choice("method", method, [row.method for row in rows])
    return next(row for row in rows if row.method == method)


def choose_renderer(sun_elevations_deg, budget, level="default", rows=RENDERERS, frames=None, pixels=DEFAULT_PIXELS):
    """(row, estimated error, {method: estimated error}): the cheapest row of ``rows`` whose estimated
    error over the sun path ``sun_elevations_deg`` = (low, high) [deg] fits ``budget`` (relative), for
    the ray march of quality level ``level`` (a name of :data:`RAY_MARCH_ERROR`); the 'raymarch' row
    when none fits. The cost of ``frames`` frames of ``pixels`` rendered pixels each
    (:meth:`RendererRow.cost_cpu_s`) decides; with ``frames=None`` (the frame count unknown) the rows
    with a build of their own are left out (module docstring) and the cost of one frame decides.
    ValueError naming an argument that is no such value: the path's elevations in [-90, 90], low <=
    high; the budget in (0, 1]; frames and pixels at least 1 (a negative count made the dearest row
    cheapest)."""
    low, high = check_range("sun_elevations_deg", sun_elevations_deg, -90.0, 90.0)
    check_real("budget", budget, 0.0, 1.0, low_open=True)
    check_choice("level", level, list(RAY_MARCH_ERROR))
    check_integer("frames", frames, 1, 10**9, optional=True)
    check_integer("pixels", pixels, 1, 2**31 - 1)
    march = error_over(RAY_MARCH_ERROR[level], low, high)
    estimates = {row.method: error_over(row.error, low, high) + (march if row.on_ray_march else 0.0)
                 for row in rows}
    candidates = [row for row in rows if frames is not None or row.build_cpu_s == 0.0]
    for row in sorted(candidates, key=lambda r: r.cost_cpu_s(1 if frames is None else frames, pixels)):
        if estimates[row.method] <= budget:
            return row, estimates[row.method], estimates
    fallback = renderer_row("raymarch", rows)
    return fallback, estimates[fallback.method], estimates
