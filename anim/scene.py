"""Scene files: a TOML scene for ``clsky animate --scene FILE`` and ``clsky render --scene FILE``.

A scene holds what a command line of ``clsky animate`` or ``clsky render`` sets, in five sections::

    [camera]  camera, size, fov_deg, heading_deg, pitch_deg, altitude, method, skyview_size
    [sky]     preset, mode, ground_albedo, ozone_column_du, error_budget, quality, table_size, samples,
              sampling, wavelengths
    [sun]     animate: frames, start_elevation_deg, max_elevation_deg, location, date, start_hour,
              end_hour, step_minutes; render: sun_elevation_deg, sun_azimuth_deg
    [display] tone_map, exposure, auto_exposure, white_balance, dither
    [output]  output; animate: fps, hdr, hdr_precision

Its keys are :class:`clsky.anim.animate.AnimationConfig`'s field names (``sun_elevation_deg`` and
``sun_azimuth_deg`` are ``clsky render``'s sun), with the same units and ranges. :data:`SCENE_KEYS` is
the one mapping of a key to its section and to the command-line option that sets it (its argparse
``dest``); the option's name, type and choices come from the parser itself, and the ranges from
AnimationConfig's checks, so neither is written twice.

How a scene and a command line combine: the scene's values stand in for the options' defaults; an
option typed on the command line wins, and one line on stderr says so. A scene is checked whole before
any work: an unknown section or key, a wrong type or (through AnimationConfig) an out-of-range value is
one line naming the file and the key (``UsageError``, exit status 2).

``--print-scene`` writes the scene of a command line (:func:`scene_text`): every key set, so that
``--scene`` of that output reproduces the run exactly, whatever the defaults become. Every output
carries that text and clsky's version (:func:`output_metadata`): the metrics JSON, the PNG text chunks.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import math
import pathlib
import re
import sys

import clsky
from clsky._files import as_path, read_user_text
from clsky.errors import is_finite_real, is_integer, short
from clsky.cli import UsageError

if sys.version_info >= (3, 11):
    import tomllib
else:                                            # Python 3.10: the same parser, as a package
    import tomli as tomllib

__all__ = ["SceneKey", "SCENE_KEYS", "SECTIONS", "track_given_options", "command_keys", "field_options",
           "load_scene", "apply_scene",
           "field_values", "scene_values", "scene_text", "output_metadata", "source_of", "METADATA_KEYS"]


@dataclasses.dataclass(frozen=True)
class SceneKey:
    """One scene key: ``[section] key``, set on the command line by the option of ``dest`` (item
    ``index`` of a two-value option such as ``--hours START END``; ``inverted`` for ``--no-dither``)."""

    section: str
    key: str
    dest: str
    index: int | None = None
    inverted: bool = False

    @property
    def name(self) -> str:
        return f"{self.section}.{self.key}"


def _keys(section, *items):
    return [SceneKey(section, *item) if isinstance(item, tuple) else SceneKey(section, item, item) for item in items]


#: Every scene key, in the order a printed scene lists them. A key belongs to the commands whose parser
#: has its ``dest``. The key is the AnimationConfig field (render's sun: its own two).
SCENE_KEYS = (
    _keys("camera", "camera", "size", ("fov_deg", "fov"), ("heading_deg", "heading"), ("pitch_deg", "pitch"),
          "altitude", "method", "skyview_size")
    + _keys("sky", "preset", "mode", "ground_albedo", "ozone_column_du", "error_budget", "quality", "table_size",
            "samples", "sampling", "wavelengths")
    + _keys("sun", "frames", ("start_elevation_deg", "start_elevation"), ("max_elevation_deg", "max_elevation"),
            "location", "date", ("start_hour", "hours", 0), ("end_hour", "hours", 1), "step_minutes",
            ("sun_elevation_deg", "sun_elevation"), ("sun_azimuth_deg", "sun_azimuth"))
    + _keys("display", "tone_map", "exposure", "auto_exposure", "white_balance", ("dither", "no_dither", None, True))
    + _keys("output", "output", "fps", "hdr", "hdr_precision")
)

SECTIONS = tuple(dict.fromkeys(key.section for key in SCENE_KEYS))

#: PNG text chunk / JSON member names of the metadata every output carries.
METADATA_KEYS = ("clsky_version", "scene")


class _GivenTracker(argparse.Action):
    """Mixin of :func:`track_given_options`: records the option string of each option typed."""

    def __call__(self, parser, namespace, values, option_string=None):
        given = dict(getattr(namespace, "given_options", None) or {})
        given[self.dest] = option_string
        namespace.given_options = given
        super().__call__(parser, namespace, values, option_string)


def track_given_options(parser):
    """Make ``parser`` record which options the command line types: after parsing, the namespace's
    ``given_options`` maps each typed option's dest to the option string (argparse calls an action only
    for an option typed, so a value equal to the default still counts as typed)."""
    for action in parser._actions:
        if action.option_strings and not isinstance(action, (argparse._HelpAction, argparse._VersionAction)):
            action.__class__ = type(f"Tracked{type(action).__name__}", (_GivenTracker, type(action)), {})
    parser.set_defaults(given_options={})


def _actions(parser):
    return {action.dest: action for action in parser._actions if action.option_strings}


def _long_option(action):
    """The first long option of ``action`` ('--output' of '-o', '--auto-exposure' of its '--no-' pair)."""
    return next((o for o in action.option_strings if o.startswith("--")), action.option_strings[0])


def _is_flag(action):
    return isinstance(action, (argparse._StoreTrueAction, argparse.BooleanOptionalAction))


def _option(action, key):
    """The option a user types for ``key`` ('--hours END' for an item)."""
    option = _long_option(action)
    if key.index is not None and isinstance(action.metavar, tuple):
        option += f" {action.metavar[key.index]}"
    return option


def command_parser(command):
    """The argparse parser of ``clsky <command>`` ('animate' or 'render')."""
    from clsky.cli import build_parser

    from .cli import register

    parser, _ = build_parser(extensions=(register,))
    return parser._subparsers._group_actions[0].choices[command]


def command_keys(parser):
    """The scene keys of a command (its parser, or its name 'animate' / 'render'):
    {name: (SceneKey, argparse action)}."""
    if isinstance(parser, str):
        parser = command_parser(parser)
    actions = _actions(parser)
    return {key.name: (key, actions[key.dest]) for key in SCENE_KEYS if key.dest in actions}


def field_options(parser):
    """{AnimationConfig field: the option a user types} of a command (:func:`command_keys`), or one
    option per item of a tuple field ('--table-size W', ...), for :func:`clsky.cli.option_message`."""
    options = {}
    for key, action in command_keys(parser).values():
        if key.index is None and isinstance(action.metavar, tuple):
            options[key.key] = tuple(f"{_long_option(action)} {name}" for name in action.metavar)
        else:
            options[key.key] = _option(action, key)
    return options


def _type_error(key, action, value):
    """None, or what ``value`` of TOML should have been for the option ``action`` of ``key``."""
    def is_number(v):          # TOML integers have any size: one beyond float's range is no number here
        return isinstance(v, float) or (is_integer(v) and is_finite_real(v))

    if _is_flag(action):
        return None if isinstance(value, bool) else "true or false"
    if key.key == "date":
        return None if isinstance(value, datetime.date) and not isinstance(value, datetime.datetime) else \
            "a TOML date (YYYY-MM-DD, unquoted)"
    if action.nargs not in (None, "?") and key.index is None:
        want = action.nargs
        item = "integers" if action.type is int else "numbers"
        ok = isinstance(value, list) and len(value) == want and all(
            (isinstance(v, int) and not isinstance(v, bool)) if action.type is int else is_number(v) for v in value)
        return None if ok else f"a list of {want} {item}" + _beyond_float(value)
    if action.type is int:
        return None if isinstance(value, int) and not isinstance(value, bool) else "an integer"
    if action.type is float:
        return None if is_number(value) else "a number" + _beyond_float(value)
    if action.choices is not None:
        return None if isinstance(value, str) else f"a string, one of {', '.join(map(str, action.choices))}"
    return None if isinstance(value, str) else "a string"


def _beyond_float(value):
    """' (...)' where ``value`` (a number or a list) holds an integer too large for a float, else ''."""
    numbers = value if isinstance(value, list) else [value]
    if any(is_integer(v) and not is_finite_real(v) for v in numbers):
        return " (of at most about 1.8e308 in size)"
    return ""


def _shown_value(value):
    """``value`` for a message: as TOML, but integers too large for a float in short form (1e+400)."""
    return short(value) if _beyond_float(value) else _toml_value(value)


def load_scene(path, parser):
    """The scene of the TOML file ``path`` for the command of ``parser``: {key name: value}.

    Raises
    ------
    UsageError
        One line naming the file: unreadable, not TOML, an unknown section or key (or one of the other
        command), or a value of the wrong type (ranges are AnimationConfig's, see :func:`apply_scene`).
    """
    try:
        path = as_path(path, "--scene")         # '' is no file name (pathlib reads it as '.')
    except ValueError as error:
        raise UsageError(str(error)) from None
    try:
        document = tomllib.loads(read_user_text(path))
    except OSError as error:
        raise UsageError(f"--scene: cannot read {path}: {error.strerror or error}") from None
    except UnicodeDecodeError:
        raise UsageError(f"--scene {path}: not a TOML file (not UTF-8 text)") from None
    except ValueError as error:        # TOMLDecodeError, or an integer of more than 4300 digits
        why = "a number of more than 4300 digits" if "integer string conversion" in str(error) else error
        raise UsageError(f"--scene {path}: not a valid TOML file: {why}") from None
    except RecursionError:
        raise UsageError(f"--scene {path}: not a valid TOML file: nested too deeply") from None
    keys = command_keys(parser)
    every = {key.name for key in SCENE_KEYS}
    values = {}
    for section, table in document.items():
        sections = ", ".join(f"[{s}]" for s in SECTIONS)
        if isinstance(table, list) and table and all(isinstance(item, dict) for item in table):
            raise UsageError(f"{path}: [[{section}]] makes an array of tables; a scene's keys go under one "
                             f"[{section}] section")
        if not isinstance(table, dict):
            raise UsageError(f"{path}: {section} = {_toml_value(table)} is outside a section (keys go under "
                             f"{sections})")
        if section not in SECTIONS:
            raise UsageError(f"{path}: unknown section [{section}] (valid: {sections})")
        for name, value in table.items():
            full = f"{section}.{name}"
            command = parser.prog.split()[-1]
            if full not in keys:
                valid = ", ".join(k.split(".", 1)[1] for k in keys if k.startswith(section + "."))
                other = f" (a key of clsky {'render' if command == 'animate' else 'animate'} only)" \
                    if full in every else ""
                raise UsageError(f"{path}: unknown key {full}{other}; valid keys of [{section}] for "
                                 f"clsky {command}: {valid}")
            key, action = keys[full]
            expected = _type_error(key, action, value)
            if expected is not None:
                raise UsageError(f"{path}: {full} must be {expected}, got {_shown_value(value)}")
            values[full] = value
    return values


def apply_scene(args, parser):
    """Put the scene of ``args.scene`` (if given) into ``args`` as the options' values, except the
    options typed on the command line: those win, and each says so in one line on stderr. Records
    ``args.scene_sources`` (dest -> 'FILE: section.key') for :func:`source_of`."""
    args.scene_sources = {}
    if getattr(args, "scene", None) is None:
        return args
    scene = load_scene(args.scene, parser)
    keys = command_keys(parser)
    given = getattr(args, "given_options", {}) or {}
    for name, value in scene.items():
        key, action = keys[name]
        if key.dest in given:
            typed = getattr(args, key.dest)
            typed = typed[key.index] if key.index is not None else typed
            shown = (not typed) if key.inverted else typed
            print(f"clsky: {given[key.dest]} {_shown(typed)} overrides {args.scene}'s {name} = "
                  f"{_toml_value(value)}" if not _is_flag(action) else
                  f"clsky: {given[key.dest]} overrides {args.scene}'s {name} = {_toml_value(value)}"
                  f" (now {_toml_value(shown)})", file=sys.stderr)
            continue
        if key.inverted:
            value = not value
        elif isinstance(value, list):
            value = list(value)
        if key.index is not None:
            items = list(getattr(args, key.dest))
            items[key.index] = float(value)
            value = items
        elif action.type is float and not isinstance(value, list):
            value = float(value)
        setattr(args, key.dest, value)
        args.scene_sources[key.dest if key.index is None else (key.dest, key.index)] = f"{args.scene}: {name}"
    return args


def _shown(value):
    """An option's typed value as the override's line shows it: numbers as :func:`clsky.errors.short` does
    (``--exposure 1.0000001`` was shown as '1', its default's bound), a list's items spaced."""
    if isinstance(value, (list, tuple)):
        return " ".join(map(_shown, value))
    return short(value) if isinstance(value, float) else str(value)


def source_of(args, field):
    """Where the value of AnimationConfig field (or render sun key) ``field`` came from, for messages:
    'FILE: section.key' when the scene set it, else None (the command line's option names it)."""
    sources = getattr(args, "scene_sources", {}) or {}
    for key in SCENE_KEYS:
        if key.key == field:
            found = sources.get(key.dest if key.index is None else (key.dest, key.index))
            if found is not None:
                return found
    return None


def field_values(args, parser):
    """{AnimationConfig field (or render sun key): value} of the parsed options, through
    :data:`SCENE_KEYS` (``--no-dither`` -> dither, ``--hours`` -> start_hour and end_hour)."""
    values = {}
    for key, action in command_keys(parser).values():
        value = getattr(args, key.dest)
        if key.index is not None:
            value = value[key.index]
        elif key.inverted:
            value = not value
        elif isinstance(value, list):
            value = tuple(value)
        values[key.key] = value
    return values


def scene_values(config, parser="animate", extra=None):
    """{key name: value} of the scene of ``config`` (an AnimationConfig) for a command (its parser or
    name, as in :func:`command_keys`); ``extra`` holds the keys that are not config fields (render's sun and output). Keys
    whose value is None (unset: the default applies) are left out."""
    extra = extra or {}
    values = {}
    for name, (key, _) in command_keys(parser).items():
        value = extra[key.key] if key.key in extra else getattr(config, key.key)
        if isinstance(value, pathlib.PurePath):
            value = str(value)
        if value is not None:
            values[name] = value
    return values


def _toml_value(value):
    """``value`` as a TOML value: booleans, integers, floats (repr: exact round trip), strings, dates
    and lists of those."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
        return repr(value)
    if isinstance(value, datetime.date):
        return value.isoformat()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):     # a table a scene wrongly holds, shown in messages as TOML (a repr before)
        keys = (k if re.fullmatch(r"[A-Za-z0-9_-]+", str(k)) else _toml_value(str(k)) for k in value)
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in zip(keys, value.values())) + "}"
    # a TOML basic string: JSON's escapes are TOML's, and TOML forbids DEL too (U+007F), which JSON leaves
    return json.dumps(str(value), ensure_ascii=False).replace("\x7f", "\\u007f")


def scene_text(values, command):
    """The TOML text of a scene (:func:`scene_values`), sections in :data:`SECTIONS` order."""
    lines = [f"# clsky {clsky.__version__} scene: clsky {command} --scene FILE"]
    for section in SECTIONS:
        items = [(name.split(".", 1)[1], value) for name, value in values.items() if name.startswith(section + ".")]
        if items:
            lines += ["", f"[{section}]"] + [f"{key} = {_toml_value(value)}" for key, value in items]
    return "\n".join(lines) + "\n"


def output_metadata(scene):
    """{'clsky_version': ..., 'scene': TOML text} carried by every output (PNG text chunks, JSON)."""
    return {"clsky_version": clsky.__version__, "scene": scene}
