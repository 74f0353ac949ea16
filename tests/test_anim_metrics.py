"""clsky.anim.tonemap and clsky.anim.metrics: tone map, dither, frame comparison, colour science, images."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from clsky.anim.metrics import (BLACK_FRAME_FLOOR, D65_WHITE_XYZ, INVALID_COLOUR, SRGB_TO_XYZ, colormap_viridis,
                          compare_frames, composite, delta_e_cie76, display_floor, display_to_lab,
                          error_image, frame_changes, frame_comparison, linear_srgb_to_xyz, mean_luminance,
                          relative_error_map, temporal_jumps, xyz_to_lab)
from clsky.anim import metrics, tonemap
from clsky.anim.tonemap import dither_noise, luminance, to_uint8, tone_map


def _sky(height=24, width=32, seed=1):
    """A smooth HDR test frame with every pixel in [0.1, 2.2] (well above the error floor)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width]
    base = np.stack([0.1 + x / width, 0.2 + y / height, 0.5 + 0.5 * (x + y) / (width + height)], axis=-1)
    return base * rng.uniform(1.0, 1.5, size=(height, width, 1))


# Tone map ---------------------------------------------------------------------------------------------

def test_tone_map_known_values():
    hdr = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    display = tone_map(hdr)
    assert_array_equal(display[0], 0.0)          # exactly: expm1(-0) = 0 and 0 ** (1/2.2) = 0
    # expm1 against 1 - exp and the power: a few ulps.
    assert_allclose(display[1], (1.0 - np.exp(-1.0)) ** (1 / 2.2), rtol=1e-14, atol=0)


def test_tone_map_exposure_scales_hdr():
    hdr = _sky()
    # exposure multiplies hdr before the curve: identical arithmetic up to one rounding of the product.
    assert_allclose(tone_map(hdr, exposure=4.0), tone_map(4.0 * hdr), rtol=1e-15, atol=0)


def test_tone_map_monotonic_and_bounded():
    hdr = np.linspace(0.0, 50.0, 50001)[:, None].repeat(3, axis=1)
    display = tone_map(hdr)[:, 0]
    # Strictly increasing while a 1e-3 step changes the value by more than an ulp of 1
    # (0.45 exp(-h) 1e-3 > 2.2e-16, h < 28: take h <= 20); never decreasing beyond.
    assert np.all(np.diff(display[:20001]) > 0)
    assert np.all(np.diff(display) >= 0)
    wide = np.concatenate([np.logspace(-12, 3, 200), [np.inf]])[:, None].repeat(3, axis=1)
    values = tone_map(wide)
    assert values.min() >= 0.0 and values.max() <= 1.0 and values[-1, 0] == 1.0


@pytest.mark.parametrize("bad", [np.array([[-1e-3, 0.0, 0.0]]), np.array([[np.nan, 0.0, 0.0]]),
                                 np.zeros((4, 2))])
def test_tone_map_rejects_bad_input(bad):
    with pytest.raises(ValueError, match="hdr"):
        tone_map(bad)


def test_to_uint8_rounds_to_nearest_and_clips():
    codes = np.arange(256)
    assert_array_equal(to_uint8(codes / 255.0), codes)
    assert_array_equal(to_uint8((codes[:-1] + 0.49) / 255.0), codes[:-1])
    assert_array_equal(to_uint8((codes[:-1] + 0.51) / 255.0), codes[:-1] + 1)
    assert_array_equal(to_uint8(np.array([-0.5, 1.5])), [0, 255])
    assert to_uint8(np.zeros(3)).dtype == np.uint8


@pytest.mark.parametrize("level", [100.3, 37.5, 200.8])
def test_dither_keeps_the_mean(level):
    flat = np.full((256, 256), level / 255.0)
    dithered = to_uint8(flat, dither=True, seed=3).astype(float)
    # TPDF dither is unbiased; the mean of 65536 pixels has a standard error of 0.5 / 256 ~ 0.002 LSB,
    # so 0.5 LSB (the bias of plain rounding can reach it) is a very loose bound.
    assert abs(dithered.mean() - level) < 0.5
    assert abs(dithered.mean() - level) < abs(np.round(level) - level) + 0.02
    # Each pixel moves by the +-1 LSB noise plus rounding: strictly less than 1.5 LSB.
    assert np.abs(dithered - level).max() < 1.5
    assert_array_equal(to_uint8(flat, dither=True, seed=3), to_uint8(flat, dither=True, seed=3))
    # the noise drawn once (dither_noise) for several images: the same codes as its seed's
    assert_array_equal(to_uint8(flat, dither=True, noise=dither_noise(flat.shape, 3)),
                       to_uint8(flat, dither=True, seed=3))
    with pytest.raises(ValueError, match="noise must have the display's shape"):
        to_uint8(flat, dither=True, noise=dither_noise((3, 256), 3))


def test_dither_breaks_the_banding_of_a_smooth_gradient():
    gradient = np.linspace(0.40, 0.42, 512)          # 5 code values over 512 columns: wide bands
    image = np.broadcast_to(gradient, (256, 512))
    plain = to_uint8(image).astype(int)
    dithered = to_uint8(image, dither=True).astype(int)
    # Plain rounding: neighbours differ by 0 or 1 (the band edges) and each column is one code value.
    assert set(np.unique(np.diff(plain, axis=1))) == {0, 1}
    assert len(np.unique(np.diff(dithered, axis=1))) >= 4
    # Local (column) means follow the gradient: plain rounding errs by up to 1/2 LSB; with dither the
    # error is the mean of 256 noise samples of std 0.5 LSB: std 0.03, max over 512 columns ~ 0.12.
    assert np.abs(plain.mean(axis=0) - 255 * gradient).max() > 0.45
    assert np.abs(dithered.mean(axis=0) - 255 * gradient).max() < 0.25


def test_luminance_weights():
    # Exact: the weights themselves, one product and a sum of zeros.
    assert_allclose(luminance(np.eye(3)), [0.2126, 0.7152, 0.0722], rtol=0, atol=0)
    assert_allclose(luminance(np.ones((2, 2, 3))), 1.0, rtol=1e-15)   # 0.2126+0.7152+0.0722 rounds


# compare_frames -------------------------------------------------------------------------------------

def test_identical_frames_give_zero():
    frame = _sky()
    result = compare_frames(frame, frame.copy())
    for key in ("rmse", "rmse_relative", "median_rel", "p95_rel", "max_rel", "mean_delta_e"):
        assert result[key] == 0.0, key
    json.dumps(result, allow_nan=False)


def test_uniformly_brighter_frame():
    reference = _sky()
    test = 1.1 * reference
    result = compare_frames(reference, test)
    # Every pixel's error is 0.1 up to the rounding of 1.1 * x and of the luminance sums (~1e-16).
    for key in ("median_rel", "p95_rel", "max_rel"):
        assert abs(result[key] - 0.1) < 1e-12, key
    rmse = np.sqrt(np.mean((0.1 * reference) ** 2))
    mean_y = np.mean(0.2126 * reference[..., 0] + 0.7152 * reference[..., 1] + 0.0722 * reference[..., 2])
    # Same sums in another order: rounding only.
    assert_allclose(result["rmse"], rmse, rtol=1e-12)
    assert_allclose(result["rmse_relative"], rmse / mean_y, rtol=1e-12)
    assert result["mean_delta_e"] > 0.1
    assert result["pixels"] == reference.shape[0] * reference.shape[1]


def test_mean_delta_e_of_grey_frames_is_the_lightness_difference():
    reference = np.full((4, 5, 3), 0.3)
    test = np.full((4, 5, 3), 0.4)

    def lightness(hdr):                              # grey: L* from Y = 1 - exp(-hdr), a* = b* = 0
        return 116.0 * np.cbrt(1.0 - np.exp(-hdr)) - 16.0

    result = compare_frames(reference, test, exposure=1.0)
    # Grey maps to a multiple of the white point; the gamma round trip (x^(1/2.2))^2.2 costs ulps.
    assert_allclose(result["mean_delta_e"], lightness(0.4) - lightness(0.3), rtol=1e-9)
    doubled = compare_frames(reference, test, exposure=2.0)
    assert_allclose(doubled["mean_delta_e"], lightness(0.8) - lightness(0.6), rtol=1e-9)


def test_invalid_pixels_do_not_count():
    reference = _sky()
    valid = np.ones(reference.shape[:2], dtype=bool)
    valid[:, :5] = False
    test = reference.copy()
    test[:, :5] = np.nan                             # garbage outside the image circle
    reference_garbage = reference.copy()
    reference_garbage[:, :5] = -7.0
    result = compare_frames(reference_garbage, test, valid)
    assert result["max_rel"] == 0.0 and result["rmse"] == 0.0
    error = relative_error_map(reference, 2.0 * reference, valid)
    assert not np.isnan(error).any()
    assert_array_equal(error[:, :5], 0.0)
    assert_allclose(error[:, 5:], 1.0, rtol=1e-13)   # rounding of 2x and the luminance sums


def test_floor_for_black_pixels_and_black_frames():
    reference = _sky()
    reference[:6] = 0.0                              # black ground
    test = reference.copy()
    test[:6] = 1e-6
    error = relative_error_map(reference, test)
    floor = 1e-3 * np.percentile(luminance(reference), 99)
    # Black pixels are measured against the floor: |dY| / floor, with dY = 1e-6 (Y of grey = value).
    assert_allclose(error[:6], 1e-6 / floor, rtol=1e-9)
    assert_array_equal(error[6:], 0.0)
    result = compare_frames(reference, test)
    assert_allclose(result["floor"], floor, rtol=1e-15)
    json.dumps(result, allow_nan=False)
    night = compare_frames(np.zeros((3, 3, 3)), np.full((3, 3, 3), 1e-9))
    assert night["floor"] == BLACK_FRAME_FLOOR
    assert np.isfinite(night["max_rel"]) and np.isfinite(night["rmse_relative"])
    json.dumps(night, allow_nan=False)


def test_compare_frames_returns_the_error_map_it_took_its_statistics_of():
    """return_error_map: the map is relative_error_map's, bit for bit (the animation's third panel draws it,
    computed once with the statistics), zero on invalid pixels, and the numbers are the same as without it."""
    reference = _sky()
    test = reference * np.linspace(0.9, 1.2, reference.shape[1])[None, :, None]
    valid = np.ones(reference.shape[:2], dtype=bool)
    valid[:, :3] = False
    numbers, error = compare_frames(reference, test, valid, return_error_map=True)
    assert_array_equal(error, relative_error_map(reference, test, valid))
    assert numbers == compare_frames(reference, test, valid)
    assert error[:, :3].max() == 0.0 and numbers["max_rel"] == error.max() > 0.1


def test_frame_comparison_takes_the_means_of_mean_luminance_with_the_numbers():
    """frame_comparison: compare_frames' numbers and error map, and both frames' means over the valid
    pixels bit for bit mean_luminance's (an animation's temporal jumps read them from it), whatever the
    invalid pixels hold."""
    reference = _sky()
    test = reference * np.linspace(0.8, 1.3, reference.shape[1])[None, :, None]
    valid = np.ones(reference.shape[:2], dtype=bool)
    valid[2:5, 7:] = False
    reference[~valid] = np.nan
    compared = frame_comparison(reference, test, valid)
    numbers, error = compare_frames(reference, test, valid, return_error_map=True)
    assert compared.numbers == numbers
    assert_array_equal(compared.error_map, error)
    assert compared.mean_luminance == (mean_luminance(reference[None], valid)[0], mean_luminance(test[None], valid)[0])
    assert compared.mean_luminance[1] > compared.mean_luminance[0] > 0


def test_compare_frames_rejects_bad_input():
    frame = _sky()
    with pytest.raises(ValueError, match="differ in shape"):
        compare_frames(frame, frame[:-1])
    bad = frame.copy()
    bad[3, 3, 1] = np.nan
    with pytest.raises(ValueError, match="test"):
        compare_frames(frame, bad)
    with pytest.raises(ValueError, match="reference"):
        compare_frames(-frame, frame)
    with pytest.raises(TypeError, match="valid"):
        compare_frames(frame, frame, valid=np.ones(frame.shape[:2]))
    with pytest.raises(ValueError, match="no pixel"):
        compare_frames(frame, frame, valid=np.zeros(frame.shape[:2], dtype=bool))


@pytest.mark.parametrize("value, message", [(np.nan, "test contains 1 NaN or infinite values on valid pixels"),
                                            (np.inf, "test contains 1 NaN or infinite values on valid pixels"),
                                            (-np.inf, "test contains 1 NaN or infinite values on valid pixels"),
                                            (-0.25, r"test contains negative values on valid pixels \(minimum -0.25\)"),
                                            (1e308, r"test contains values above 1e\+100 on valid pixels \(maximum "
                                                    r"1e\+308\): their squares overflow the metrics")])
def test_bad_values_count_on_valid_pixels_only(value, message):
    """One bad value on a valid pixel is refused with its count or the minimum; the same value on an
    invalid pixel (outside the image circle) is zeroed and never counts."""
    frame = _sky()
    valid = np.ones(frame.shape[:2], dtype=bool)
    valid[0, 0] = False
    bad = frame.copy()
    bad[3, 3, 1] = value
    with pytest.raises(ValueError, match=f"^{message}$"):
        compare_frames(frame, bad, valid=valid)
    outside = frame.copy()
    outside[0, 0, 1] = value
    assert compare_frames(frame, outside, valid=valid)["p95_rel"] == compare_frames(frame, frame, valid=valid)["p95_rel"]


def test_largest_allowed_values_give_finite_metrics():
    """Frames at MAX_HDR_VALUE (1e100) everywhere give finite metrics, equal to those of the same frames
    scaled to 1 where the metrics are scale-free; at 1e308 the RMSE was NaN (inf / inf) before the limit."""
    from clsky.anim.metrics import MAX_HDR_VALUE

    reference, test = _sky(), _sky() * 1.1
    scale = MAX_HDR_VALUE / max(reference.max(), test.max())
    big = compare_frames(reference * scale, test * scale)
    small = compare_frames(reference, test)
    assert all(np.isfinite(value) for value in big.values() if isinstance(value, float))
    for name in ("rmse_relative", "median_rel", "p95_rel", "max_rel"):
        # each a ratio of sums or of values that the scale multiplies alike: equal to rounding (1e-12)
        assert big[name] == pytest.approx(small[name], rel=1e-12)


# Colour science -------------------------------------------------------------------------------------

def test_srgb_matrix_rounds_to_the_printed_iec_matrix():
    printed = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    # IEC 61966-2-1 prints 4 decimals: the derived matrix must round to it (|difference| <= 0.5e-4).
    assert np.abs(SRGB_TO_XYZ - printed).max() <= 0.5e-4
    assert_allclose(D65_WHITE_XYZ, [0.95046, 1.0, 1.08906], atol=1e-5)   # the usual 5-decimal D65


def test_lab_of_white_and_grey():
    # White maps to the white point by construction: rounding only (~1e-14).
    assert_allclose(xyz_to_lab(linear_srgb_to_xyz([1.0, 1.0, 1.0])), [100.0, 0.0, 0.0], atol=1e-6)
    # 18 % grey: L* = 116 * 0.18^(1/3) - 16 = 49.496; a*, b* vanish up to rounding.
    assert_allclose(xyz_to_lab(linear_srgb_to_xyz([0.18] * 3)), [116 * 0.18 ** (1 / 3) - 16, 0, 0],
                    atol=1e-9)
    # Dark values use the linear segment: Y = 0.001 -> L* = 903.3 Y (CIE 15 kappa = (29/3)^3).
    assert_allclose(xyz_to_lab(linear_srgb_to_xyz([0.001] * 3))[0], (29 / 3) ** 3 * 0.001, rtol=1e-9)


@pytest.mark.parametrize("rgb, published", [
    ((1.0, 0.0, 0.0), (53.24, 80.09, 67.20)),
    ((0.0, 0.0, 1.0), (32.30, 79.19, -107.86)),
])
def test_lab_of_srgb_primaries(rgb, published):
    lab = xyz_to_lab(linear_srgb_to_xyz(rgb))
    # Published values (e.g. B. Lindbloom's calculator) are rounded to 2 decimals (+-0.005); the
    # matrices they use (7-digit vs derived from the chromaticities) differ by < 0.005 in a*, b*.
    assert_allclose(lab, published, atol=0.01)


def test_display_to_lab_decodes_gamma_2_2():
    display = np.array([[1.0, 0.0, 0.0], [0.5, 0.5, 0.5]])
    lab = display_to_lab(display)
    # Red: the gamma does nothing to 0 and 1. Grey: Y = 0.5^2.2 exactly up to the power's rounding.
    assert_allclose(lab[0], xyz_to_lab(linear_srgb_to_xyz([1.0, 0.0, 0.0])), atol=1e-12)
    assert_allclose(lab[1, 0], 116 * np.cbrt(0.5 ** 2.2) - 16, rtol=1e-12)
    assert_allclose(delta_e_cie76(lab[0], lab[0]), 0.0, atol=0)


# Images ---------------------------------------------------------------------------------------------

def test_error_image_shape_colours_and_legend():
    height, width = 60, 80
    error = np.zeros((height, width))
    error[:, 40:] = 0.1
    error[:, 70:] = 0.5                               # beyond vmax: saturates
    valid = np.ones((height, width), dtype=bool)
    valid[:10, :10] = False
    image = error_image(error, valid, vmax=0.1)
    assert image.dtype == np.uint8 and image.shape[0] == height and image.shape[2] == 3
    assert image.shape[1] > width + 30                # a legend panel was appended
    assert_array_equal(image[0, 0], INVALID_COLOUR)
    assert not np.array_equal(image[30, 20], image[30, 50])   # colour of 0 and of vmax differ
    assert_array_equal(image[30, 50], image[30, 75])
    assert_array_equal(image[30, 20], colormap_viridis(0.0))
    legend = image[:, width:].reshape(-1, 3)
    background = legend[0]
    assert (np.any(legend != background, axis=1)).sum() > 200    # bar + text drawn
    bright = np.all(image[:12, width:] > 200, axis=-1)          # the title's white text at the top
    assert bright.sum() > 20
    plain = error_image(error, valid, legend=False)
    assert plain.shape == (height, width, 3)
    assert_array_equal(plain, image[:, :width])


def test_error_image_rejects_bad_input():
    with pytest.raises(ValueError, match="vmax"):
        error_image(np.zeros((5, 5)), vmax=0.0)
    with pytest.raises(ValueError, match="error_map"):
        error_image(np.full((5, 5), np.nan))


def test_colormap_is_monotonic_in_lightness():
    colours = colormap_viridis(np.linspace(0.0, 1.0, 64)) / 255.0
    lightness = xyz_to_lab(linear_srgb_to_xyz(colours ** 2.2))[:, 0]
    assert np.all(np.diff(lightness) > 0)


def test_composite_shape_gutters_and_labels():
    panels = [np.full((20, width, 3), 200, np.uint8) for width in (30, 40, 50)]
    result = composite(panels, ["table", "ray march", "error"])
    assert result.shape == (20, 30 + 40 + 50 + 2 * 4, 3) and result.dtype == np.uint8
    assert np.all(result[:, 30:34] < 40) and np.all(result[:, 74:78] < 40)   # dark gutters
    assert np.any(result[:12, :30] != 200)                                    # a label was drawn
    assert np.all(result[15:, :30] == 200)                                    # and only at the top
    with pytest.raises(ValueError, match="height"):
        composite([panels[0], np.zeros((21, 5, 3), np.uint8)], ["a", "b"])
    with pytest.raises(ValueError, match="labels"):
        composite(panels, ["a"])


def test_composite_labels_stay_inside_their_panels():
    """A label wider than its panel ran over the gutter into the next panel (64 pixels: 'sky-view map'),
    and a 16-pixel frame was all label: a label is cut to the letters that fit, ending in '.', and left
    out where not two fit; a panel's pixels beyond the label's width are its own."""
    for side, drawn in ((16, False), (24, True), (64, True), (128, True)):
        panels = [np.full((side, side, 3), 200, np.uint8) for _ in range(2)]
        result = composite(panels, ["sky-view map", "table lookup"])
        assert np.any(result[:, :side] != 200) == drawn, side
        assert np.all(result[:, side:side + 4] < 40), side                   # the gutter is untouched
    assert np.all(composite([np.full((64, 64, 3), 200, np.uint8)], ["sky-view map " * 4])[:, 62:] == 200)


# Temporal -------------------------------------------------------------------------------------------

def test_temporal_jumps_find_an_injected_jump():
    frames = 24
    reference = 2.0 * np.exp(-0.3 * np.arange(frames))   # a darkening twilight: smooth in time
    table = reference * 1.02
    table[15:] *= 0.85                                   # a step when the sun crosses a table node
    result = temporal_jumps(table, reference)
    assert result["worst_frames"][0] == 15
    assert result["excess"][0] == 0.0 and result["table_jumps"].shape == (frames,)
    # Away from the step both renders jump alike: the constant factor cancels (rounding only).
    assert np.abs(np.delete(result["excess"], 15)).max() < 1e-12
    # Excess at the step: (m14 - 0.85 m15) / m14 - (m14 - m15) / m14 = 0.15 m15 / m14.
    assert_allclose(result["excess"][15], 0.15 * np.exp(-0.3), rtol=1e-12)


def test_temporal_jumps_on_frames_and_per_pixel():
    frames, height, width = 10, 6, 8
    scale = np.linspace(1.0, 0.6, frames)[:, None, None, None]
    reference = scale * _sky(height, width)[None]
    table = reference.copy()
    table[6:, :, : width // 2] *= 1.2                  # half the sky brightens at frame 6 ...
    table[6:, :, width // 2:] *= 0.8                   # ... the other half darkens
    by_mean = temporal_jumps(table, reference)
    by_pixel = temporal_jumps(table, reference, per_pixel=True)
    assert by_pixel["worst_frames"][0] == 6
    # The mean sees only what does not cancel; the per-pixel change sees the whole 20 % step.
    assert by_pixel["excess"][6] > 0.1 > abs(by_mean["excess"][6])
    changes = frame_changes(reference)
    assert changes[0] == 0.0
    # The reference scales uniformly: every pixel changes by 1 - s_k / s_(k-1) (rounding only).
    expected = 1.0 - scale[1:, 0, 0, 0] / scale[:-1, 0, 0, 0]
    assert_allclose(changes[1:], expected, rtol=1e-12)
    with pytest.raises(ValueError, match="per_pixel"):
        temporal_jumps(table[:, 0, 0, 0], reference[:, 0, 0, 0], per_pixel=True)


def test_display_floor_is_half_a_code_value():
    floor = display_floor(1.0)
    # Tone mapping the floor gives 0.5 / 255 up to the rounding of log1p and the power.
    assert_allclose(tone_map(np.full(3, floor))[0] * 255, 0.5, rtol=1e-12)
    assert_allclose(display_floor(4.0), floor / 4.0, rtol=1e-15)


def test_compare_frames_takes_the_display_values_of_whole_frames():
    """display=(reference, test) display-linear frames (computed once with the 8-bit frames) gives the
    same numbers, bit for bit, as the display callable applied to the valid pixels; a pair of the wrong
    shape is refused."""
    rng = np.random.default_rng(5)
    reference = rng.random((6, 7, 3)) * 3.0
    test = reference * (1.0 + 0.1 * rng.standard_normal((6, 7, 1)))
    valid = rng.random((6, 7)) > 0.3

    def display(pixels):
        return np.clip(pixels, 0.0, 1.0) ** 1.3

    by_callable = compare_frames(reference, np.abs(test), valid, display=display)
    by_frames = compare_frames(reference, np.abs(test), valid, display=(display(reference), display(np.abs(test))))
    assert by_frames == by_callable and by_frames["mean_delta_e"] > 0
    with pytest.raises(ValueError, match="display must be"):
        compare_frames(reference, np.abs(test), valid, display=(display(reference)[:3], display(np.abs(test))))


@pytest.mark.parametrize("call, message", [
    (lambda: metrics.display_floor(1e-320), r"^exposure must be large enough for a finite floor"),   # inf: no jump
    (lambda: metrics.relative_jumps([1.0, 2.0], None), r"^floor must be a finite number > 0, got None"),
    (lambda: metrics.temporal_jumps(np.ones(3), np.ones(3), worst=-1), r"^worst must be an integer in \[0, "),
    (lambda: metrics.temporal_jumps(np.ones(3), np.ones(3), worst=2.5), r"^worst must be an integer in \[0, "),
    (lambda: tonemap.to_uint8(np.zeros(4), dither="no"), r"^dither must be True or False, got 'no'"),   # dithered
    (lambda: tonemap.to_uint8(np.zeros(4), dither=True, seed=-1), r"^seed must be an integer in \[0, "),
])
def test_metric_and_quantiser_arguments_are_refused_by_name(call, message):
    """A probe's: an infinite floor made every jump 0, worst=-1 and 2.5 were taken, dither='no' dithered,
    and a seed of -1 was NumPy's SeedSequence error."""
    with pytest.raises(ValueError, match=message):
        call()
