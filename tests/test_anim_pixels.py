"""clsky.anim.pixels: the valid pixels of a frame by the mask's flat indices, the boolean index's values."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from clsky.anim.pixels import set_valid_pixels, valid_pixels


def _fisheye_mask(size):
    y, x = np.mgrid[0:size, 0:size]
    centre = (size - 1) / 2
    return (y - centre) ** 2 + (x - centre) ** 2 < (size / 2) ** 2


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.uint8])
@pytest.mark.parametrize("channels", [1, 3, 4])
def test_valid_pixels_are_the_boolean_index_bit_for_bit(dtype, channels):
    """Every value and its order the boolean index's, for contiguous and strided frames (a channel
    slice, a transposed frame) and a random mask."""
    rng = np.random.default_rng(channels)
    frame = (rng.random((37, 41, channels + 2)) * 200).astype(dtype)
    for view in (np.ascontiguousarray(frame[..., :channels]), frame[..., :channels],
                 frame.transpose(1, 0, 2)[..., 1:channels + 1]):
        mask = rng.random(view.shape[:2]) < 0.6
        expected, got = view[mask], valid_pixels(view, mask)
        assert got.dtype == expected.dtype and got.shape == expected.shape == (mask.sum(), channels)
        assert_array_equal(got, expected)


def test_set_valid_pixels_writes_what_the_boolean_index_writes():
    """In place, on a contiguous frame and on a strided view of one (whose rows are no view: the boolean
    index writes through), with a (n, C) array and a broadcast row."""
    rng = np.random.default_rng(3)
    mask = _fisheye_mask(64)
    for values in (rng.integers(0, 255, (int(mask.sum()), 3)).astype(np.uint8), np.array([1, 2, 3], np.uint8)):
        expected = np.zeros((64, 64, 3), np.uint8)
        expected[mask] = values
        got = np.zeros((64, 64, 3), np.uint8)
        set_valid_pixels(got, mask, values)
        assert_array_equal(got, expected)
        base = np.zeros((64, 64, 5), np.uint8)
        set_valid_pixels(base[..., 1:4], mask, values)
        assert_array_equal(base[..., 1:4], expected)
        assert not base[..., [0, 4]].any()


def test_shapes_that_do_not_pair_keep_numpys_behaviour():
    """A mask of another shape, or not bool, goes to NumPy's own index: its error or its result."""
    frame = np.zeros((4, 5, 3))
    with pytest.raises(IndexError):
        valid_pixels(frame, np.ones((5, 4), dtype=bool))
    with pytest.raises(IndexError):
        set_valid_pixels(frame, np.ones((5, 4), dtype=bool), 1.0)
    flat = np.arange(6.0)
    assert_array_equal(valid_pixels(flat, flat > 2), [3.0, 4.0, 5.0])
