"""Parameter checks shared by the animation modules: ValueError (:class:`clsky.errors.ParameterError`)
naming the parameter and its range; NumPy scalars are numbers too."""

from __future__ import annotations

import math

from clsky.errors import ParameterError, is_integer, is_real_number


def check_real(name, value, low=-math.inf, high=math.inf, low_open=False):
    """``value`` as a float if it is a finite real number in [low, high] (or (low, high]); bools,
    strings and NaN are refused."""
    bounded = (low, high) != (-math.inf, math.inf)
    valid = f"a finite number in {'(' if low_open else '['}{low:g}, {high:g}]" if bounded else "a finite number"
    if (not is_real_number(value) or not math.isfinite(value)
            or not ((low < value) if low_open else (low <= value)) or not value <= high):
        raise ParameterError(name, valid, value)
    return float(value)


def check_integer(name, value, low, high):
    """``value`` as an int if it is an integer (Python's or NumPy's, not a bool) in [low, high]."""
    if not is_integer(value) or not low <= value <= high:
        raise ParameterError(name, f"an integer in [{low}, {high}]", value)
    return int(value)
