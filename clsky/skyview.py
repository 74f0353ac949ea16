"""A per-frame sky-view map (Hillaire 2020): ray-march a small 2D map once per frame, sample it per pixel.

For each frame the sky seen from the observer's altitude h is ray-marched (the all-orders ray march of
:meth:`clsky.render.SkyRenderer.render_raymarch`, called on the map's node directions, without the sun's
disc) on a 2D map of view zenith angle theta x azimuth phi relative to the sun's vertical plane; every
pixel of any camera then reads it bilinearly (``kernels/skyview.cl``: ``render_skyview``; NumPy twin
:func:`clsky.reference.render_skyview`) and adds the sun's disc itself.

Mapping (after Hillaire 2020, sec. 5.3, and ``SkyViewLutParamsToUv`` in his
``Resources/RenderSkyCommon.hlsl``; written here from the equations):

* Rows. The horizon's zenith angle theta_H = acos(mu_H), mu_H = -sqrt(h (2 Rp + h)) / (Rp + h)
  (:func:`clsky.reference.horizon_cos`), splits the map into ``sky_rows`` rows of rays that leave the
  atmosphere (theta in [0, theta_H]) and ``ground_rows`` rows of rays that hit the ground (theta in
  [theta_H, pi], beta = pi - theta_H), each half with its own nodes at both of its ends:
  sky  t = 1 - sqrt(1 - theta / theta_H),  row = t (sky_rows - 1);
  ground  t = sqrt((theta - theta_H) / beta),  row = sky_rows + t (ground_rows - 1).
  Both put nodes densest at the horizon, where the radiance changes fastest (the ray length to the ground
  goes as sqrt(theta - theta_H), which the ground mapping makes linear). A pixel interpolates within its
  half only: nothing is interpolated across the horizon (a pixel with mu_v < mu_H is in the ground half).
  Both halves have a row at theta_H; each is marched :data:`HORIZON_EDGE_RAD` on its own side of the
  horizon (the limits from above and from below), so that no rounding of mu_H can put it in the wrong half.
* Columns: phi in [0, pi] (the atmosphere is symmetric about the sun's vertical plane, so phi and -phi
  look alike): 'linear' u = phi / pi, or 'sun' u = sin(phi / 2) = sqrt((1 - cos phi) / 2) (Hillaire's,
  denser toward the sun's azimuth), column = u (W - 1).

The map's radiance depends on (h, mu_v, mu_s, nu) only, so its nodes are laid out in a canonical frame
(the sun's azimuth along +x): the node directions depend on the altitude and the map's settings alone and
are uploaded once (:meth:`clsky.render.SkyRenderer.skyview_map`).

References
----------
S. Hillaire, "A Scalable and Production Ready Sky and Atmosphere Rendering Technique", Computer Graphics
Forum 39(4) (EGSR 2020), doi:10.1111/cgf.14050; code: github.com/sebh/UnrealEngineSkyAtmosphere.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .errors import ParameterError, check_choice, check_integer, ordered_items

__all__ = ["SkyViewSettings", "AZIMUTH_MAPPINGS", "horizon", "row_angles", "column_azimuths",
           "node_directions", "canonical_sun", "check_size", "DEFAULT_SIZE", "HORIZON_EDGE_RAD"]

#: Azimuth mappings and their kernel codes.
AZIMUTH_MAPPINGS = {"linear": 0, "sun": 1}
#: Default map size (W azimuth columns, H rows: sky and ground halves of H // 2 rows each, the sky's
#: rounded up): measured in README "Sky-view table".
DEFAULT_SIZE = (64, 128)
#: How far from the horizon [rad] its two rows are marched, each on its own side: the limits from above
#: and below. A ray that hits the ground there is shorter than the grazing one by about
#: r sqrt(2 |mu_H| eps) (70 m of 357 km from 10 km), and |mu - mu_H| = eps sin(theta_H) is some 1e7
#: times the rounding of mu_H.
HORIZON_EDGE_RAD = 1e-9
#: Largest map side (nodes).
MAX_SIDE = 4096


@dataclasses.dataclass(frozen=True)
class SkyViewSettings:
    """The sky-view map's size and azimuth mapping.

    Parameters
    ----------
    size : (W, H)
        W azimuth columns over [0, pi] in [2, 4096]; H rows in [4, 4096]: ceil(H / 2) sky rows
        (zenith to horizon), floor(H / 2) ground rows (horizon to nadir).
    azimuth_mapping : {'linear', 'sun'}
        Column placement (module docstring); 'sun' (default), Hillaire's: within 10 deg of the sun
        (the Mie aureole) it halves the error of 'linear' at 32 to 64 columns (p95 0.56 % against 1.01 %
        with the sun at +30 deg, 0.59 % against 1.52 % at +5 deg, 64 x 128 map, 256^2 fisheye against
        the per-pixel ray march), for 0.08 % against 0.07 % over the whole sky (README "Sky-view table").

    Raises
    ------
    ValueError
        (:class:`~clsky.errors.ParameterError`) naming ``size`` (with its index) or ``azimuth_mapping``.
    """

    size: tuple = DEFAULT_SIZE
    azimuth_mapping: str = "sun"

    def __post_init__(self):
        object.__setattr__(self, "size", check_size("size", self.size))
        check_choice("azimuth_mapping", self.azimuth_mapping, tuple(AZIMUTH_MAPPINGS))

    @property
    def sky_rows(self) -> int:
        return self.size[1] - self.size[1] // 2

    @property
    def ground_rows(self) -> int:
        return self.size[1] // 2


def check_size(name, value):
    """(W, H) ints, W in [2, 4096] and H in [4, 4096], from an ordered pair of integers (a tuple, a list, a
    1D array: :func:`clsky.errors.ordered_items`); ParameterError names ``name`` (and the item)."""
    items = ordered_items(value)         # a set's items in hash order: {33, 128} was (128, 33)
    if items is None or len(items) != 2:
        raise ParameterError(name, "two integers (W, H)", value)
    return (check_integer(name, items[0], 2, MAX_SIDE, index=0), check_integer(name, items[1], 4, MAX_SIDE, index=1))


def horizon(altitude, planet_radius):
    """(mu_H, theta_H [rad]): cosine and zenith angle of the horizon seen from ``altitude`` [m]."""
    from .reference import horizon_cos

    mu = float(horizon_cos(float(altitude), planet_radius))
    return mu, math.acos(mu)


def row_angles(settings: SkyViewSettings, horizon_angle):
    """View zenith angles [rad] of the map's rows, (H,): sky half then ground half (module docstring);
    the ground half's first row at the horizon itself (its limit from below is marched)."""
    t = np.linspace(0.0, 1.0, settings.sky_rows)
    sky = horizon_angle * (1.0 - (1.0 - t) ** 2)
    t = np.linspace(0.0, 1.0, settings.ground_rows)
    ground = horizon_angle + (math.pi - horizon_angle) * t * t
    sky[-1], ground[0] = horizon_angle, horizon_angle
    return np.concatenate([sky, ground])


def column_azimuths(settings: SkyViewSettings):
    """Azimuths [rad] from the sun's vertical plane of the map's columns, (W,), in [0, pi]."""
    u = np.linspace(0.0, 1.0, settings.size[0])
    if settings.azimuth_mapping == "sun":
        return 2.0 * np.arcsin(u)
    return math.pi * u


def node_directions(settings: SkyViewSettings, altitude, planet_radius):
    """Unit node directions (H, W, 3) of the map in the canonical frame (sun azimuth along +x, z the
    zenith); the two horizon rows point :data:`HORIZON_EDGE_RAD` above and below the horizon."""
    _, angle = horizon(altitude, planet_radius)
    theta = row_angles(settings, angle)
    theta[settings.sky_rows - 1] -= HORIZON_EDGE_RAD
    theta[settings.sky_rows] += HORIZON_EDGE_RAD
    phi = column_azimuths(settings)
    sin_theta = np.sin(theta)[:, None]
    return np.stack(np.broadcast_arrays(sin_theta * np.cos(phi), sin_theta * np.sin(phi), np.cos(theta)[:, None]),
                    axis=-1)


def canonical_sun(sun_direction):
    """The sun direction turned about the zenith into the map's frame: (hypot(x, y), 0, z)."""
    sun = np.asarray(sun_direction, dtype=np.float64)
    return np.array([math.hypot(sun[0], sun[1]), 0.0, sun[2]])
