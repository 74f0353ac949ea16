"""Benchmark: the quality levels below civil twilight, measured against the converged reference.

bench/bench_quality.py's levels table on four frames with the sun at -6, -8, -10 and -12 deg
(clsky.anim.accuracy.DUSK_ELEVATIONS; -6 deg is the default animation's lowest sun): the reference (one
table per frame on the sun range that frame needs), then each quality level planned for the path from
-12 to 45 deg, its table built, its frames ray-marched, looked up and read from the sky-view map, each
against the reference; and how far the reference converged at these suns (each group of its counts
doubled in turn). The measured errors are the ones the scene planner quotes below -4 deg, the convergence the
margin its promise rule takes there (clsky.renderer_choice.RAY_MARCH_ERROR, SKYVIEW_ON_REFERENCE,
REFERENCE_RESOLUTION).

Writes the README section "quality-dusk", docs/quality_dusk.csv and docs/quality_dusk_reference.csv.

Usage: python bench/bench_quality_dusk.py [--size 64] [--groups GROUP ...] [--reference-cache FILE]
[--no-readme] [--docs DIR] [--smoke]

``--groups``: the reference's count groups to double (all by default, as bench/bench_quality.py's: each
rebuilds the four reference tables, about 13 min on the 2-core Xeon; ``--groups`` with none measures the levels
alone, about 20 min; bench_quality.DUSK); the other options as bench/bench_quality.py's.
"""

from bench_quality import DUSK, main

if __name__ == "__main__":
    main(DUSK, __doc__)
