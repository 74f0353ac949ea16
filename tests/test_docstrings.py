"""The examples in the docstrings of clsky and clsky.anim run and print what they show (doctest), as the
README's command lines do (tests/test_readme.py): an example that no longer holds is a bug in the docs.

Each module is its own case; a module without examples passes trivially (the count of those that have
some is checked, so that a broken collection cannot pass for an empty one)."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import numpy as np
import pytest

import clsky
import clsky.anim


def _modules():
    for package in (clsky, clsky.anim):
        yield package.__name__
        for info in pkgutil.iter_modules(package.__path__, package.__name__ + "."):
            if info.name != "clsky.anim" and not info.name.endswith("__main__"):
                yield info.name


MODULES = sorted(set(_modules()))


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_hold(name):
    """Under NumPy's own printing: a test that imports colour-science itself (tests/test_display.py) leaves its
    worker printing arrays as NumPy 1.13 did (colour's import sets that process-wide; clsky's own import of it
    does not, tests/test_colour_constants.py)."""
    module = importlib.import_module(name)
    with np.printoptions(legacy=False):
        failed, _ = doctest.testmod(module, verbose=False, report=True)
    assert failed == 0, f"{failed} docstring example(s) of {name} failed (printed above)"


def test_the_examples_are_found():
    """The modules with examples: at least the ones known to have them, and 20 in all (23 on 2026-12-06)."""
    finder = doctest.DocTestFinder()
    with_examples = {name for name in MODULES
                     if any(test.examples for test in finder.find(importlib.import_module(name)))}
    assert {"clsky.errors", "clsky._files", "clsky.anim.cameras"} <= with_examples, sorted(with_examples)
    assert len(with_examples) >= 20, sorted(with_examples)
