"""Validation errors that know which parameter they are about, and short numbers for messages.

A :class:`ParameterError` is a ``ValueError`` that carries the parameter's name (``field``), the item
of a tuple parameter (``index``), what is valid and what was given. The library's message names the
Python parameter (``size[0] must be ...``); a command line rewords it with :meth:`ParameterError.reworded`
to name the option the user typed (``--size W must be ...``).
"""

from __future__ import annotations

import dataclasses
import decimal
import importlib
import math
import numbers

import numpy as np

__all__ = ["ParameterError", "NumericalError", "short", "counted", "is_real_number", "is_finite_real",
           "is_integer", "as_real_array", "check_range", "check_integer", "check_real", "check_choice",
           "check_instance", "check_flag", "require_extra", "ordered_items", "dataclass_from_dict"]

#: Longest text of a value echoed in a message.
_MAX_ECHO = 60


#: Most bits of an integer that :func:`short` writes whole where %g would round it (64-bit bounds take 64).
_MAX_INTEGER_BITS = 100


def short(value) -> str:
    """``value`` as a short text for a message: numbers with at most 6 significant digits where that is
    the number itself (a 300-digit integer prints as ``1e+300``), else every digit it takes (a value just
    outside a range must not print as its bound: ``1.0000001``, not ``1``), other values by ``repr``, cut
    to 60 characters.

    Examples
    --------
    >>> short(10**300), short(4096), short(0.25), short(1.0000001), short(0.1 + 0.2), short("a")
    ('1e+300', '4096', '0.25', '1.0000001', '0.30000000000000004', "'a'")
    >>> short(2**64), short(10**17)                        # an integer whole where %g would round it
    ('18446744073709551616', '1e+17')
    """
    if isinstance(value, (bool, np.bool_)):
        return repr(bool(value))
    if isinstance(value, numbers.Integral):
        value = int(value)
        if abs(value) < 10**7:
            return str(value)
        try:
            text = f"{float(value):g}"
        except OverflowError:                   # beyond float: its order of magnitude
            text = None
        if text is not None and int(float(text)) == value:
            return text
        if abs(value).bit_length() <= _MAX_INTEGER_BITS:   # 2**64 is not 1.84467e+19, the bound 2**64 - 1
            return str(value)
        if abs(value).bit_length() > 14000:     # beyond str()'s 4300 digits: from its logarithm
            exponent = math.floor(math.log10(abs(value)))
            mantissa = f"{10 ** (math.log10(abs(value)) - exponent):.5g}"
            return f"{'-' if value < 0 else ''}{mantissa}e+{exponent}"
        mantissa, exponent = format(decimal.Decimal(value), ".5e").split("e")     # 10**400 - 1 is 1e+400
        return f"{mantissa.rstrip('0').rstrip('.')}e{exponent}"
    if isinstance(value, numbers.Real):
        text = f"{float(value):g}"
        exact = not math.isfinite(value) or float(text) == float(value)
        return text if exact else str(value)      # a float's or NumPy float's shortest exact digits
    if isinstance(value, (tuple, list)) and len(value) <= 8:
        items = ", ".join(short(v) for v in value)
        return f"({items})" if isinstance(value, tuple) else f"[{items}]"
    text = repr(value)
    return text if len(text) <= _MAX_ECHO else text[:_MAX_ECHO - 3] + "..."


def counted(count: int, noun: str) -> str:
    """``count`` and ``noun``, plural unless the count is one, for a message or summary.

    Examples
    --------
    >>> counted(1, "order"), counted(7, "order"), counted(0, "stale frame file")
    ('1 order', '7 orders', '0 stale frame files')
    """
    return f"{count} {noun}{'s' * (count != 1)}"


def is_real_number(value) -> bool:
    """A real number: Python's or NumPy's int or float, not a bool, a string or a complex."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def is_finite_real(value) -> bool:
    """A real number (:func:`is_real_number`) that is finite: an integer too large for a float (``10**400``)
    is not, nor NaN or an infinity."""
    if not is_real_number(value):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:                       # an int beyond float's range
        return False


def is_integer(value) -> bool:
    """An integer: Python's or NumPy's, not a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


#: How the checks below begin what is valid for an optional parameter (None valid too).
_OPTIONAL = "None or "


def as_real_array(name, value, valid="real numbers"):
    """``value`` as a float64 array if it holds real numbers (ints or floats, Python's or NumPy's);
    ParameterError naming ``name`` otherwise (strings, objects, complex values, bools)."""
    try:
        array = np.asarray(value)
        if array.dtype.kind not in "iuf":
            raise TypeError(array.dtype)
        return array.astype(np.float64)
    except (TypeError, ValueError):
        raise ParameterError(name, valid, value) from None


def check_range(name, value, low, high):
    """(a, b) floats from two real numbers (NumPy's too; a tuple, list or array) with low <= a <= b <= high:
    a range of values, such as a sun path's elevations; ParameterError naming ``name`` otherwise."""
    valid = f"two numbers low <= high in [{low:g}, {high:g}]"
    items = tuple(value) if isinstance(value, (tuple, list, np.ndarray)) else ()
    if len(items) != 2 or not all(is_finite_real(v) for v in items):
        raise ParameterError(name, valid, value)
    a, b = (float(v) for v in items)
    if not low <= a <= b <= high:
        raise ParameterError(name, valid, value)
    return a, b


def check_integer(name, value, low, high, index=None, optional=False):
    """``value`` as an int if it is an integer (Python's or NumPy's, not a bool) in [low, high].

    Parameters
    ----------
    name : str
        The parameter's name, for the message.
    value : object
    low, high : int
        The valid range, both ends included.
    index : int, optional
        The item of a tuple parameter (``size[0]``).
    optional : bool
        None is valid too (and returned).

    Raises
    ------
    ParameterError
        ``'{name} must be [None or ]an integer in [low, high], got {value}'``.

    Examples
    --------
    >>> check_integer("steps", np.int64(30), 1, 4096)
    30
    >>> check_integer("size", 1, 2, 4096, index=0)
    Traceback (most recent call last):
    ...
    clsky.errors.ParameterError: size[0] must be an integer in [2, 4096], got 1
    """
    if optional and value is None:
        return None
    if not is_integer(value) or not low <= value <= high:
        raise ParameterError(name, (_OPTIONAL if optional else "") + f"an integer in [{low}, {high}]", value, index,
                             typed=not is_integer(value))
    return int(value)


def check_real(name, value, low=-math.inf, high=math.inf, low_open=False, unit="", optional=False):
    """``value`` as a float if it is a finite real number (Python's or NumPy's, not a bool or a string)
    in [low, high], or in (low, high] with ``low_open``.

    Parameters
    ----------
    name : str
        The parameter's name, for the message.
    value : object
    low, high : float
        The valid range (default: any finite number).
    low_open : bool
        Exclude ``low``.
    unit : str
        Appended to the range in the message (e.g. ``" degrees"``).
    optional : bool
        None is valid too (and returned).

    Raises
    ------
    ParameterError
        ``'{name} must be [None or ]a number in [low, high]{unit}, got {value}'`` (``a finite number``
        without bounds, ``a finite number >= low`` (or ``> low``, ``<= high``) with one); NaN and infinities are
        refused.

    Examples
    --------
    >>> check_real("fov_deg", 0.0, 0.0, 179.0, low_open=True, unit=" degrees")
    Traceback (most recent call last):
    ...
    clsky.errors.ParameterError: fov_deg must be a number in (0, 179] degrees, got 0
    """
    if optional and value is None:
        return None
    if (not is_finite_real(value) or not (low < value if low_open else low <= value)
            or not value <= high):
        if math.isinf(low) and math.isinf(high):
            valid = f"a finite number{unit}"
        elif math.isinf(high):          # one-sided: "(0, inf]" read as if inf were valid, and it is refused
            valid = f"a finite number {'>' if low_open else '>='} {low:g}{unit}"
        elif math.isinf(low):
            valid = f"a finite number <= {high:g}{unit}"
        else:
            valid = f"a number in {'(' if low_open else '['}{low:g}, {high:g}]{unit}"
        raise ParameterError(name, (_OPTIONAL if optional else "") + valid, value)
    return float(value)


def check_choice(name, value, choices, optional=False):
    """``value`` if it is one of the strings ``choices`` (listed in their order in the message).

    Raises
    ------
    ParameterError
        ``'{name} must be [None or ]one of [...], got {value}'``.

    Examples
    --------
    >>> check_choice("mapping", "cubic", ("linear", "nonlinear"))
    Traceback (most recent call last):
    ...
    clsky.errors.ParameterError: mapping must be one of ['linear', 'nonlinear'], got 'cubic'
    """
    if optional and value is None:
        return None
    if not isinstance(value, str) or value not in choices:
        raise ParameterError(name, (_OPTIONAL if optional else "") + f"one of {list(choices)}", value)
    return value


def check_instance(name, value, types, valid, optional=False):
    """``value`` if it is an instance of ``types`` (a class or a tuple of them), or None with ``optional``.

    Parameters
    ----------
    name : str
        The parameter's name, for the message.
    value : object
    types : type or tuple of types
    valid : str
        What is valid, in words, e.g. ``'a TableSettings (the sky-view map's sizes)'``.
    optional : bool
        None is valid too (and returned); ``valid`` should say what None means.

    Raises
    ------
    ParameterError
        ``'{name} must be {valid}, got {value} ({its type})'``.

    Examples
    --------
    >>> check_instance("settings", "x", dict, "a dict of settings")
    Traceback (most recent call last):
    ...
    clsky.errors.ParameterError: settings must be a dict of settings, got 'x' (str)
    """
    if (optional and value is None) or isinstance(value, types):
        return value
    raise ParameterError(name, valid, value, typed=True)


def check_flag(name, value):
    """``value`` as a bool if it is one (Python's or NumPy's); ParameterError naming ``name`` otherwise: a
    string such as ``'no'`` would be true.

    >>> check_flag("force", np.True_)
    True
    """
    return bool(check_instance(name, value, (bool, np.bool_), "True or False"))


def require_extra(module: str, purpose: str, install: str):
    """The module ``module`` imported, or ImportError saying what needs it and how to install it.

    Optional dependencies (Pillow, matplotlib, OpenEXR, imageio-ffmpeg) are imported where used, so that
    clsky's core runs without them; callers check them here *before* any work, so that a missing extra
    costs the user a one-line message, not a computation.

    >>> require_extra("math", "nothing", "pip install nothing").pi > 3
    True
    >>> require_extra("no_such_module_xyz", "the plots", "pip install 'clsky[bench]'")
    Traceback (most recent call last):
    ...
    ImportError: the plots need no_such_module_xyz: pip install 'clsky[bench]'
    """
    try:
        return importlib.import_module(module)
    except ImportError as error:
        raise ImportError(f"{purpose} need {module}: {install}") from error


class ParameterError(ValueError):
    """A parameter outside what is valid: ``'{field}[{index}] must be {valid}, got {value}'``.

    Parameters
    ----------
    field : str
        The parameter's (or dataclass field's) name.
    valid : str
        What is valid, e.g. ``'an integer in [2, 4096]'``.
    value : object
        What was given (printed short, :func:`short`).
    index : int, optional
        The item of a tuple parameter.
    typed : bool
        Name the value's type after it (``got 5 (float)`` where an integer is valid, ``got 'x' (str)``).
    """

    def __init__(self, field, valid, value, index=None, typed=False):
        self.field, self.valid, self.value, self.index, self.typed = field, valid, value, index, typed
        super().__init__(f"{field if index is None else f'{field}[{index}]'} must be {valid}, got {self._given()}")

    def _given(self) -> str:
        return short(self.value) + (f" ({type(self.value).__name__})" if self.typed else "")

    def reworded(self, name: str) -> str:
        """The message with ``name``, what the user typed (a command-line option, a scene file's key), in
        place of the parameter's name. An optional parameter's "None or " is left out there: None is what
        leaving the option or key out gives, not a value one can type."""
        valid = self.valid[len(_OPTIONAL):] if self.valid.startswith(_OPTIONAL) else self.valid
        return f"{name} must be {valid}, got {self._given()}"


class NumericalError(ArithmeticError):
    """A computation gave non-finite values (NaN or infinity) where the inputs were valid: the result
    is refused rather than returned or saved."""


def ordered_items(value):
    """``value``'s items as a tuple if it is an ordered sequence (a tuple, a list, a 1D array), else None: a
    set gave its items in hash order ({4, 8, 6} became (8, 4, 6)), a dict its keys."""
    if isinstance(value, (tuple, list)) or (isinstance(value, np.ndarray) and value.ndim == 1):
        return tuple(value)
    return None


def dataclass_from_dict(cls, data, name: str, fields: str):
    """``cls(**data)`` for ``data``, a dict of the dataclass ``cls``'s fields (the inverse of its
    ``to_dict``); ValueError naming ``name`` for anything but a dict and ``fields`` for an unknown field
    (an atmosphere's and a table's settings read back from a file)."""
    check_instance(name, data, dict, "a dict")
    unknown = set(data) - {field.name for field in dataclasses.fields(cls)}
    if unknown:
        raise ValueError(f"unknown {fields}: {sorted(unknown)}")
    return cls(**data)
