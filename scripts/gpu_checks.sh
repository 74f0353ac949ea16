#!/usr/bin/env bash
# The checks to run where a GPU is at hand (README "Speed", GPUs; issue 12): which OpenCL device clsky
# picks, the kernel-versus-twin tests on it, the benchmarks (printed, README.md left as it is) and a
# profile of the default animation's planned table (wall clock by function, device time by kernel).
# Everything goes to OUTDIR (default gpu_checks/ in the checkout; it must not exist), one log per step,
# and the first-round animations of bench_runtimes are kept there (OUTDIR/anim/<configuration>/) to
# compare with another machine's frames.
#
#   ./scripts/gpu_checks.sh [OUTDIR]
#
# NVIDIA's OpenCL library often ships without its registration (no /etc/OpenCL/vendors/nvidia.icd in
# containers): when the loader lists no GPU and libnvidia-opencl.so.1 is found, this writes a vendors
# directory (OUTDIR/vendors: nvidia.icd beside the drivers already registered) and points the loader at
# it with OCL_ICD_VENDORS, as scripts/intel_opencl.sh does for Intel's runtime. Environment:
#   PY       the Python with clsky (default .venv/bin/python, else python3);
#   WORKERS  pytest-xdist workers for the tests when xdist is installed (default 8);
#   SMOKE=1  the benchmarks at their smoke sizes and one test file (tests/test_devices.py runs it on PoCL);
#   ONLY     the steps to run, by name, when device time is short (default all): tests runtimes orders
#            render animate profile copies (the machine and its OpenCL devices are always shown).
# Each step is bounded by STEP_LIMIT seconds (default 300); a failing step is reported and the next runs.
set -uo pipefail
out=$(realpath -m "${1:-$(dirname "$0")/../gpu_checks}")      # OUTDIR as given, from where it was given
cd "$(dirname "$0")/.."

STEPS="tests runtimes orders render animate profile copies"
ONLY=$(echo ${ONLY:-$STEPS})                                # its names separated by single spaces
for name in $ONLY; do
    [[ " $STEPS " == *" $name "* ]] || { echo "gpu_checks: ONLY: no step '$name' (steps: $STEPS)" >&2; exit 2; }
done
wanted() { [[ " $ONLY " == *" $1 "* ]]; }

if [ -e "$out" ]; then
    echo "gpu_checks: $out exists already (nothing is overwritten): give another OUTDIR" >&2
    exit 2
fi
mkdir -p "$out" || exit 2
PY=${PY:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}
STEP_LIMIT=${STEP_LIMIT:-300}
SMOKE=${SMOKE:-}
start=$(date +%s)
failed=0

step() { printf '\n=== [+%ss] %s\n' $(( $(date +%s) - start )) "$*"; }
# run LOG command...: the command bounded by STEP_LIMIT, its output shown and kept in $out/LOG
run() {
    local log=$1; shift
    timeout -k 10 "$STEP_LIMIT" "$@" 2>&1 | tee "$out/$log"
    local status=${PIPESTATUS[0]}
    [ "$status" = 0 ] || { echo "gpu_checks: exit status $status: $*"; failed=1; }
}

step "machine"
{ command -v nvidia-smi >/dev/null && nvidia-smi -L; echo "cores: $(nproc); kernel: $(uname -r); $(uptime)"; } 2>&1 |
    tee "$out/machine.txt"

step "OpenCL devices"
gpus=$("$PY" -c "import pyopencl as cl
print(sum(len(platform.get_devices(cl.device_type.GPU)) for platform in cl.get_platforms()))" 2>/dev/null || echo 0)
if [ "$gpus" = 0 ] && [ -z "${OCL_ICD_VENDORS:-}" ]; then
    library=$( (ldconfig -p 2>/dev/null | awk '/libnvidia-opencl\.so\.1/ {print $NF; exit}') )
    [ -n "$library" ] || library=$(find /usr/local/nvidia /usr/lib /usr/lib64 -name 'libnvidia-opencl.so.1' \
                                    2>/dev/null | head -1)
    if [ -n "$library" ]; then
        mkdir -p "$out/vendors"
        printf '%s\n' "$library" > "$out/vendors/nvidia.icd"
        for icd in /etc/OpenCL/vendors/*.icd; do [ -f "$icd" ] && cp "$icd" "$out/vendors/"; done
        export OCL_ICD_VENDORS="$out/vendors"
        echo "registered NVIDIA's OpenCL library $library: OCL_ICD_VENDORS=$OCL_ICD_VENDORS"
    fi
fi
run devices.txt "$PY" -m clsky.anim devices

if wanted tests; then
step "kernel-versus-twin tests on clsky's device"
tests=$("$PY" - <<'EOF'
import ast, pathlib
tree = ast.parse(pathlib.Path("tests/test_intel_opencl.py").read_text())
names = next(node.value for node in ast.walk(tree)
             if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "TWIN_TESTS")
more = ["test_stopping.py", "test_vector_width.py", "test_devices.py", "test_cube_root.py", "test_source_stride.py"]
print(" ".join("tests/" + name for name in [element.value for element in names.elts] + more))
EOF
)
[ -z "$SMOKE" ] || tests="tests/test_devices.py"
parallel=()
"$PY" -c "import xdist" 2>/dev/null && parallel=(-n "${WORKERS:-8}")
run tests.txt "$PY" -m pytest -q -p no:cacheprovider -m "not slow" -rfEs "${parallel[@]}" $tests
fi

smoke=(); [ -z "$SMOKE" ] || smoke=(--smoke)
wanted runtimes || wanted orders || wanted render || wanted animate && step "benchmarks (printed only)"
wanted runtimes && run bench_runtimes.txt "$PY" bench/bench_runtimes.py --vector-widths 8 1 --rounds 1 --no-readme \
    --keep-outputs "$out/anim" "${smoke[@]}"
wanted orders && run bench_orders.txt "$PY" bench/bench_orders.py --repeat 2 --no-readme "${smoke[@]}"
wanted render && run bench_render.txt "$PY" bench/bench_render.py --no-readme --skip-animation "${smoke[@]}"
# the default animation with the default host threads (half the cores) against one, and one after the other;
# the frames' host half alone on 1, 2, 4, ... host threads
wanted animate && run bench_animate.txt "$PY" bench/bench_animate.py --no-readme --stage-frames 2 "${smoke[@]}"

if wanted profile; then
step "the default animation's planned table: wall-clock profile and device time per kernel (a process's third build)"
run profile.txt "$PY" - "${smoke[@]}" <<'EOF'
import collections, cProfile, pstats, sys
sys.path.insert(0, "bench")
import clsky
from clsky import _cl
from bench_orders import build_cases
from _report import SMOKE

engines = []                 # every engine made from here on profiles its launches (OpenCL events)
plain_init = _cl.Engine.__init__


def profiling_init(self, ctx=None, dtype=_cl.np.float64, profile=False, fast_math=False, queue=None, allocator=None):
    plain_init(self, ctx, dtype, True, fast_math, queue, allocator)
    engines.append(self)


_cl.Engine.__init__ = profiling_init


class ProfilingQueue(_cl.cl.CommandQueue):
    """Every queue made from here on profiles (the orders' shared and copy queues too, not an engine's)."""

    def __init__(self, context, device=None, properties=0):
        super().__init__(context, device, properties | _cl.cl.command_queue_properties.PROFILING_ENABLE)


_cl.cl.CommandQueue = ProfilingQueue
label, atmosphere, planned = build_cases("--smoke" in sys.argv)[1]
clsky.ScatteringTable.build(atmosphere, planned.replace(size=SMOKE.table))      # kernels compiled
clsky.ScatteringTable.build(atmosphere, planned)                                # caches warm
for engine in engines:
    engine.events.clear()
profile = cProfile.Profile()                                                    # wall clock
profile.runcall(clsky.ScatteringTable.build, atmosphere, planned)
print(f"{label}, {' x '.join(map(str, planned.size))}:")
pstats.Stats(profile).sort_stats("cumulative").print_stats(40)
pstats.Stats(profile).sort_stats("tottime").print_stats(25)           # where the host itself spends it
seconds, launches, unprofiled = collections.Counter(), collections.Counter(), 0
for engine in engines:
    for kernel, event in engine.events:
        try:
            seconds[kernel] += (event.profile.end - event.profile.start) * 1e-9
            launches[kernel] += 1
        except _cl.cl.Error:                     # a queue made without profiling (not an engine's own)
            unprofiled += 1
print("device time per kernel in that build [s] (launches):")
for kernel, total in seconds.most_common():
    print(f"  {kernel:24s} {total:8.3f} ({launches[kernel]})")
print(f"  all kernels              {sum(seconds.values()):8.3f}; launches not profiled: {unprofiled}")
EOF

fi

if wanted copies; then
step "copies: rectangular reads and writes (3 or 6 of 8 doubles a row), contiguous ones, packed reads"
# The planned build reads every order's nodes (3 of 8 doubles a row) and the gathered sum (6) by
# clEnqueueReadBufferRect on CPUs and packed on the device (pack_channels) elsewhere, and writes its first
# gather (6) by clEnqueueWriteBufferRect (clsky/azimuth.py, clsky._cl.rectangular_reads): all three timed.
run copies.txt "$PY" - "${smoke[@]}" <<'EOF'
import sys, time
import numpy as np
import pyopencl as cl
import pyopencl.array as cla
from clsky import TableSettings, _cl
from clsky.multiple import MultipleScatteringEngine

rows = 4096 if "--smoke" in sys.argv else 32 * 256 * 208          # the planned table's cells, one node
ctx = _cl.make_context()
queue = cl.CommandQueue(ctx)
device = cl.Buffer(ctx, cl.mem_flags.READ_WRITE, rows * 64)
cl.enqueue_fill_buffer(queue, device, np.zeros(1), 0, rows * 64).wait()
padded = np.empty((rows, 8))
engine = MultipleScatteringEngine(TableSettings(), queue=queue)
padded_d = cla.Array(queue, (rows, 8), np.float64, data=device)
print(f"{_cl.describe_device(queue.device)}: {rows} rows of 8 doubles ({rows * 64 / 2**20:.0f} MiB), best of 3")


def rectangle(channels, host, read):
    source, target = (device, host) if read else (host, device)
    cl.enqueue_copy(queue, target, source, buffer_origin=(0, 0, 0), host_origin=(0, 0, 0),
                    region=(channels * 8, rows, 1), buffer_pitches=(64, 0), host_pitches=(channels * 8, 0),
                    is_blocking=True)


def contiguous(channels, host, read):
    if read:
        cl.enqueue_copy(queue, padded, device, is_blocking=True)
        host[...] = padded[:, :channels]
    else:
        padded[:, :channels] = host
        cl.enqueue_copy(queue, device, padded, is_blocking=True)


def packed(channels, host, read):
    """What clsky.azimuth reads on devices other than CPUs: the channels packed on the device, one read."""
    packed_d = cla.empty(queue, (rows, channels), np.float64)
    engine.pack_channels(padded_d, channels, packed_d)
    cl.enqueue_copy(queue, host, packed_d.data, is_blocking=True)


for channels in (3, 6):
    host = np.zeros((rows, channels))
    for read in (True, False):
        ways = (("rectangular", rectangle), ("contiguous + host copy", contiguous)) + ((("packed", packed),) if read else ())
        for label, copy in ways:
            seconds = []
            for _ in range(3):
                start = time.perf_counter()
                copy(channels, host, read)
                queue.finish()           # a blocking write returns when the host array is free, maybe sooner
                seconds.append(time.perf_counter() - start)
            print(f"  {'read' if read else 'write'} {channels} of 8 doubles, {label:24s} {1000 * min(seconds):8.1f} ms")
EOF
fi

step "done in $(( $(date +%s) - start )) s: $out"
exit $failed
