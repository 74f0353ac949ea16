"""clsky.anim: frames and animations of clsky skies (cameras, sun paths, rendering, writers).

The repository keeps this package in the top-level ``anim/`` folder; it installs as ``clsky.anim``
(pyproject's package-dir), so nothing outside the ``clsky`` name lands in site-packages.
``clsky.anim`` imports the core (``clsky``, ``clsky.render``, ...); the core never imports ``clsky.anim``.
"""
