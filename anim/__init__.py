"""anim: frames and animations of clsky skies (cameras, sun paths, rendering, writers).

``anim`` imports ``clsky``; ``clsky`` never imports ``anim``.
"""
