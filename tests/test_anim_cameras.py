"""clsky.anim.cameras: per-pixel view directions of the fisheye, perspective and equirectangular cameras.

Frame: x = east, y = north, z = up; azimuth from north clockwise (east = 90 deg); row 0 at the top.
Angles are measured with atan2 (never arccos near 1, which loses half the digits), so tolerances of
1e-12 deg / rad leave room for a few ulps of float64 trigonometry, not for mistakes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from clsky.anim.cameras import (CAMERAS, Camera, EquirectangularCamera, FisheyeCamera, PerspectiveCamera,
                          camera_from_name, sun_direction)

#: Direction arithmetic is a handful of float64 sin/cos/products: a few ulps (~1e-16) of error.
DIRECTION_ATOL = 1e-14
#: Angles from atan2 of such directions [deg]: ~1e-14 deg expected, 1e-12 leaves margin.
ANGLE_ATOL_DEG = 1e-12


def zenith_deg(dirs):
    """Zenith angle [deg] of unit vectors, accurate near 0 and 180 (atan2, not arccos)."""
    return np.degrees(np.arctan2(np.hypot(dirs[..., 0], dirs[..., 1]), dirs[..., 2]))


def azimuth_deg(dirs):
    """Azimuth [deg] in [0, 360), from north clockwise."""
    return np.mod(np.degrees(np.arctan2(dirs[..., 0], dirs[..., 1])), 360.0)


def angle_between_deg(a, b):
    """Angle [deg] between unit vectors (atan2 of |a x b| and a . b: accurate at every angle)."""
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def wrapped_difference_deg(a, b):
    """a - b wrapped into [-180, 180)."""
    return np.mod(np.asarray(a) - np.asarray(b) + 180.0, 360.0) - 180.0


ALL_CAMERAS = [
    FisheyeCamera(64), FisheyeCamera(33, heading_deg=37.5), FisheyeCamera(2),
    PerspectiveCamera(48, 32), PerspectiveCamera(31, 17, fov_deg=179.0, heading_deg=-45.0,
                                                 pitch_deg=90.0),
    PerspectiveCamera(20, 40, fov_deg=1.0, heading_deg=400.0, pitch_deg=-90.0),
    EquirectangularCamera(64, 32), EquirectangularCamera(3, 2),
]


# Common interface ---------------------------------------------------------------------------------

@pytest.mark.parametrize("camera", ALL_CAMERAS, ids=repr)
def test_directions_are_unit_vectors_of_the_right_shape(camera):
    assert isinstance(camera, Camera)
    assert camera.name in CAMERAS
    dirs, valid = camera.directions()
    assert dirs.dtype == np.float64 and dirs.shape == (camera.height, camera.width, 3)
    assert valid.dtype == np.bool_ and valid.shape == (camera.height, camera.width)
    assert np.all(np.isfinite(dirs))
    # Every pixel, valid or not, holds a unit vector (invalid ones a harmless one).
    assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, rtol=0, atol=DIRECTION_ATOL)


def test_sun_direction():
    cases = {(0.0, 123.0): (0, 0, 1), (90.0, 0.0): (0, 1, 0), (90.0, 90.0): (1, 0, 0),
             (90.0, 180.0): (0, -1, 0), (90.0, 270.0): (-1, 0, 0), (180.0, 0.0): (0, 0, -1)}
    for (zenith, azimuth), expected in cases.items():
        direction = sun_direction(zenith, azimuth)
        assert direction.shape == (3,) and direction.dtype == np.float64
        assert_allclose(direction, expected, rtol=0, atol=DIRECTION_ATOL)
    assert_allclose(sun_direction(60.0, 180.0), (0.0, -math.sqrt(3) / 2, 0.5), rtol=0,
                    atol=DIRECTION_ATOL)
    many = sun_direction(np.linspace(0, 180, 7)[:, None], np.linspace(0, 360, 5))
    assert many.shape == (7, 5, 3)
    assert_allclose(np.linalg.norm(many, axis=-1), 1.0, rtol=0, atol=DIRECTION_ATOL)
    for bad in (math.nan, math.inf):
        with pytest.raises(ValueError, match="zenith_deg"):
            sun_direction(bad, 0.0)
        with pytest.raises(ValueError, match="azimuth_deg"):
            sun_direction(0.0, bad)
    # a zenith angle of -10 deg was a sun 80 deg up on the other side; 1e300 deg had no precision left
    for bad in (-10.0, 180.5, 1e300, [10.0, -1e-9]):
        with pytest.raises(ValueError, match=r"^zenith_deg must be in \[0, 180\] degrees, got"):
            sun_direction(bad, 0.0)
    for bad in (-360.5, 1e300):
        with pytest.raises(ValueError, match=r"^azimuth_deg must be in \[-360, 720\] degrees, got"):
            sun_direction(45.0, bad)
    assert_allclose(sun_direction(180.0, 720.0), (0.0, 0.0, -1.0), rtol=0, atol=DIRECTION_ATOL)


# Fisheye ------------------------------------------------------------------------------------------

def fisheye_radius(size):
    """Distance of every pixel centre from the image centre, in units of the horizon radius."""
    centres = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    return np.hypot(centres[None, :], centres[:, None])


@pytest.mark.parametrize("size", [65, 64])
def test_fisheye_centre_looks_at_the_zenith(size):
    dirs, valid = FisheyeCamera(size).directions()
    pixel_deg = 180.0 / size                   # zenith angle spanned by one pixel (90 deg / radius)
    middle = size // 2
    if size % 2:                               # odd: one pixel sits exactly on the centre
        assert zenith_deg(dirs[middle, middle]) <= ANGLE_ATOL_DEG
    else:                                      # even: four pixels, half a pixel diagonally away
        central = dirs[middle - 1:middle + 1, middle - 1:middle + 1]
        assert_allclose(zenith_deg(central), math.sqrt(2) * pixel_deg / 2, rtol=0,
                        atol=ANGLE_ATOL_DEG)
    assert zenith_deg(dirs[valid]).min() <= math.sqrt(2) * pixel_deg / 2 + ANGLE_ATOL_DEG


@pytest.mark.parametrize("size", [65, 64])
def test_fisheye_rim_is_the_horizon_and_outside_is_invalid(size):
    dirs, valid = FisheyeCamera(size).directions()
    radius = fisheye_radius(size)
    assert_array_equal(valid, radius <= 1.0)
    assert not valid[0, 0] and not valid[0, -1] and not valid[-1, 0] and not valid[-1, -1]
    assert_array_equal(dirs[~valid], np.broadcast_to([0.0, 0.0, 1.0], dirs[~valid].shape))
    # No valid pixel looks below the horizon; the edge pixels of the middle rows/columns are half a
    # pixel (90 / size deg) inside the rim, i.e. at zenith angle 90 (1 - 1 / size) deg.
    assert zenith_deg(dirs[valid]).max() <= 90.0
    middle = size // 2
    for row, col in [(middle, 0), (middle, size - 1), (0, middle), (size - 1, middle)]:
        assert valid[row, col]
        assert abs(zenith_deg(dirs[row, col]) - 90.0 * (1.0 - 1.0 / size)) <= 90.0 / size


def test_fisheye_orientation_north_up_east_left():
    size = 65                                   # odd: the middle row and column are exact axes
    dirs, _ = FisheyeCamera(size).directions()
    middle = size // 2
    rim_zenith = 90.0 * (1.0 - 1.0 / size)      # edge pixel centres (see the test above)
    expected = {"top": ((0, middle), 0.0), "left": ((middle, 0), 90.0),
                "bottom": ((size - 1, middle), 180.0), "right": ((middle, size - 1), 270.0)}
    for side, ((row, col), azimuth) in expected.items():
        assert_allclose(dirs[row, col], sun_direction(rim_zenith, azimuth), rtol=0,
                        atol=DIRECTION_ATOL, err_msg=side)
    # Looking up from below: north at the top, EAST ON THE LEFT (x = +1), west on the right.
    assert dirs[0, middle, 1] > 0.99           # top: north
    assert dirs[middle, 0, 0] > 0.99           # left edge, middle row: east
    assert dirs[middle, -1, 0] < -0.99         # right edge: west
    assert dirs[-1, middle, 1] < -0.99         # bottom: south


@pytest.mark.parametrize("heading", [90.0, 200.0, -30.0])
def test_fisheye_heading_puts_that_azimuth_at_the_top(heading):
    size = 65
    middle = size // 2
    dirs, _ = FisheyeCamera(size, heading_deg=heading).directions()
    assert abs(wrapped_difference_deg(azimuth_deg(dirs[0, middle]), heading)) <= ANGLE_ATOL_DEG
    # Left stays 90 deg counter-clockwise on the screen from the top: azimuth heading + 90.
    assert abs(wrapped_difference_deg(azimuth_deg(dirs[middle, 0]), heading + 90.0)) \
        <= ANGLE_ATOL_DEG
    # Rotating the camera rotates the image: same zenith angles everywhere.
    assert_allclose(zenith_deg(dirs), zenith_deg(FisheyeCamera(size).directions()[0]), rtol=0,
                    atol=ANGLE_ATOL_DEG)


@pytest.mark.parametrize("size", [64, 33])
def test_fisheye_is_equidistant(size):
    """Zenith angle = 90 deg x (distance from the centre / horizon radius), at every valid pixel."""
    camera = FisheyeCamera(size, heading_deg=15.0)
    dirs, valid = camera.directions()
    radius = fisheye_radius(size)
    assert_allclose(zenith_deg(dirs[valid]), 90.0 * radius[valid], rtol=0, atol=ANGLE_ATOL_DEG)
    # Azimuth: heading + atan2(-u, v) with u right and v up (east on the left).
    centres = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    u, v = np.broadcast_arrays(centres[None, :], -centres[:, None])
    expected = np.degrees(np.arctan2(-u, v)) + camera.heading_deg
    off_centre = valid & (radius > 1e-6)
    assert np.abs(wrapped_difference_deg(azimuth_deg(dirs), expected)[off_centre]).max() \
        <= ANGLE_ATOL_DEG


@pytest.mark.parametrize("size", [64, 65])
def test_fisheye_mirror_symmetry(size):
    """Heading 0: pixels (row, col) and (row, size - 1 - col) are mirror images in x (east-west)."""
    dirs, valid = FisheyeCamera(size).directions()
    mirrored = dirs[:, ::-1] * np.array([-1.0, 1.0, 1.0])
    # The mirrored pixel centres agree to ~1 ulp (2 (i + 0.5) / n - 1 is not always exactly odd).
    assert_allclose(mirrored[valid], dirs[valid], rtol=0, atol=DIRECTION_ATOL)
    assert_array_equal(valid[:, ::-1], valid)
    assert_array_equal(valid[::-1, :], valid)


# Perspective --------------------------------------------------------------------------------------

@pytest.mark.parametrize("heading, pitch", [(180.0, 10.0), (0.0, 0.0), (90.0, 45.0),
                                            (237.0, -30.0), (12.0, 90.0), (300.0, -90.0)])
def test_perspective_centre_pixel_is_the_optical_axis(heading, pitch):
    camera = PerspectiveCamera(41, 31, fov_deg=70.0, heading_deg=heading, pitch_deg=pitch)
    dirs, valid = camera.directions()
    assert valid.all()
    assert_allclose(dirs[15, 20], sun_direction(90.0 - pitch, heading), rtol=0, atol=DIRECTION_ATOL)


@pytest.mark.parametrize("fov", [1.0, 60.0, 90.0, 150.0, 179.0])
def test_perspective_horizontal_fov_is_exact(fov):
    """Pinhole: tan(angle from the axis) is linear in the image x coordinate and reaches
    tan(fov / 2) at the image edges x = +-width / 2 (so the edge-to-edge field of view is fov)."""
    width, height = 40, 21
    camera = PerspectiveCamera(width, height, fov_deg=fov, heading_deg=110.0, pitch_deg=25.0)
    dirs, _ = camera.directions()
    forward, right, _ = camera.basis()
    row = dirs[height // 2]                     # the row through the optical axis (height odd)
    angle = np.degrees(np.arctan2(row @ right, row @ forward))
    x = np.arange(width) + 0.5 - width / 2      # pixel centres, from -(width - 1)/2 to +(width - 1)/2
    expected = np.degrees(np.arctan(x / (width / 2) * math.tan(math.radians(fov / 2))))
    assert_allclose(angle, expected, rtol=0, atol=ANGLE_ATOL_DEG)
    # The pixels of that row stay in the plane of the axis and the horizontal right vector.
    assert_allclose(row @ np.cross(right, forward), 0.0, rtol=0, atol=DIRECTION_ATOL)


@pytest.mark.parametrize("fov, width, height", [(90.0, 64, 48), (60.0, 30, 50), (170.0, 17, 9)])
def test_perspective_corner_angles_match_the_fov(fov, width, height):
    camera = PerspectiveCamera(width, height, fov_deg=fov, heading_deg=200.0, pitch_deg=-15.0)
    dirs, _ = camera.directions()
    forward, _, _ = camera.basis()
    tan_half = math.tan(math.radians(fov / 2))
    # Square pixels: a pixel centre at (x, y) pixels from the centre is atan(|(x, y)| / f) off axis,
    # f = (width / 2) / tan(fov / 2).
    corner = math.hypot((width - 1) / 2, (height - 1) / 2)
    expected = math.degrees(math.atan(corner * tan_half / (width / 2)))
    for row, col in [(0, 0), (0, -1), (-1, 0), (-1, -1)]:
        assert abs(angle_between_deg(dirs[row, col], forward) - expected) <= ANGLE_ATOL_DEG
    # The image corners themselves (extrapolated half a pixel) are at atan(|(W/2, H/2)| / f).
    assert math.isclose(math.degrees(math.atan(math.hypot(width / 2, height / 2) / camera.focal_length)),
                        math.degrees(math.atan(math.hypot(1.0, height / width) * tan_half)),
                        rel_tol=1e-14)


def test_perspective_orientation_and_level_horizon():
    width, height = 33, 25
    # Looking south: east (x > 0) on the left, west on the right, sky at the top.
    dirs, _ = PerspectiveCamera(width, height, fov_deg=90.0, heading_deg=180.0,
                                pitch_deg=0.0).directions()
    assert dirs[height // 2, 0, 0] > 0.5 and dirs[height // 2, -1, 0] < -0.5
    assert np.all(dirs[0, :, 2] > 0) and np.all(dirs[-1, :, 2] < 0)
    # Pitch 0: the middle row is the horizon itself.
    assert_allclose(dirs[height // 2, :, 2], 0.0, rtol=0, atol=DIRECTION_ATOL)
    # No roll at any pitch: mirror pixels (row, col), (row, W - 1 - col) have the same elevation.
    # (At pitch -60 and 80 the 90 x 74 deg view reaches past the nadir / zenith.)
    for pitch in (-60.0, -30.0, 10.0, 40.0, 80.0):
        dirs, _ = PerspectiveCamera(width, height, heading_deg=77.0, pitch_deg=pitch).directions()
        assert_allclose(dirs[:, ::-1, 2], dirs[:, :, 2], rtol=0, atol=DIRECTION_ATOL)
        if abs(pitch) <= 40.0:                  # the centre column spans pitch +- 37 deg
            assert np.all(np.diff(dirs[:, width // 2, 2]) < 0)    # elevation falls down the image


# Equirectangular ----------------------------------------------------------------------------------

def test_equirectangular_convention():
    width, height = 128, 64
    dirs, valid = EquirectangularCamera(width, height).directions()
    assert valid.all()
    half_pixel_deg = 180.0 / width              # half a column, in azimuth
    # Column centres: azimuth 360 (col + 0.5) / width, from north clockwise; every row alike.
    expected_azimuth = 360.0 * (np.arange(width) + 0.5) / width
    for row in (1, height // 2, height - 2):
        assert_allclose(azimuth_deg(dirs[row]), expected_azimuth, rtol=0, atol=ANGLE_ATOL_DEG)
    # Rows: elevation 90 - 180 (row + 0.5) / height, every column alike.
    expected_elevation = 90.0 - 180.0 * (np.arange(height) + 0.5) / height
    assert_allclose(90.0 - zenith_deg(dirs), np.broadcast_to(expected_elevation[:, None],
                                                             (height, width)),
                    rtol=0, atol=ANGLE_ATOL_DEG)
    # Column width/4 looks east, width/2 south, 3 width/4 west, 0 north: within half a pixel.
    middle = height // 2
    for col, azimuth in [(0, 0.0), (width // 4, 90.0), (width // 2, 180.0), (3 * width // 4, 270.0)]:
        assert abs(wrapped_difference_deg(azimuth_deg(dirs[middle, col]), azimuth)) \
            <= half_pixel_deg + ANGLE_ATOL_DEG
    assert dirs[middle, width // 4, 0] > 0.99   # east is +x
    # Top row half a row (90 / height deg) from the zenith, bottom row from the nadir.
    assert_allclose(zenith_deg(dirs[0]), 90.0 / height, rtol=0, atol=ANGLE_ATOL_DEG)
    assert_allclose(zenith_deg(dirs[-1]), 180.0 - 90.0 / height, rtol=0, atol=ANGLE_ATOL_DEG)


def test_equirectangular_covers_the_sphere():
    width, height = 128, 64
    dirs, _ = EquirectangularCamera(width, height).directions()
    elevation = np.arcsin(np.clip(dirs[..., 2], -1.0, 1.0))
    d_longitude, d_latitude = 2.0 * np.pi / width, np.pi / height
    total = np.sum(np.cos(elevation)) * d_longitude * d_latitude
    # Midpoint rule for the integral of cos over [-pi/2, pi/2] in steps h: it gives exactly
    # 2 (h / 2) / sin(h / 2) ~ 2 (1 + h^2 / 24): a relative excess of 2.0e-4 for h = pi / 64.
    h = d_latitude
    assert math.isclose(total, 4.0 * np.pi * (h / 2) / math.sin(h / 2), rel_tol=1e-12)
    assert math.isclose(total, 4.0 * np.pi, rel_tol=1e-3)


# Validation and registry --------------------------------------------------------------------------

@pytest.mark.parametrize("factory, kwargs, parameter", [
    (FisheyeCamera, dict(size=1), "size"),
    (FisheyeCamera, dict(size=16385), "size"),
    (FisheyeCamera, dict(size=64.0), "size"),
    (FisheyeCamera, dict(size=True), "size"),
    (FisheyeCamera, dict(size="64"), "size"),
    (FisheyeCamera, dict(size=64, heading_deg=math.nan), "heading_deg"),
    (FisheyeCamera, dict(size=64, heading_deg=math.inf), "heading_deg"),
    (FisheyeCamera, dict(size=64, heading_deg="north"), "heading_deg"),
    (PerspectiveCamera, dict(width=1, height=64), "width"),
    (PerspectiveCamera, dict(width=64, height=20000), "height"),
    (PerspectiveCamera, dict(width=64, height=64, fov_deg=0.0), "fov_deg"),
    (PerspectiveCamera, dict(width=64, height=64, fov_deg=-10.0), "fov_deg"),
    (PerspectiveCamera, dict(width=64, height=64, fov_deg=179.5), "fov_deg"),
    (PerspectiveCamera, dict(width=64, height=64, fov_deg=math.nan), "fov_deg"),
    (PerspectiveCamera, dict(width=64, height=64, pitch_deg=90.5), "pitch_deg"),
    (PerspectiveCamera, dict(width=64, height=64, pitch_deg=-91.0), "pitch_deg"),
    (PerspectiveCamera, dict(width=64, height=64, pitch_deg=math.nan), "pitch_deg"),
    (PerspectiveCamera, dict(width=64, height=64, heading_deg=-math.inf), "heading_deg"),
    # AnimationConfig's and the command line's range (AZIMUTH_RANGE_DEG): 1e308 deg kept no precision
    (FisheyeCamera, dict(size=64, heading_deg=1e308), r"heading_deg must be a number in \[-360, 720\] degrees"),
    (PerspectiveCamera, dict(width=64, height=64, heading_deg=-720.0), "heading_deg"),
    (EquirectangularCamera, dict(width=0, height=64), "width"),
    (EquirectangularCamera, dict(width=128, height=2.5), "height"),
])
def test_invalid_parameters_raise_naming_them(factory, kwargs, parameter):
    with pytest.raises(ValueError, match=parameter):
        factory(**kwargs)


def test_boundary_values_are_accepted():
    FisheyeCamera(2)
    FisheyeCamera(np.int64(16384))
    PerspectiveCamera(2, 16384, fov_deg=179.0, pitch_deg=90.0)
    PerspectiveCamera(16384, 2, fov_deg=1e-3, pitch_deg=-90.0, heading_deg=-360.0)
    FisheyeCamera(2, heading_deg=720.0)
    EquirectangularCamera(2, 2)


def test_camera_from_name():
    assert set(CAMERAS) == {"fisheye", "perspective", "equirectangular"}
    assert camera_from_name("fisheye", 32, 32, heading_deg=10.0) == FisheyeCamera(32, 10.0)
    assert camera_from_name("perspective", 40, 30, fov_deg=60.0, pitch_deg=0.0) \
        == PerspectiveCamera(40, 30, fov_deg=60.0, pitch_deg=0.0)
    assert camera_from_name("equirectangular", 64, 32) == EquirectangularCamera(64, 32)
    for name in CAMERAS:
        camera = camera_from_name(name, 16, 16)
        assert camera.name == name and (camera.width, camera.height) == (16, 16)
    with pytest.raises(ValueError, match="name"):
        camera_from_name("orthographic", 32, 32)
    with pytest.raises(ValueError, match="width and height"):
        camera_from_name("fisheye", 64, 32)
    with pytest.raises(ValueError, match="fov_deg"):
        camera_from_name("perspective", 64, 32, fov_deg=200.0)
    with pytest.raises(TypeError):
        camera_from_name("equirectangular", 64, 32, fov_deg=90.0)


@pytest.mark.parametrize("angle", ["abc", 10**400, 1j, True])
def test_sun_direction_refuses_what_is_no_angle(angle):
    """A string gave NumPy's message, 10**400 an OverflowError, 1j a TypeError, and True was 1 deg."""
    with pytest.raises(ValueError, match=r"^zenith_deg must be a real number of degrees or an array of them"):
        sun_direction(angle, 0.0)
    with pytest.raises(ValueError, match=r"^azimuth_deg must be a real number of degrees"):
        sun_direction(30.0, angle)


# Radiance's view of a camera (Camera.radiance_view) -------------------------------------------------

def radiance_directions(view, width, height):
    """The directions of the pixel centres of a ``width`` x ``height`` picture taken with Radiance's view
    options ``view`` (-vta or -vtv), as Radiance's ``viewray`` (src/common/image.c) computes them, written
    here from its formulas and sharing no code with the cameras: hvec = normalize(vd x vu), vvec =
    normalize(hvec x vd); image coordinates x = (col + 0.5) / width - 0.5 (right) and y = (rows from the
    bottom + 0.5) / height - 0.5 (up). Perspective: vd + x 2 tan(vh / 2) hvec + y 2 tan(vv / 2) vvec.
    Angular fisheye: x, y scaled by vh / 180 and vv / 180, d = |(x, y)|, the direction cos(pi d) vd +
    sin(pi d) (x hvec + y vvec) / d. Returns (directions, inside): inside as evalglare takes a -vta picture's
    pixel to be (pict_is_validpixel: its direction within 90 deg of vd)."""
    words = view.split()
    kind = words[0]
    options, name = {}, None
    for word in words[1:]:
        if word.startswith("-v"):
            name = word
            options[name] = []
        else:
            options[name].append(float(word))
    vd, vu = np.array(options["-vd"]), np.array(options["-vu"])
    vh, vv = options["-vh"][0], options["-vv"][0]
    vd = vd / np.linalg.norm(vd)
    hvec = np.cross(vd, vu)
    hvec /= np.linalg.norm(hvec)
    vvec = np.cross(hvec, vd)
    x = ((np.arange(width) + 0.5) / width - 0.5)[None, :, None]
    y = ((height - 1 - np.arange(height) + 0.5) / height - 0.5)[:, None, None]
    if kind == "-vtv":
        half_width, half_height = (2.0 * math.tan(math.radians(angle) / 2.0) for angle in (vh, vv))
        rays = vd + x * half_width * hvec + y * half_height * vvec
        return rays / np.linalg.norm(rays, axis=-1, keepdims=True), np.ones((height, width), bool)
    assert kind == "-vta"
    x, y = x * vh / 180.0, y * vv / 180.0
    d = np.hypot(x, y)
    sine = np.sin(math.pi * d) / np.where(d > 0.0, d, 1.0)
    rays = np.cos(math.pi * d) * vd + sine * (x * hvec + y * vvec)
    return rays, rays @ vd >= 0.0


@pytest.mark.parametrize("size, heading", [(16, 0.0), (33, 0.0), (24, 37.5), (20, 270.0)])
def test_fisheye_radiance_view_looks_where_the_camera_does(size, heading):
    """Radiance's angular fisheye of the camera's VIEW= line gives its pixels' directions (to 1e-14: the
    view's 17 digits and two formulas' roundings) and the same circle of valid pixels."""
    camera = FisheyeCamera(size, heading_deg=heading)
    view = camera.radiance_view()
    assert view.startswith("-vta ") and "-vh 180 -vv 180" in view
    directions, valid = camera.directions()
    radiance, inside = radiance_directions(view, size, size)
    assert_array_equal(inside, valid)
    assert_allclose(radiance[valid], directions[valid], rtol=0.0, atol=1e-14)


@pytest.mark.parametrize("width, height, fov, heading, pitch", [
    (16, 12, 90.0, 180.0, 10.0), (9, 21, 30.0, 45.0, -20.0), (40, 10, 170.0, 300.0, 0.0), (8, 8, 60.0, 10.0, 90.0),
    (8, 6, 1e-3, 0.0, -90.0)])
def test_perspective_radiance_view_looks_where_the_camera_does(width, height, fov, heading, pitch):
    """Radiance's perspective view of the camera's VIEW= line gives its pixels' directions, the zenith and
    the nadir included (1e-14; the thousandth of a degree's directions agree to its tangents' rounding)."""
    camera = PerspectiveCamera(width, height, fov_deg=fov, heading_deg=heading, pitch_deg=pitch)
    view = camera.radiance_view()
    assert view.startswith("-vtv ")
    directions, _ = camera.directions()
    radiance, _ = radiance_directions(view, width, height)
    assert_allclose(radiance, directions, rtol=0.0, atol=1e-14)


def test_equirectangular_has_no_radiance_view():
    """Radiance has no view type of a latitude-longitude panorama (-vtc is cylindrical)."""
    assert EquirectangularCamera(16, 8).radiance_view() is None
