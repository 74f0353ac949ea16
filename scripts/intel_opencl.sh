#!/usr/bin/env bash
# Opt-in: Intel's CPU OpenCL runtime beside PoCL, for this checkout only (README "Speed": on the 2-core
# AMD EPYC development machine it renders the same frames as PoCL, 1.4-1.5x faster in the ray march).
# It is Intel's proprietary, freely redistributable runtime from PyPI (intel-opencl-rt, about 800 MB
# installed). This installs it under .intel-opencl (or the directory given as $1) and writes there an
# OpenCL vendors directory that lists it and the drivers already registered (/etc/OpenCL/vendors,
# .venv/etc/OpenCL/vendors); nothing outside that directory changes. Point the OpenCL loader at it:
#   OCL_ICD_VENDORS=$PWD/.intel-opencl/vendors .venv/bin/clsky devices
# With both runtimes listed, clsky prefers Intel's on a machine without a GPU; PYOPENCL_CTX=portable
# picks PoCL ("Portable Computing Language"). Needs ./scripts/setup.sh first. Safe to run again.
set -euo pipefail
# the directory as given, from where it was given (empty or absent: .intel-opencl in the checkout)
prefix=$(realpath -m -- "${1:-$(dirname "$0")/../.intel-opencl}")
cd "$(dirname "$0")/.."

log() { printf 'intel_opencl: %s\n' "$*" >&2; }

if [ ! -x .venv/bin/python ]; then
    log "no .venv here: run ./scripts/setup.sh first"
    exit 2
fi
log "installing Intel's CPU OpenCL runtime under $prefix"
# intel-cmplr-lib-rt brings the math libraries (libimf, libsvml) that libintelocl.so needs but the
# intel-opencl-rt wheel does not declare; without them the loader skips the runtime without a word
.venv/bin/python -m pip install -q --no-warn-script-location --prefix "$prefix" \
    "intel-opencl-rt==2026.2.*" "intel-cmplr-lib-rt==2026.2.*"
library="$prefix/lib/libintelocl.so"
if [ ! -f "$library" ]; then
    log "the install did not provide $library"
    exit 1
fi

# the vendors directory is written under a unique name beside its final place, and "vendors" is a link
# to it, replaced by a rename: a run that is interrupted, or two at once, never leave it half written
vendors="$prefix/vendors"
staging=$(mktemp -d "$prefix/.vendors.XXXXXX")
trap 'rm -rf "$staging" "$staging.link"' EXIT
printf '%s\n' "$library" > "$staging/intel-cpu.icd"
for icd in /etc/OpenCL/vendors/*.icd .venv/etc/OpenCL/vendors/*.icd; do
    if [ -f "$icd" ] && ! grep -q libintelocl "$icd"; then
        cp "$icd" "$staging/"
    fi
done
chmod 755 "$staging"
previous=$(readlink "$vendors" 2>/dev/null || true)
if [ -e "$vendors" ] && [ ! -L "$vendors" ]; then
    rm -rf "$vendors"                   # a directory in its place (an earlier version of this script wrote one)
fi
ln -s "$(basename "$staging")" "$staging.link"
mv -T "$staging.link" "$vendors"
trap - EXIT
if [ -n "$previous" ] && [ "$previous" != "$(basename "$staging")" ]; then
    rm -rf "${prefix:?}/$previous"
fi

log "OpenCL devices with OCL_ICD_VENDORS=$vendors (* = the one clsky uses):"
OCL_ICD_VENDORS="$vendors" .venv/bin/clsky devices >&2
if ! OCL_ICD_VENDORS="$vendors" .venv/bin/python -c \
        "import pyopencl as cl, sys; sys.exit(0 if any('Intel' in p.name for p in cl.get_platforms()) else 1)"; then
    log "the OpenCL loader does not list Intel's runtime (a CPU it does not support?)"
    exit 1
fi
log "use it with: OCL_ICD_VENDORS=$vendors"
