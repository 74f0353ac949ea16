"""clsky's own disk cache: where it is, and how a file gets into it.

What is kept there is what would cost every process a measurable share of a small run to recompute
(docs/speed-log.md): colour-science's constants (:mod:`clsky.colour_constants`) and the scene plan's pilot
shares (:func:`clsky.planner.pilot_share`, keyed by :func:`source_digest` among others). The directory is
``$CLSKY_CACHE_DIR`` where that is set to an absolute path (the test suite gives each session its own),
else ``$XDG_CACHE_HOME/clsky`` or ``~/.cache/clsky`` (an XDG_CACHE_HOME that is not an absolute path is
ignored, as the XDG Base Directory specification asks); without a home directory there is none. Files land through
:func:`clsky._files.atomic_write` (a unique temporary beside the target, renamed onto it), so concurrent
writers leave one writer's whole file and one that raises (KeyboardInterrupt included) leaves nothing;
each reader validates what it reads (its own format, a SHA-256 digest) and ignores a file that fails. A
directory that cannot be written is no error: the thing is then recomputed by every process, as without
the cache, and a note says so once a process. Nothing is ever deleted from it (README "Known limits").
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import pathlib

from ._files import atomic_write

__all__ = ["cache_directory", "source_digest", "store"]


def cache_directory(*parts: str) -> pathlib.Path | None:
    """``$CLSKY_CACHE_DIR/<parts>`` where that variable holds an absolute path, else
    ``$XDG_CACHE_HOME/clsky/<parts>`` or ``~/.cache/clsky/<parts>``; None where none is known."""
    explicit = os.environ.get("CLSKY_CACHE_DIR", "")
    if os.path.isabs(explicit):
        return pathlib.Path(explicit, *parts)
    if explicit:
        _ignored_once(explicit)
    base = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(base):
        home = os.path.expanduser("~")
        if not os.path.isabs(home):
            return None
        base = os.path.join(home, ".cache")
    return pathlib.Path(base, "clsky", *parts)


@functools.lru_cache(maxsize=None)
def _ignored_once(value: str):
    """Say once a process, on stderr, that a relative CLSKY_CACHE_DIR is ignored (it was, without a word,
    and the cache went where the user had set it not to go)."""
    logging.getLogger("clsky").warning(f"clsky: note: CLSKY_CACHE_DIR={value!r} is not an absolute path: ignored "
                                       f"(the cache goes to $XDG_CACHE_HOME/clsky or ~/.cache/clsky)")


def store(path: pathlib.Path, write) -> bool:
    """Put a file at ``path`` (its parent created if needed) by calling ``write(file)`` on a binary file
    object of a unique temporary, renamed onto ``path`` when ``write`` returns. Returns whether the file
    landed; an OSError (a read-only or full disk, a file where a directory should be) only returns False."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(path, overwrite=True) as temporary, open(temporary, "wb") as file:
            write(file)
    except (OSError, ValueError) as error:
        _unwritable_once(str(cache_directory()), str(error))
        return False
    return True


#: The cache directories a note has been given for in this process (:func:`_unwritable_once`).
_NOTED = set()


def _unwritable_once(directory: str, reason: str):
    """Say once a process and directory, on stderr, that the cache could not be written (a read-only or full
    disk): the run is right, but computes again what it would have read (about a second), which it did
    without a word."""
    if directory in _NOTED:
        return
    _NOTED.add(directory)
    logging.getLogger("clsky").warning(f"clsky: note: clsky's cache {directory} cannot be written ({reason}): what "
                                       f"it keeps is computed again each run (set CLSKY_CACHE_DIR to a writable "
                                       f"directory)")


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 (hex) of clsky's own code: every ``.py`` file of the package and every OpenCL kernel
    (``.cl``) it builds, by name and content. A result kept on disk under a key that holds it is never
    read by another version of the code (an edit, an upgrade); about 3 ms the first time in a process."""
    from ._cl import kernel_directory

    package = pathlib.Path(__file__).resolve().parent
    sha = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        sha.update(f"{path.relative_to(package).as_posix()}\n".encode())
        sha.update(path.read_bytes())
    for entry in sorted(kernel_directory().iterdir(), key=lambda entry: entry.name):
        if entry.name.endswith(".cl"):
            sha.update(f"kernels/{entry.name}\n".encode())
            sha.update(entry.read_bytes())
    return sha.hexdigest()
