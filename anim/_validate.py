"""Parameter checks shared by the animation modules: ValueError naming the parameter and its range."""

from __future__ import annotations

import math
import numbers

import numpy as np


def check_real(name, value, low=-math.inf, high=math.inf, low_open=False):
    """``value`` as a float if it is a finite real number in [low, high] (or (low, high]); bools,
    strings and NaN are refused."""
    bounded = (low, high) != (-math.inf, math.inf)
    valid = f"a finite number in {'(' if low_open else '['}{low:g}, {high:g}]" if bounded else "a finite number"
    if (isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real) or not math.isfinite(value)
            or not ((low < value) if low_open else (low <= value)) or not value <= high):
        raise ValueError(f"{name} must be {valid}, got {value!r}")
    return float(value)


def check_integer(name, value, low, high):
    """``value`` as an int if it is an integer (not a bool) in [low, high]."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not low <= value <= high:
        raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    return int(value)
