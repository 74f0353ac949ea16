"""Cameras: one unit view direction per pixel, in the observer's local frame.

Frame and conventions shared by every camera and by :mod:`clsky.anim.sunpath`:

- x = east, y = north, z = up (zenith): a right-handed East-North-Up (ENU) frame.
- Azimuth phi is measured from north, clockwise seen from above (north 0, east 90, south 180,
  west 270 degrees), as a compass bearing and as pvlib's solar azimuth. Zenith angle theta is
  measured from the zenith, elevation = 90 deg - theta.
- The direction of (theta, phi) is ``(sin theta sin phi, sin theta cos phi, cos theta)``.
- Images are ``(height, width)`` arrays, row 0 at the top, column 0 on the left; every direction is
  taken at a pixel centre.

Every camera has ``width``, ``height`` and ``name`` and a method ``directions()`` returning
``(dirs, valid)``: ``dirs`` float64 of shape ``(height, width, 3)`` (unit vectors; invalid pixels get
the zenith ``(0, 0, 1)``, a harmless direction) and ``valid`` bool of shape ``(height, width)``.

Examples
--------
>>> from clsky.anim.cameras import camera_from_name
>>> camera = camera_from_name("fisheye", 65, 65)
>>> dirs, valid = camera.directions()
>>> dirs.shape, valid.shape
((65, 65, 3), (65, 65))
>>> float(dirs[32, 32, 2])                    # the centre pixel looks at the zenith (z = 1)
1.0
"""

from __future__ import annotations

import abc
import dataclasses
import math
from typing import ClassVar

import numpy as np

from clsky.errors import as_real_array, short

from clsky.errors import check_integer, check_real

__all__ = ["Camera", "FisheyeCamera", "PerspectiveCamera", "EquirectangularCamera", "CAMERAS",
           "camera_from_name", "sun_direction", "MIN_SIZE", "MAX_SIZE"]

#: Valid range of image sizes [pixels], inclusive.
MIN_SIZE, MAX_SIZE = 2, 16384


# Validation ---------------------------------------------------------------------------------------

def _check_size(name, value):
    return check_integer(name, value, MIN_SIZE, MAX_SIZE)


# Directions ---------------------------------------------------------------------------------------

def _direction(zenith_rad, azimuth_rad):
    """Unit vectors (..., 3) of zenith angles and azimuths [rad] (azimuth clockwise from north)."""
    sin_zenith = np.sin(zenith_rad)
    return np.stack(np.broadcast_arrays(sin_zenith * np.sin(azimuth_rad),
                                        sin_zenith * np.cos(azimuth_rad),
                                        np.cos(zenith_rad)), axis=-1)


def sun_direction(zenith_deg, azimuth_deg):
    """Unit vector toward the sun in the local East-North-Up frame.

    Parameters
    ----------
    zenith_deg : float or array_like
        Sun zenith angle [deg], in [0, 180].
    azimuth_deg : float or array_like
        Sun azimuth [deg], from north clockwise seen from above (east = 90), in [-360, 720]
        (:data:`AZIMUTH_RANGE_DEG`).

    Returns
    -------
    numpy.ndarray
        float64, shape ``(3,)`` for scalars (``broadcast shape + (3,)`` for arrays): (east, north, up).

    Raises
    ------
    ValueError
        If an angle is outside its range (NaN and infinities too).

    Notes
    -----
    ``d = (sin theta sin phi, sin theta cos phi, cos theta)`` with theta the zenith angle and phi
    the azimuth.

    Examples
    --------
    >>> [round(float(c), 12) for c in sun_direction(90.0, 90.0)]       # on the horizon, due east
    [1.0, 0.0, 0.0]
    >>> [round(float(c), 12) for c in sun_direction(60.0, 180.0)]      # 30 deg high, due south
    [0.0, -0.866025403784, 0.5]
    """
    # a string was NumPy's message, 10**400 an OverflowError, 1j a TypeError, and True was 1 deg
    zenith, azimuth = (as_real_array(name, value, "a real number of degrees or an array of them")
                       for name, value in (("zenith_deg", zenith_deg), ("azimuth_deg", azimuth_deg)))
    # a zenith angle of -10 deg was a sun 80 deg up on the other side, 1e300 deg one of no precision
    if not np.all((zenith >= 0.0) & (zenith <= 180.0)):
        raise ValueError(f"zenith_deg must be in [0, 180] degrees, got {short(zenith_deg)}")
    low, high = AZIMUTH_RANGE_DEG
    if not np.all((azimuth >= low) & (azimuth <= high)):
        raise ValueError(f"azimuth_deg must be in [{low:g}, {high:g}] degrees, got {short(azimuth_deg)}")
    return _direction(np.radians(zenith), np.radians(azimuth))


def _radiance_view(kind, direction, up, horizontal_deg, vertical_deg):
    """Radiance's view options of type ``-vt<kind>`` from the origin (each number to 17 significant digits,
    so that the directions it gives are the camera's to rounding)."""
    def numbers(values):
        return " ".join(f"{float(v):.17g}" for v in values)

    return (f"-vt{kind} -vp 0 0 0 -vd {numbers(direction)} -vu {numbers(up)} -vh {float(horizontal_deg):.17g} "
            f"-vv {float(vertical_deg):.17g} -vs 0 -vl 0")


def _pixel_centres(count):
    """Pixel centres along an axis of ``count`` pixels, as fractions in (0, 1): (i + 0.5) / count."""
    return (np.arange(count, dtype=np.float64) + 0.5) / count


# Cameras ------------------------------------------------------------------------------------------

class Camera(abc.ABC):
    """Interface of every camera: ``width``, ``height``, ``name`` and :meth:`directions`."""

    #: Registry name of the camera type (a key of :data:`CAMERAS`).
    name: ClassVar[str]
    width: int
    height: int

    @abc.abstractmethod
    def directions(self):
        """View direction of every pixel centre.

        Returns
        -------
        dirs : numpy.ndarray
            float64, shape (height, width, 3): unit vectors (east, north, up); invalid pixels hold the
            zenith (0, 0, 1).
        valid : numpy.ndarray
            bool, shape (height, width): pixels that see the sky sphere.
        """

    def radiance_view(self) -> str | None:
        """The camera as Radiance's view options (``-vt... -vp -vd -vu -vh -vv``, the ``VIEW=`` line of a
        Radiance picture, which tools such as evalglare and Radiance's ``vwrays`` read to know where each
        pixel looks), in the ENU frame (x east, y north, z up), the observer at the origin; None where
        Radiance has no view type for the projection (the equirectangular panorama). Radiance's view
        geometry (``viewray`` of its image.c) maps the pixel centres to the directions of
        :meth:`directions`."""
        return None


@dataclasses.dataclass(frozen=True)
class FisheyeCamera(Camera):
    """All-sky equidistant fisheye, oriented like an all-sky camera photo.

    The image is square. The zenith is at the centre and the horizon (zenith angle 90 deg) on the
    inscribed circle; the zenith angle grows linearly with the distance from the centre. North is at
    the top, **east on the left** and west on the right: the sky seen from below, looking up.
    Pixels outside the circle are invalid.

    Parameters
    ----------
    size : int
        Width and height [pixels], an integer in [2, 16384].
    heading_deg : float
        Azimuth [deg] placed at the top of the image (default 0: north up), in [-360, 720]. Increasing it
        turns the image clockwise on the screen.

    Raises
    ------
    ValueError
        Naming the parameter and its valid range.

    Notes
    -----
    With pixel centres ``u = 2 (col + 0.5) / size - 1`` (right positive) and
    ``v = 1 - 2 (row + 0.5) / size`` (up positive) and ``r = sqrt(u^2 + v^2)``:

    - zenith angle ``theta = r * 90 deg`` (equidistant projection r = f theta), valid if ``r <= 1``;
    - azimuth ``phi = heading_deg + atan2(-u, v)``: top 0, left +90 (east), right -90 (west).

    References
    ----------
    .. [1] K. Miyamoto, "Fish eye lens", J. Opt. Soc. Am. 54(8), 1060-1061 (1964),
       doi:10.1364/JOSA.54.001060.
    .. [2] J. Kannala and S. S. Brandt, "A generic camera model and calibration method for
       conventional, wide-angle, and fish-eye lenses", IEEE TPAMI 28(8), 1335-1340 (2006),
       doi:10.1109/TPAMI.2006.153.

    Examples
    --------
    >>> camera = FisheyeCamera(64)
    >>> dirs, valid = camera.directions()
    >>> bool(valid[0, 0]), bool(valid[32, 32])      # corners lie outside the sky circle
    (False, True)
    >>> bool(dirs[32, 0, 0] > 0.99)                  # left edge, middle row: east (x = +1)
    True
    """

    name: ClassVar[str] = "fisheye"
    size: int
    heading_deg: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "size", _check_size("size", self.size))
        object.__setattr__(self, "heading_deg",
                           check_real("heading_deg", self.heading_deg, *AZIMUTH_RANGE_DEG, unit=" degrees"))

    @property
    def width(self) -> int:
        """Image width [pixels] (= size)."""
        return self.size

    @property
    def height(self) -> int:
        """Image height [pixels] (= size)."""
        return self.size

    def directions(self):
        """View direction of every pixel centre; pixels outside the horizon circle are invalid.

        Returns
        -------
        dirs : numpy.ndarray
            float64 (size, size, 3) unit vectors (east, north, up); invalid pixels hold (0, 0, 1).
        valid : numpy.ndarray
            bool (size, size): pixel centre inside or on the horizon circle.
        """
        centres = 2.0 * _pixel_centres(self.size) - 1.0
        u = centres[np.newaxis, :]                 # right positive
        v = -centres[:, np.newaxis]                # up positive (row 0 at the top)
        radius = np.hypot(u, v)
        valid = radius <= 1.0
        zenith = np.where(valid, radius, 0.0) * (0.5 * np.pi)
        azimuth = np.radians(self.heading_deg) + np.arctan2(-u, v)
        return _direction(zenith, azimuth), valid

    def radiance_view(self) -> str:
        """Radiance's angular fisheye (``-vta``, equidistant) looking up, 180 deg across: the image's top
        toward ``heading_deg`` (``-vu``) and its right (Radiance's ``vd x vu``) 90 deg west of it, as
        :meth:`directions` has them (east on the left: the sky seen from below)."""
        heading = math.radians(self.heading_deg)
        return _radiance_view("a", (0.0, 0.0, 1.0), (math.sin(heading), math.cos(heading), 0.0), 180.0, 180.0)


#: A perspective camera's horizontal field of view [deg]: from a thousandth of a degree (a telescope's
#: tens of arcseconds; at 5e-324 the focal length divided by zero, and below about 1e-150 the directions
#: overflowed) to 179.
FOV_RANGE_DEG = (1e-3, 179.0)
#: A heading or a sun's azimuth as typed [deg, clockwise from north]: a turn either way of the usual
#: [0, 360) (1e308 deg was taken and kept no precision in radians).
AZIMUTH_RANGE_DEG = (-360.0, 720.0)


@dataclasses.dataclass(frozen=True)
class PerspectiveCamera(Camera):
    """Pinhole (rectilinear) camera with a level horizon.

    Parameters
    ----------
    width, height : int
        Image size [pixels], integers in [2, 16384].
    fov_deg : float
        Horizontal field of view [deg], edge to edge of the image, in :data:`FOV_RANGE_DEG` (default 90).
    heading_deg : float
        Azimuth of the optical axis [deg], from north clockwise (90 = east), in [-360, 720] (default 180:
        looking south).
    pitch_deg : float
        Elevation of the optical axis [deg], in [-90, 90] (default 10).

    Raises
    ------
    ValueError
        Naming the parameter and its valid range.

    Notes
    -----
    Forward ``F = (cos p sin h, cos p cos h, sin p)``, right ``R = (cos h, -sin h, 0)`` (horizontal:
    no roll, so the horizon is level; defined at p = +-90 deg too) and up ``U = R x F =
    (-sin p sin h, -sin p cos h, cos p)``, with h = heading and p = pitch. The focal length in pixels
    is ``f = (width / 2) / tan(fov / 2)``; a pixel centre at ``x = col + 0.5 - width / 2`` (right)
    and ``y = height / 2 - (row + 0.5)`` (up) looks along ``normalize(f F + x R + y U)``. Square
    pixels: the vertical field of view is ``2 atan((height / 2) / f)``. Every pixel is valid.

    Examples
    --------
    >>> camera = PerspectiveCamera(5, 3, fov_deg=90.0, heading_deg=90.0, pitch_deg=0.0)
    >>> dirs, valid = camera.directions()
    >>> [round(float(c), 12) for c in dirs[1, 2]]    # the centre pixel looks due east
    [1.0, 0.0, 0.0]
    >>> bool(valid.all())
    True
    """

    name: ClassVar[str] = "perspective"
    width: int
    height: int
    fov_deg: float = 90.0
    heading_deg: float = 180.0
    pitch_deg: float = 10.0

    def __post_init__(self):
        object.__setattr__(self, "width", _check_size("width", self.width))
        object.__setattr__(self, "height", _check_size("height", self.height))
        object.__setattr__(self, "fov_deg", check_real("fov_deg", self.fov_deg, *FOV_RANGE_DEG, unit=" degrees"))
        object.__setattr__(self, "heading_deg",
                           check_real("heading_deg", self.heading_deg, *AZIMUTH_RANGE_DEG, unit=" degrees"))
        object.__setattr__(self, "pitch_deg", check_real("pitch_deg", self.pitch_deg, -90.0, 90.0))

    @property
    def focal_length(self) -> float:
        """Focal length [pixels]: (width / 2) / tan(fov / 2)."""
        return 0.5 * self.width / math.tan(math.radians(0.5 * self.fov_deg))

    def basis(self):
        """Camera axes in the ENU frame: forward, right, up (each a unit vector of shape (3,))."""
        heading, pitch = math.radians(self.heading_deg), math.radians(self.pitch_deg)
        forward = np.array([math.cos(pitch) * math.sin(heading), math.cos(pitch) * math.cos(heading),
                            math.sin(pitch)])
        right = np.array([math.cos(heading), -math.sin(heading), 0.0])
        up = np.array([-math.sin(pitch) * math.sin(heading), -math.sin(pitch) * math.cos(heading),
                       math.cos(pitch)])
        return forward, right, up

    def directions(self):
        """View direction of every pixel centre (all valid).

        Returns
        -------
        dirs : numpy.ndarray
            float64 (height, width, 3) unit vectors (east, north, up).
        valid : numpy.ndarray
            bool (height, width), all True.
        """
        forward, right, up = self.basis()
        x = (np.arange(self.width, dtype=np.float64) + 0.5 - 0.5 * self.width)[np.newaxis, :, None]
        y = (0.5 * self.height - (np.arange(self.height, dtype=np.float64) + 0.5))[:, None, None]
        rays = self.focal_length * forward + x * right + y * up
        dirs = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
        return dirs, np.ones((self.height, self.width), dtype=bool)

    def radiance_view(self) -> str:
        """Radiance's perspective view (``-vtv``): ``-vd`` forward, ``-vu`` the camera's up (Radiance's
        right, ``vd x vu``, is then :meth:`basis`'s right), ``-vh`` the horizontal field of view and
        ``-vv`` the vertical one, 2 atan((height / 2) / f)."""
        forward, _, up = self.basis()
        vertical = math.degrees(2.0 * math.atan(0.5 * self.height / self.focal_length))
        return _radiance_view("v", forward, up, self.fov_deg, vertical)


@dataclasses.dataclass(frozen=True)
class EquirectangularCamera(Camera):
    """Full 360 x 180 deg latitude-longitude panorama, usable as an HDR environment map.

    Convention (the usual one for environment maps: the panorama seen from inside the sphere,
    not mirrored; turning right moves right in the image):

    - column -> azimuth: ``phi = 360 deg * (col + 0.5) / width``, from north clockwise seen from
      above. The left edge (x = 0) is north, x = width/4 east, x = width/2 (the image centre) south,
      x = 3 width/4 west, and the right edge north again.
    - row -> elevation: ``e = 90 deg - 180 deg * (row + 0.5) / height``: the top edge is the zenith,
      the middle (y = height/2) the horizon, the bottom edge the nadir.

    Equivalently, normalised texture coordinates ``u = x / width = phi / 360 deg`` and
    ``v = y / height = (90 deg - e) / 180 deg`` with v = 0 at the top row (image order, as stored
    by image files). To load the map into an engine whose equirectangular lookup puts another
    direction at u = 0.5, rotate it about the vertical so that u = 0.5 is south. This is OpenEXR's
    latitude-longitude layout with the world axes X = east, Y = up, Z = south (:mod:`clsky.anim.exr`, which
    writes such maps; ``docs/exr.md`` gives the rotations for Blender and three.js). Every pixel is
    valid; a 2:1 aspect ratio gives square pixels at the horizon.

    Parameters
    ----------
    width, height : int
        Image size [pixels], integers in [2, 16384] (usually width = 2 height).

    Raises
    ------
    ValueError
        Naming the parameter and its valid range.

    Notes
    -----
    The solid angle of pixel (row, col) is ``(sin e_top - sin e_bottom) (2 pi / width)`` ~
    ``cos(e) (pi / height) (2 pi / width)`` [sr]; the pixels tile the sphere (4 pi sr) once.

    References
    ----------
    .. [1] J. P. Snyder, "Map Projections - A Working Manual", USGS Professional Paper 1395,
       pp. 90-91 (equidistant cylindrical projection) (1987), doi:10.3133/pp1395.

    Examples
    --------
    >>> camera = EquirectangularCamera(8, 4)
    >>> dirs, valid = camera.directions()
    >>> dirs.shape
    (4, 8, 3)
    >>> bool(dirs[0, 0, 2] > 0.9), bool(dirs[-1, 0, 2] < -0.9)   # top row up, bottom row down
    (True, True)
    """

    name: ClassVar[str] = "equirectangular"
    width: int
    height: int

    def __post_init__(self):
        object.__setattr__(self, "width", _check_size("width", self.width))
        object.__setattr__(self, "height", _check_size("height", self.height))

    def directions(self):
        """View direction of every pixel centre (all valid).

        Returns
        -------
        dirs : numpy.ndarray
            float64 (height, width, 3) unit vectors (east, north, up).
        valid : numpy.ndarray
            bool (height, width), all True.
        """
        azimuth = (2.0 * np.pi) * _pixel_centres(self.width)[np.newaxis, :]
        zenith = np.pi * _pixel_centres(self.height)[:, np.newaxis]   # 90 deg - elevation
        return _direction(zenith, azimuth), np.ones((self.height, self.width), dtype=bool)


# Registry -----------------------------------------------------------------------------------------

def _fisheye_from_size(width, height, **options):
    if width != height:
        raise ValueError(f"the fisheye camera is square: width and height must be equal, "
                         f"got {short(width)} x {short(height)}")
    return FisheyeCamera(width, **options)


#: Camera types by name: factory ``(width, height, **options) -> Camera``.
CAMERAS = {
    "fisheye": _fisheye_from_size,
    "perspective": PerspectiveCamera,
    "equirectangular": EquirectangularCamera,
}


def camera_from_name(name, width, height, **options):
    """Make a camera from its registry name.

    Parameters
    ----------
    name : {'fisheye', 'perspective', 'equirectangular'}
        Camera type (a key of :data:`CAMERAS`).
    width, height : int
        Image size [pixels], integers in [2, 16384]; equal for 'fisheye'.
    **options
        Keyword arguments of the camera class (``heading_deg``; ``fov_deg`` and ``pitch_deg`` for
        'perspective').

    Returns
    -------
    Camera

    Raises
    ------
    ValueError
        Unknown name, invalid size or option value, or a non-square fisheye.
    TypeError
        An option the camera does not take.

    Examples
    --------
    >>> camera_from_name("perspective", 320, 240, fov_deg=60.0)
    PerspectiveCamera(width=320, height=240, fov_deg=60.0, heading_deg=180.0, pitch_deg=10.0)
    """
    if not isinstance(name, str) or name not in CAMERAS:
        raise ValueError(f"name must be one of {sorted(CAMERAS)}, got {name!r}")
    return CAMERAS[name](width, height, **options)
