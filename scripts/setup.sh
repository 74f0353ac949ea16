#!/usr/bin/env bash
# Set up clsky on a fresh machine: a virtual environment in .venv with clsky and its extras, and a CPU
# OpenCL driver. As root with apt-get, installs Debian's PoCL 3.1 (about 4-5x faster than the pip
# build, measured: README, its setup paragraph); otherwise, or if that fails, falls back to the PoCL pip build.
# Prints which OpenCL device clsky will use. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."

log() { printf 'setup: %s\n' "$*" >&2; }

if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    if ! dpkg -s pocl-opencl-icd >/dev/null 2>&1; then
        log "installing Debian's PoCL (pocl-opencl-icd) with apt-get"
        if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq pocl-opencl-icd >/dev/null; }; then
            log "apt-get could not install pocl-opencl-icd; will fall back to the pip build"
        fi
    fi
else
    log "not root or no apt-get: skipping Debian's PoCL"
fi

python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[anim,test,bench,dask]"

if ! .venv/bin/python -c "import pyopencl as cl, sys; sys.exit(0 if any(p.get_devices() for p in cl.get_platforms()) else 1)" 2>/dev/null; then
    log "no OpenCL device found: installing the PoCL pip build (pyopencl[pocl])"
    .venv/bin/python -m pip install -q -e ".[anim,test,bench,dask,pocl]"
fi
# three.js's EXRLoader (tests/js, pinned by its package-lock.json) for tests/test_exr.py; optional
if command -v npm >/dev/null 2>&1; then
    npm ci --prefix tests/js --no-audit --no-fund --silent || log "npm ci in tests/js failed: the three.js test will skip"
fi
log "OpenCL devices (* = the one clsky uses):"
.venv/bin/clsky devices >&2
log "clsky will use: $(.venv/bin/python -c 'import clsky._cl as c; print(c.describe_device(c.default_device()))')"
