"""The twilight yardstick: the ray march against the independent Monte Carlo (issue 11, item 1).

A ground observer looks at the zenith and 4 deg above the horizon toward, across (90 deg azimuth) and
away from the sun, with the sun at +5, +2, 0, -2, -4 and -6 deg elevation (:data:`SUN_ELEVATIONS_DEG`,
:data:`VIEWS`). Two independent solutions of the same atmosphere are compared there:

* the ray march (:meth:`clsky.render.SkyRenderer.render_raymarch`, single scattering per pixel and the
  table's gathered higher orders) with the table and quadrature the scene planner picks for that sun at
  a quality level (:func:`clsky.planner.plan_scene`: what ``clsky animate`` renders at that level);
* the spherical path tracer :mod:`clsky.montecarlo`, which imports nothing from clsky, run in batches of
  independent seeds until the standard error of every channel is below a target
  (:func:`monte_carlo`).

The deviation is ray march / Monte Carlo - 1 per channel (r, g, b), also in units of the Monte Carlo
standard error. Radiances are per unit solar irradiance [1/sr] (``ray march / atmosphere.incident_light``,
the tracer's unit). :func:`black_ground_without_ozone` gives the atmosphere of issue 11's measured
excess: the ``physical`` preset without ozone and with a black ground.

Used by ``bench/bench_twilight.py`` (README, "Twilight against Monte Carlo") and
``tests/test_twilight_montecarlo.py``. Nothing here changes the kernels, orders or renderer: it is the
yardstick for the fix of issue 11 item 2.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from . import montecarlo
from .atmosphere import AtmosphereParameters, as_atmosphere
from .errors import ParameterError, check_integer, is_real_number
from .planner import Scene, plan_scene
from .quality import quality_level
from .render import SkyRenderer
from .table import ScatteringTable

__all__ = ["SUN_ELEVATIONS_DEG", "VIEW_ELEVATION_DEG", "VIEWS", "Pooled", "black_ground_without_ozone",
           "view_directions", "sun_direction", "monte_carlo", "single_scattering", "ray_march", "deviation"]

#: Sun elevations of the comparison [deg] (issue 11: day's edge to the end of civil twilight's first half).
SUN_ELEVATIONS_DEG = (5.0, 2.0, 0.0, -2.0, -4.0, -6.0)
#: Elevation of the near-horizon views [deg]: low enough to see the horizon's brightening and the
#: anti-solar shadow, high enough that the view ray leaves the atmosphere far from the ground.
VIEW_ELEVATION_DEG = 4.0
#: name: (view elevation [deg], azimuth from the sun [deg])
VIEWS = {"zenith": (90.0, 0.0), "toward": (VIEW_ELEVATION_DEG, 0.0), "across": (VIEW_ELEVATION_DEG, 90.0),
         "away": (VIEW_ELEVATION_DEG, 180.0)}


def black_ground_without_ozone(atmosphere="physical") -> AtmosphereParameters:
    """The atmosphere of issue 11's measured excess: ``atmosphere`` (a preset name or parameters)
    with no ozone and a black ground (every other field unchanged)."""
    return as_atmosphere(atmosphere).replace(ozone_column_du=0.0, ground_albedo=0.0)


def _check_view(view):
    if not isinstance(view, str) or view not in VIEWS:
        raise ParameterError("view", f"one of {list(VIEWS)}", view)
    return VIEWS[view]


def _check_sun(elevation_deg):
    if not is_real_number(elevation_deg) or not -90.0 <= float(elevation_deg) <= 90.0:
        raise ParameterError("sun_elevation_deg", "a sun elevation in [-90, 90] deg", elevation_deg)
    return float(elevation_deg)


def sun_direction(elevation_deg: float) -> np.ndarray:
    """Unit vector to the sun at ``elevation_deg`` [deg], azimuth 0 (the +x axis; z is the zenith)."""
    e = math.radians(_check_sun(elevation_deg))
    return np.array([math.cos(e), 0.0, math.sin(e)])


def view_directions(views=None) -> np.ndarray:
    """(n, 3) unit view vectors of ``views`` (names of :data:`VIEWS`, all by default), sun at azimuth 0."""
    if isinstance(views, str):                  # one name: list("zenith") was six views of one letter each
        raise ParameterError("views", f"None or a list of names of {list(VIEWS)}", views)
    names = list(VIEWS) if views is None else list(views)
    out = np.empty((len(names), 3))
    for i, name in enumerate(names):
        elevation, azimuth = (math.radians(a) for a in _check_view(name))
        out[i] = (math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth),
                  math.sin(elevation))
    out[np.abs(out) < 1e-15] = 0.0
    return out / np.linalg.norm(out, axis=1)[:, None]


@dataclasses.dataclass(frozen=True)
class Pooled:
    """Monte Carlo estimate pooled over batches of independent seeds, per unit irradiance [1/sr].

    Attributes
    ----------
    radiance, standard_error : numpy.ndarray
        Shape (3,): mean of the batch means, and sqrt(mean of the batch variances of the mean / batches)
        (equal batch sizes, so this is the standard error of all paths together).
    photons : int
        Paths per channel, over all batches.
    batches : int
    truncated_weight : numpy.ndarray
        Shape (3,): weight still alive at the order cap, per photon (the bias bound of the cap).
    contributing_paths : numpy.ndarray
        Shape (3,): paths that brought light to the eye, over all batches
        (:attr:`clsky.montecarlo.MonteCarloResult.contributing_paths`).
    """

    radiance: np.ndarray
    standard_error: np.ndarray
    photons: int
    batches: int
    truncated_weight: np.ndarray
    contributing_paths: np.ndarray

    @property
    def reliable(self) -> np.ndarray:
        """Shape (3,) bool: the channels whose standard error measures their error (at least
        :data:`clsky.montecarlo.MIN_CONTRIBUTING_PATHS` contributing paths)."""
        return self.contributing_paths >= montecarlo.MIN_CONTRIBUTING_PATHS

    @property
    def relative_error(self) -> np.ndarray:
        """standard_error / radiance per channel; inf where the radiance is 0 or the standard error is no
        measure of the error (:attr:`reliable`): a few contributing paths gave 0 +- 0 or a spuriously small
        error, which stopped :func:`monte_carlo` before its target was met."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where((self.radiance > 0) & self.reliable, self.standard_error / self.radiance, np.inf)


#: Paths per channel and batch when the caller does not say (at most ``max_photons``).
DEFAULT_BATCH = 200_000


def monte_carlo(atmosphere, sun_elevation_deg, view, *, target=0.01, batch=None, max_photons=40_000_000,
                seed=0, max_orders=None) -> Pooled:
    """The tracer's radiance for one view, in batches of ``batch`` paths (seeds seed, seed + 1, ...)
    until every channel's relative standard error is at most ``target`` or ``max_photons`` paths per
    channel are spent.

    Parameters
    ----------
    atmosphere : AtmosphereParameters or str
        The atmosphere, or a preset's name.
    sun_elevation_deg : float
        Sun elevation [deg].
    view : str
        A name of :data:`VIEWS`.
    target : float
        Relative standard error to reach in every channel (0.01: 1 %).
    batch : int or None
        Paths per channel and batch (memory: about 1 kB per path alive), at most ``max_photons``; None:
        :data:`DEFAULT_BATCH`, or ``max_photons`` where that is fewer.
    max_photons : int
        Most paths per channel.
    seed : int
        Seed of the first batch (the k-th batch's is seed + k, each at most
        :data:`clsky.montecarlo.MAX_SEED`).
    max_orders : int or None
        The tracer's order cap (1: single scattering).

    Raises
    ------
    ValueError
        (:class:`~clsky.errors.ParameterError`) naming atmosphere, view, sun_elevation_deg, target,
        batch, max_photons, seed or max_orders when outside its valid range.
    """
    atmosphere = as_atmosphere(atmosphere)
    elevation, azimuth = _check_view(view)
    cos_view = math.sin(math.radians(elevation))
    cos_sun = math.sin(math.radians(_check_sun(sun_elevation_deg)))
    if not is_real_number(target) or not 0.0 <= target < 1.0:
        raise ParameterError("target", "a relative standard error in [0, 1)", target)
    max_photons = check_integer("max_photons", max_photons, 2, montecarlo.MAX_PHOTONS)
    # a first batch larger than the cap spent more paths than it (100 for max_photons = 10)
    batch = min(DEFAULT_BATCH, max_photons) if batch is None else check_integer("batch", batch, 2, max_photons)
    seed = check_integer("seed", seed, 0, montecarlo.MAX_SEED - max_photons // batch)
    max_orders = check_integer("max_orders", max_orders, 1, montecarlo.MAX_ORDERS_LIMIT, optional=True)
    means, variances, truncated, contributing = [], [], [], 0
    while True:
        result = montecarlo.simulate(atmosphere, 0.0, cos_view, cos_sun, math.radians(azimuth), photons=batch,
                                     seed=seed + len(means), max_orders=max_orders)
        means.append(result.radiance)
        variances.append(result.standard_error ** 2)
        truncated.append(result.truncated_weight)
        contributing = contributing + result.contributing_paths
        k = len(means)
        radiance = np.mean(means, axis=0)
        error = np.sqrt(np.mean(variances, axis=0) / k)
        pooled = Pooled(radiance, error, k * batch, k, np.mean(truncated, axis=0), contributing)
        if np.all(pooled.relative_error <= target) or (k + 1) * batch > max_photons:
            return pooled


def single_scattering(atmosphere, sun_elevation_deg, view) -> np.ndarray:
    """The tracer's deterministic single scattering (:func:`clsky.montecarlo.single_scattering`) for
    one view from the ground, per unit irradiance [1/sr], shape (3,); ``atmosphere`` parameters or a
    preset's name."""
    atmosphere = as_atmosphere(atmosphere)
    elevation, azimuth = _check_view(view)
    return montecarlo.single_scattering(atmosphere, 0.0, math.sin(math.radians(elevation)),
                                        math.sin(math.radians(_check_sun(sun_elevation_deg))),
                                        math.radians(azimuth))


def ray_march(atmosphere, sun_elevation_deg, views=None, *, quality="default", single=False, ctx=None,
              azimuth_harmonics=None):
    """The ray march's radiance per unit irradiance [1/sr], shape (n views, 3), and the table settings.

    The table and ray quadrature are the scene planner's for a fixed sun at ``sun_elevation_deg`` and
    the level ``quality`` (an all-sky fisheye from the ground). ``single=True`` plans the scene without
    the higher orders (the planner's table with ``orders=1``, no gathered light), so the ray march
    returns its single scattering alone, with the same ray quadrature. ``azimuth_harmonics`` (an
    integer in [0, 64], at most half the level's gather Phi steps: 16 at 'draft') replaces the planned
    table's ``azimuth_harmonics`` (the higher orders' azimuth harmonics, :mod:`clsky.azimuth`); None
    keeps the planner's. The views and the sun are checked before
    the plan and the table (a bad view name came after 11 s of both).
    """
    directions = view_directions(views)
    _check_sun(sun_elevation_deg)
    if azimuth_harmonics is not None:            # TableSettings' own check of them, before the plan's pilot
        quality_level(quality).table.replace(mode="physical", azimuth_harmonics=azimuth_harmonics)
    components = ("rayleigh", "mie") if single else ("rayleigh", "mie", "multiple")
    plan = plan_scene(Scene((sun_elevation_deg, sun_elevation_deg), components=components, quality=quality),
                      atmosphere, ctx=ctx, ray_march=True)
    settings = plan.table
    if azimuth_harmonics is not None and not single:
        settings = settings.replace(azimuth_harmonics=azimuth_harmonics)
    table = ScatteringTable.build(plan.atmosphere, settings, ctx=ctx)
    with SkyRenderer(table, plan.ray, ctx=ctx) as renderer:
        radiance = renderer.render_raymarch(directions, sun_direction(sun_elevation_deg), 0.0)
    return radiance / plan.atmosphere.incident_light, settings


def deviation(marched, pooled: Pooled):
    """(relative, in standard errors) of ``marched`` (3,) against ``pooled``: marched / MC - 1 and
    (marched - MC) / SE per channel (NaN where the tracer found no light: no estimate to compare with; the
    SEs NaN too where its standard error is no measure of its error, :attr:`Pooled.reliable`: a few paths
    showed a deviation of '+5203.7 SE')."""
    marched = np.asarray(marched, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):   # no path reached the sunlit air: NaN, not inf
        relative = np.where(pooled.radiance > 0, marched / pooled.radiance - 1.0, np.nan)
        sigmas = np.where((pooled.standard_error > 0) & pooled.reliable,
                          (marched - pooled.radiance) / pooled.standard_error, np.nan)
    return relative, sigmas
