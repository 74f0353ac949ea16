"""Output files: checks before the work, unique temporaries, and sets of files that land together.

Every file clsky writes goes through :func:`atomic_write` or a :class:`StagedWrites` set: it is written
to a hidden temporary file with a unique name (created exclusively, as ``tempfile.mkstemp`` does) beside
its target, then renamed onto the target (``os.replace``, atomic on POSIX). Two writers of one target
never share a temporary, so the last rename wins and the target is always one writer's complete file.
:func:`check_output` finds, before any work, what would make a write fail: a target that exists
(without ``force``) or is a directory, a missing or non-directory parent, a parent where no file can be
created, a name too long for the file system.

Examples
--------
>>> import pathlib, tempfile
>>> directory = pathlib.Path(tempfile.mkdtemp())
>>> with StagedWrites() as staged:
...     staged.stage(directory / "a.txt").write_text("a")
...     staged.stage(directory / "b.txt").write_text("b")
1
1
>>> sorted(path.name for path in directory.iterdir())
['a.txt', 'b.txt']
"""

from __future__ import annotations

import contextlib
import errno
import os
import pathlib
import re
import secrets
import signal
import stat
import tempfile
import threading

from .errors import check_flag, check_instance

__all__ = ["check_output", "check_output_directory", "atomic_write", "StagedWrites", "temporary_prefix",
           "check_suffix", "binary_and_header", "as_path", "read_user_text", "MAX_TEXT_FILE_BYTES"]

#: Random characters of a temporary's name between its prefix and suffix (as tempfile.mkstemp's).
_RANDOM_CHARACTERS = 8
_NAME_CHARACTERS = "abcdefghijklmnopqrstuvwxyz0123456789_"
#: Names tried before giving up (as tempfile: a clash needs another writer's same draw of 37^8).
_NAME_ATTEMPTS = tempfile.TMP_MAX
_DEFAULT_NAME_MAX = 255
_DEFAULT_PATH_MAX = 4096


def _limit(directory, name, default):
    try:
        return os.pathconf(directory, name)
    except (OSError, ValueError):
        return default


def _random_name():
    """:data:`_RANDOM_CHARACTERS` characters drawn by the OS's random source (unique temporary names)."""
    return "".join(secrets.choice(_NAME_CHARACTERS) for _ in range(_RANDOM_CHARACTERS))


def _nearest_existing(path):
    """The path itself or its nearest ancestor that exists (the current directory for a relative path)."""
    path = pathlib.Path(path)
    for candidate in (path, *path.parents):
        if os.path.lexists(candidate):
            return candidate
    return pathlib.Path(".")


def _label(option):
    return f"{option}: " if option else ""


#: How to overwrite, for the library's callers: the writers' ``force``, the table's save and exports' ``overwrite``.
_API_FORCE_HINT = "pass force=True (a table's save and exports: overwrite=True), or --force on the command line"


def _force_hint(option):
    return "use --force to overwrite it" if option else _API_FORCE_HINT


def temporary_prefix(path, suffix):
    """The prefix of a temporary for ``path``: ``.<name>.``, the name shortened (never the
    suffix) so that prefix + 8 random characters + ``suffix`` fit in the directory's NAME_MAX."""
    path = pathlib.Path(path)
    name_max = _limit(_nearest_existing(path.parent), "PC_NAME_MAX", _DEFAULT_NAME_MAX)
    room = name_max - 2 - _RANDOM_CHARACTERS - len(os.fsencode(suffix))
    return "." + os.fsdecode(os.fsencode(path.name)[:max(room, 0)]) + "."


def _check_names(path, option, suffix):
    """Name components too long for the file system (the target's, and those of the directories
    still to be created), a temporary name that cannot fit, or a path that is not UTF-8 text
    (:func:`_check_utf8`): ValueError."""
    path = pathlib.Path(path)
    _check_utf8(path, _label(option))
    existing = _nearest_existing(path.parent)
    name_max = _limit(existing, "PC_NAME_MAX", _DEFAULT_NAME_MAX)
    path_max = _limit(existing, "PC_PATH_MAX", _DEFAULT_PATH_MAX)
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            shown = part[:24] + "..."
            raise ValueError(f"{_label(option)}name {shown} is {len(os.fsencode(part))} bytes long; "
                             f"this file system allows {name_max}")
    if len(os.fsencode(suffix)) + 2 + _RANDOM_CHARACTERS > name_max:
        raise ValueError(f"{_label(option)}the suffix of {path.name[:24]}... is too long for a temporary name")
    longest = len(os.fsencode(str(path))) + 2 + _RANDOM_CHARACTERS + len(os.fsencode(suffix))
    if longest >= path_max:
        raise ValueError(f"{_label(option)}path {str(path)[:24]}... is too long ({longest} bytes with its "
                         f"temporary name; at most {path_max - 1})")


def is_utf8(text: str) -> bool:
    """Whether ``text`` (a path as Python reads it: bytes that are not UTF-8 become lone surrogates) is
    UTF-8 text."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _check_utf8(path, prefix=""):
    """ValueError (its message starting with ``prefix``) for an output path that is not UTF-8 text: clsky
    prints its outputs' names and writes them into text that must be UTF-8 (a frame's PNG text and EXR
    attributes hold its scene, whose TOML names the output; ``--print-scene``'s TOML), and a name of other
    bytes (``-o $'caf\\xe9.png'``) failed there, after the work, in Python's words ('surrogates not
    allowed'). Every output (a table's save too) takes the one rule."""
    text = os.fspath(path)
    if not is_utf8(text):
        shown = os.fsencode(text).decode("utf-8", "backslashreplace")
        raise ValueError(f"{prefix}{shown} is not UTF-8 text: clsky prints its outputs' names and records "
                         f"them in UTF-8 text; rename it") from None


def _probe_directory(directory, option):
    """PermissionError unless a file can be created in ``directory`` (os.access, then a real file:
    os.access says yes to root where creating still fails, e.g. in /sys)."""
    if not os.access(directory, os.W_OK | os.X_OK):
        raise PermissionError(f"{_label(option)}cannot write in directory {directory}")
    try:
        fd, probe = tempfile.mkstemp(prefix=".clsky-probe.", dir=directory)
    except OSError as error:
        raise PermissionError(f"{_label(option)}cannot create a file in directory {directory} "
                              f"({error.strerror.lower()})") from None
    os.close(fd)
    os.unlink(probe)


def _check_parent(directory, option, create=False, probe=True):
    """The directory that will hold an output: it exists (or, with ``create``, its nearest existing
    ancestor does), is a directory, and a file can be created in it."""
    directory = pathlib.Path(directory)
    if create:
        directory = _nearest_existing(directory)
    if not directory.exists():
        raise FileNotFoundError(f"{_label(option)}directory {directory} does not exist")
    if not directory.is_dir():
        raise NotADirectoryError(f"{_label(option)}{directory} is not a directory")
    if probe:
        _probe_directory(directory, option)


def as_path(value, name: str = "path") -> pathlib.Path:
    """``value`` (a str or os.PathLike) as a Path; ValueError naming ``name`` for anything else (None, a
    number, bytes) and for a NUL character, which no file name may hold (the OS would refuse it only
    when the file is opened, after the work).

    >>> as_path("sky.png")
    PosixPath('sky.png')
    >>> as_path(None, "--output")
    Traceback (most recent call last):
    ...
    ValueError: --output must be a file path (a str or os.PathLike), got None (NoneType)
    """
    if not isinstance(value, (str, os.PathLike)):
        raise ValueError(f"{name} must be a file path (a str or os.PathLike), got {value!r:.60} "
                         f"({type(value).__name__})")
    text = os.fspath(value)
    if not isinstance(text, str):
        raise ValueError(f"{name} must be a file path as text, got {text!r:.60} ({type(text).__name__})")
    if "\0" in text:
        raise ValueError(f"{name} must not hold a NUL character, got {text!r:.60}")
    if not text:                            # pathlib reads '' as '.', the current directory
        raise ValueError(f"{name} must be a file path, got an empty one")
    return pathlib.Path(text)


#: The largest text file a user hands clsky (a scene, a sweep, a metrics JSON) [bytes]: theirs take kB.
MAX_TEXT_FILE_BYTES = 64 * 2**20


def open_regular_file(path):
    """The file at ``path`` opened for binary reading, once, without blocking, and checked on the open file
    to be a regular one: a FIFO without a writer blocked a read for ever (also one swapped in between a
    check of the name and its open), and ``/dev/zero`` filled the memory.

    Raises
    ------
    OSError
        Unreadable (FileNotFoundError, PermissionError, ...; its ``strerror`` says why), a directory
        (IsADirectoryError), or not a regular file (errno EINVAL, its ``strerror`` says so).
    """
    descriptor = os.open(as_path(path), os.O_RDONLY | os.O_NONBLOCK)
    try:
        mode = os.fstat(descriptor).st_mode     # before open(): it names a directory's descriptor ('3'), not path
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(errno.EISDIR, "Is a directory", str(path))
        if not stat.S_ISREG(mode):
            raise OSError(errno.EINVAL, "not a regular file (a FIFO, a device or a socket)", str(path))
        return open(descriptor, "rb")
    except BaseException:
        os.close(descriptor)
        raise


def read_user_text(path, limit: int = MAX_TEXT_FILE_BYTES) -> str:
    """The UTF-8 text of the file at ``path`` (a leading byte-order mark dropped: editors on Windows write
    one), for files the user names (a scene, a sweep, a metrics JSON).

    The file is opened without blocking and must be a regular file: a FIFO without a writer blocked
    ``--scene`` and ``--sweep`` for ever, and ``/dev/zero`` filled the memory.

    Raises
    ------
    OSError
        Unreadable (its ``strerror`` says why), a directory (IsADirectoryError), not a regular file, or
        larger than ``limit`` bytes (``strerror`` says so).
    UnicodeDecodeError
        Not UTF-8 text.
    """
    with open_regular_file(path) as stream:
        data = stream.read(limit + 1)
    if len(data) > limit:
        raise OSError(errno.EFBIG, f"larger than {limit // 2**20} MiB (no file clsky reads is so large)", str(path))
    return data.decode("utf-8-sig")


def check_suffix(path, suffix: str, name: str = "path") -> pathlib.Path:
    """``path`` as a Path if it names a file NAME``suffix`` (a name before the suffix: pathlib's own reading,
    for which '.png' is a hidden file without a suffix); ValueError naming ``name`` otherwise.

    >>> check_suffix("sky.png", ".png")
    PosixPath('sky.png')
    >>> check_suffix(".png", ".png", "--output")
    Traceback (most recent call last):
    ...
    ValueError: --output must end in .png after a file name (NAME.png), got '.png'
    """
    result = as_path(path, name)
    if result.suffix != suffix or _names_a_directory(path):
        raise ValueError(f"{name} must end in {suffix} after a file name (NAME{suffix}), got {str(path)!r}")
    _check_utf8(result, f"{name}: ")                    # an output's name, written into its metadata
    return result


def _names_a_directory(path) -> bool:
    """Whether ``path`` (as typed) ends in a path separator, or in ``.`` or ``..`` after one: a directory's
    name, whatever pathlib makes of it (it drops them: ``-o x.png/`` and ``-o x.png/.`` wrote the file
    x.png)."""
    text = os.fspath(path)
    if not isinstance(text, str):
        return False
    separators = tuple(filter(None, (os.sep, os.altsep)))
    return text.endswith(separators) or text.endswith(tuple(s + d for s in separators for d in (".", "..")))


def binary_and_header(name, parameter: str = "path") -> tuple[pathlib.Path, pathlib.Path]:
    """The pair ``NAME.bin`` and ``NAME.json`` an export writes for ``name`` (``export_raw``,
    ``export_texture``, ``clsky table --raw NAME``): a trailing ``.bin`` or ``.json`` typed with the name is
    one of the pair's own suffixes and is not doubled; any other dot belongs to the name (``sky.v2`` gives
    ``sky.v2.bin``, where pathlib's ``with_suffix`` gave ``sky.bin``). ValueError naming ``parameter`` for a
    name without a file name (empty, a directory's, or a suffix alone: ``.json`` wrote hidden
    ``.json.bin`` and ``.json.json``).

    >>> binary_and_header("out/sky.json")
    (PosixPath('out/sky.bin'), PosixPath('out/sky.json'))
    >>> binary_and_header("sky.v2")
    (PosixPath('sky.v2.bin'), PosixPath('sky.v2.json'))
    """
    text = os.fspath(name) if isinstance(name, (str, os.PathLike)) else name
    if not isinstance(text, str):
        raise ValueError(f"{parameter} must be a file name (NAME gives NAME.bin and NAME.json), got {text!r}")
    path = pathlib.Path(text)
    stem = path.name[:-len(path.suffix)] if path.suffix in (".bin", ".json") else path.name
    if not stem or stem in (".", "..", ".bin", ".json") or text.endswith(("/", os.sep)):
        raise ValueError(f"{parameter} must be a file name (NAME gives NAME.bin and NAME.json), got {text!r}")
    return path.with_name(stem + ".bin"), path.with_name(stem + ".json")


def check_output(path, force=False, option=None, suffix=None, probe=True):
    """Check, before any work, that ``path`` can be written as a new file.

    Parameters
    ----------
    path : str or os.PathLike
        The output file.
    force : bool
        An existing file may be replaced.
    option : str, optional
        The command-line option that named ``path`` (e.g. ``"--output"``): it starts the message,
        and an existing file asks for ``--force``.
    suffix : str, optional
        Suffix of the temporary file (default: the path's): its length counts for the name check.
    probe : bool
        Create and delete a file in the parent to prove it writable (False when the caller creates
        its temporary there next, which proves it as well).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    FileExistsError
        ``path`` exists and not ``force``.
    IsADirectoryError
        ``path`` is a directory.
    FileNotFoundError, NotADirectoryError
        Its parent does not exist, or is not a directory.
    PermissionError
        No file can be created in its parent (read-only file system, permissions, immutable
        directory, a pseudo file system such as /proc or /sys).
    ValueError
        A name longer than the file system's NAME_MAX, a path (with its temporary name) longer
        than PATH_MAX, or a path that is not UTF-8 text (:func:`_check_names`).
    """
    typed, path = path, as_path(path, option or "path")
    suffix = path.suffix if suffix is None else suffix
    _check_names(path, option, suffix)
    if path.is_dir() or _names_a_directory(typed):
        raise IsADirectoryError(f"{_label(option)}{typed} is a directory" if path.is_dir() else
                                f"{_label(option)}{typed} names a directory (its trailing '/', '/.' or '/..'), "
                                f"not a file")
    if os.path.lexists(path) and not force:
        raise _exists(f"{_label(option)}{path} exists; {_force_hint(option)}", path)
    _check_parent(path.parent, option, probe=probe)
    return path


def _exists(message, path) -> FileExistsError:
    """FileExistsError(``message``) carrying ``path`` as its ``path`` attribute (``filename`` would change its
    text): a command line maps it to the option that named the file (the animation's run)."""
    error = FileExistsError(message)
    error.path = str(path)
    return error


def check_output_directory(path, option=None, names=()):
    """Check, before any work, that ``path`` can hold output files: an existing directory where
    files can be created, or a path whose missing parts can be created (``mkdir(parents=True)``).

    Parameters
    ----------
    path : str or os.PathLike
    option : str, optional
        As in :func:`check_output`.
    names : sequence of str
        The longest file names to be created in it: each, with its temporary name, must fit.

    Raises
    ------
    NotADirectoryError
        ``path`` (or an ancestor) exists and is not a directory.
    PermissionError
        Nothing can be created there.
    ValueError
        A name component too long.
    """
    path = pathlib.Path(path)
    for name in (*names, "x"):
        _check_names(path / name, option, pathlib.Path(name).suffix)
    if os.path.lexists(path) and not path.is_dir():
        raise NotADirectoryError(f"{_label(option)}{path} exists and is not a directory")
    _check_parent(path, option, create=True)
    return path


#: The signals that interrupt a command cleanly (clsky/cli.py; SIGHUP: the terminal was closed) and
#: that are held back while a set of files lands.
INTERRUPT_SIGNALS = _DEFERRED_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


@contextlib.contextmanager
def _signals_deferred():
    """Hold SIGINT, SIGTERM and SIGHUP back during the block and deliver them after it, to the
    handlers that were in place: an interruption then arrives after a set landed, never halfway.

    Python runs signal handlers in the main thread whichever thread the signal reached (PoCL's
    worker threads included, so blocking with pthread_sigmask would not do), so swapping the
    handlers for a recorder is enough; elsewhere than the main thread the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending = []
    previous = {}
    for number in _DEFERRED_SIGNALS:
        handler = signal.getsignal(number)
        if handler is None or handler == signal.SIG_IGN:     # not Python's to change, or ignored
            continue
        previous[number] = signal.signal(number, lambda signum, frame: pending.append(signum))
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        for number in dict.fromkeys(pending):
            signal.raise_signal(number)


def _place(temporary, target, overwrite):
    """Rename ``temporary`` onto ``target``; without ``overwrite`` a target that appeared meanwhile
    is kept (hard link: atomic create-if-absent; plain check where links are not supported)."""
    if overwrite:
        os.replace(temporary, target)
        return
    try:
        os.link(temporary, target)
    except FileExistsError:
        raise _exists(f"{target} exists (it appeared during the run); {_API_FORCE_HINT}", target) from None
    except OSError as error:
        if error.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EXDEV, errno.EMLINK):
            raise
        if os.path.lexists(target):
            raise _exists(f"{target} exists (it appeared during the run); {_API_FORCE_HINT}", target) from None
        os.replace(temporary, target)
        return
    os.unlink(temporary)


class StagedWrites:
    """A set of output files that land together: each is written to a unique hidden temporary beside
    its target, and all are renamed onto their targets at :meth:`commit`.

    Used as a context manager: commits when the block ends normally, deletes every temporary when it
    raises (KeyboardInterrupt included), and the targets are left as they were.

    Notes
    -----
    - Order: the files are renamed in the order they were staged, those staged with ``last=True``
      after the others (an animation's MP4: when it is there, its frames and metrics are too); then
      the files given to :meth:`remove_on_commit` are deleted.
    - SIGINT, SIGTERM and SIGHUP are held back while the set is renamed (when committing in the
      main thread) and delivered after it, so an interruption arrives after the set landed, not
      halfway.
    - A rename that fails midway (rare after :func:`check_output`: a disk removed, a permission
      changed during the run) stops the commit: the targets renamed so far hold the new files, the
      others keep their old contents (or stay absent); the remaining temporaries are deleted and the
      error names the file that failed and the new files already in place.
    - A killed process (SIGKILL, power loss) can leave hidden temporaries ``.<name>.XXXXXXXX<suffix>``
      beside the targets; they are never mistaken for outputs, and can be deleted.
    - Concurrent writers of the same targets each rename their own complete files: every target is
      complete, and the last rename wins per file (a set written by two runs at once may mix them).
    """

    def __init__(self):
        self._staged = []           # (temporary, target, overwrite, last)
        self._removals = []
        self.committed = []

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, traceback):
        if exc_type is None:
            self.commit()
        else:
            self.discard()
        return False

    def stage(self, path, overwrite=False, suffix=None, last=False):
        """Check ``path`` (:func:`check_output`) and create its empty temporary; returns the
        temporary's path, to be written by the caller (the file may be replaced, not only filled).

        ``suffix`` is the temporary's suffix (default: the target's; writers that pick a format
        from the file name need it).
        """
        path, overwrite = output_target(path, overwrite, flag="overwrite")
        suffix = path.suffix if suffix is None else suffix
        check_output(path, force=overwrite, suffix=suffix, probe=False)
        prefix = temporary_prefix(path, suffix)
        for _ in range(_NAME_ATTEMPTS):
            temporary = path.parent / f"{prefix}{_random_name()}{suffix}"
            entry = (temporary, path, bool(overwrite), bool(last))
            # registered before the file exists: an interruption (a signal's exception) from here on
            # finds it in the set, whose discard deletes it (an unregistered empty temporary was left
            # behind once by a SIGTERM between mkstemp and the registration)
            self._staged.append(entry)
            try:
                # like mkstemp (O_EXCL: never someone else's file), with the mode a plain open gives
                # (0o666 less the umask): mkstemp's 0600 would leak into the final file
                os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0),
                                 0o666))
            except FileExistsError:
                self._staged.remove(entry)
                continue
            except OSError as error:
                self._staged.remove(entry)
                raise PermissionError(f"cannot create a file beside {path} ({error.strerror.lower()})") from None
            return temporary
        raise FileExistsError(errno.EEXIST, f"no unused temporary name beside {path} after {_NAME_ATTEMPTS} tries")

    def remove_on_commit(self, path):
        """Delete ``path`` (if it still exists) once the staged files are in place."""
        self._removals.append(pathlib.Path(path))

    @property
    def temporaries(self):
        """The temporaries not yet renamed."""
        return [entry[0] for entry in self._staged]

    def discard(self, temporary=None):
        """Delete one staged temporary (``temporary``), or all of them and forget the removals; each as far
        as it can (:func:`_unlink_if_possible`: a folder made read-only during the run stopped the deletions
        at its first temporary, left the others behind, and its error replaced the run's own)."""
        keep = []
        for entry in self._staged:
            if temporary is None or entry[0] == pathlib.Path(temporary):
                _unlink_if_possible(entry[0])
            else:
                keep.append(entry)
        self._staged = keep
        if temporary is None:
            self._removals = []

    def commit(self):
        """Rename every staged temporary onto its target (see the class notes), then delete the
        files to remove. Returns the targets written."""
        entries = [e for e in self._staged if not e[3]] + [e for e in self._staged if e[3]]
        with _signals_deferred():
            for position, (temporary, target, overwrite, _) in enumerate(entries):
                try:
                    _place(temporary, target, overwrite)
                except BaseException as error:
                    for rest in entries[position:]:
                        _unlink_if_possible(rest[0])
                    self._staged = []
                    if not isinstance(error, OSError) or not self.committed:
                        raise                    # nothing is in place yet: the error says it all
                    done = ", ".join(str(path) for path in self.committed) or "none"
                    wrapped = type(error)(f"could not put {target} in place ({error}); "
                                          f"new files already in place: {done}")
                    wrapped.path, wrapped.committed = getattr(error, "path", None), list(self.committed)
                    raise wrapped from error
                self.committed.append(target)
            self._staged = []
            for path in self._removals:
                path.unlink(missing_ok=True)
            self._removals = []
        return list(self.committed)


def _unlink_if_possible(path):
    """Delete ``path`` if it exists and can be deleted: a temporary cleaned up after an error, which must
    not replace that error (a read-only folder keeps its temporary: nothing else can be done there)."""
    try:
        path.unlink(missing_ok=True)
    except OSError:
        pass


def output_target(path, force, name="path", flag="force"):
    """(``path`` as a Path, ``force`` as a bool), or ValueError naming ``name`` or ``flag``: a path that is
    None, a number or bytes, an empty one (pathlib's '.'), or a flag that is no bool (``force='no'`` was
    true, and replaced the file)."""
    return as_path(path, name), check_flag(flag, force)


@contextlib.contextmanager
def atomic_write(path, overwrite=False, suffix=None, staging=None):
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The target file; its directory must exist.
    overwrite : bool
        Replace an existing ``path``.
    suffix : str, optional
        Suffix of the temporary (default: the target's).
    staging : StagedWrites, optional
        Stage the file in this set instead: it is renamed when the set commits.

    Raises
    ------
    FileExistsError, IsADirectoryError, FileNotFoundError, NotADirectoryError, PermissionError, ValueError
        From :func:`check_output`, before anything is written.

    Notes
    -----
    The temporary has a unique name (``.<name>.XXXXXXXX<suffix>``): concurrent writers never share
    one, and the last rename wins. An exception in the block (KeyboardInterrupt included) deletes
    the temporary and leaves ``path`` as it was.
    """
    check_instance("staging", staging, StagedWrites, "None or a StagedWrites", optional=True)
    own = StagedWrites() if staging is None else None
    writes = staging or own
    temporary = None
    try:
        temporary = writes.stage(path, overwrite, suffix)
        yield temporary
    except OSError as error:                     # e.g. a full disk: name the target, not the temporary
        _discard_staged(writes, own, temporary)
        if temporary is not None and error.errno is None and re.fullmatch(r"\d+ requested and \d+ written", str(error)):
            # NumPy's short write (np.save, tofile), no errno nor file: '3072 requested and 992 written'
            raise OSError(f"cannot write {path}: a short write ({error}): is the disk full?") from error
        # a write to an open file (a full disk: ENOSPC) names no file; the block writes the temporary
        if temporary is None or error.errno is None or error.filename not in (str(temporary), temporary, None):
            raise
        reason = error.strerror or str(error)
        raise type(error)(f"cannot write {path}: {reason[:1].lower()}{reason[1:]}") from error
    except BaseException:
        _discard_staged(writes, own, temporary)
        raise
    if own is not None:
        own.commit()


def _discard_staged(writes, own, temporary):
    """Delete what :func:`atomic_write` staged: all of its own set (an interruption inside ``stage`` may
    come before ``temporary`` is known), or ``temporary`` in the caller's set (whose own discard deletes
    the rest)."""
    if own is not None:
        own.discard()
    elif temporary is not None:
        writes.discard(temporary)
