"""Animation frames on a Dask farm (:class:`clsky.farm.Farm`): ``clsky animate --workers N`` / ``--scheduler``.

What runs where:

- The client (the ``clsky animate`` process) checks the outputs, plans the scene and builds the table
  once (:func:`clsky.anim.animate.make_table`), exactly as a single-process run does.
- The table goes to the workers as the bytes of its table file (:meth:`clsky.ScatteringTable.save`; one
  file per batch of a spectral table), inside a Dask worker plugin that every worker receives, those
  that join or restart later included. A worker writes them to a private temporary file and reads them
  with :meth:`clsky.ScatteringTable.load`: every check of a table file (checksums, parameters hash,
  shapes, values) runs on each worker. Then, on its first frame, it builds its own OpenCL context (in a
  process started with ``spawn``), renderer, camera directions and display pipeline.
- Each frame is two tasks. ``render``: the HDR frames (:func:`clsky.anim.animate.render_frame`), kept in
  the worker's memory; with auto-exposure, a small ``meter`` task returns the frame's metered EV
  (:meth:`clsky.anim.display.Display.metered_ev`). The client smooths the EVs in frame order
  (:meth:`~clsky.anim.display.Display.next_ev`, the one sequential step of the frame loop), then
  ``finish`` (:func:`clsky.anim.animate.frame_outputs`: display values, metrics, composite) runs on the
  worker holding the HDR frames and returns the 8-bit image, the metrics row and, with ``--hdr``, the
  HDR frame.
- The results come back in frame order, at most ``window`` frames in flight, to the single writer of
  the normal path (:func:`clsky.anim.animate._write_animation`): the same staged, atomic outputs, the
  same metrics JSON, PNG, MP4 and EXR files, bit for bit those of a single-process run
  (tests/test_farm.py).
- A lost worker costs the frames it held: Dask reruns their tasks on the other workers (and the
  LocalCluster's nanny restarts the process).
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import pathlib
import tempfile
import threading

import numpy as np

from clsky.farm import Farm, check_window, result_of, translate_errors

try:                                                      # the plugin needs Dask; the module imports without it
    from distributed import WorkerPlugin as _WorkerPlugin
except ImportError:                                       # pragma: no cover - Farm refuses to start first
    _WorkerPlugin = object

__all__ = ["animation_frames", "table_payload", "load_table_payload"]


def table_payload(table) -> dict:
    """What workers receive of an animation's table: the bytes of its table file
    (:meth:`clsky.ScatteringTable.save`), or for a :class:`clsky.spectrum.SpectralTable` those of each
    batch's table with its wavelengths and record."""
    from clsky.spectrum import SpectralTable

    tables = table.tables if isinstance(table, SpectralTable) else (table,)
    with tempfile.TemporaryDirectory(prefix="clsky-farm-") as directory:
        files = []
        for index, batch in enumerate(tables):
            path = batch.save(pathlib.Path(directory) / f"table_{index}.npz")
            files.append(path.read_bytes())
    if isinstance(table, SpectralTable):
        return {"files": files, "wavelengths": np.asarray(table.wavelengths).tolist(), "record": dict(table.record)}
    return {"files": files}


def load_table_payload(payload):
    """The table of :func:`table_payload`'s ``payload``, each file read by :meth:`clsky.ScatteringTable.load`
    (every check of a table file; :class:`clsky.table.TableFormatError` for a damaged one)."""
    from clsky.spectrum import SpectralTable
    from clsky.table import ScatteringTable

    tables = []
    with tempfile.TemporaryDirectory(prefix="clsky-farm-") as directory:
        for index, data in enumerate(payload["files"]):
            path = pathlib.Path(directory) / f"table_{index}.npz"
            path.write_bytes(data)
            tables.append(ScatteringTable.load(path))
    if "wavelengths" in payload:
        return SpectralTable(np.asarray(payload["wavelengths"], dtype=np.float64), tuple(tables), payload["record"])
    return tables[0]


@dataclasses.dataclass(frozen=True)
class _Job:
    """One animation on the farm: its token (in task keys and the plugin's name), config, table payload
    and lookup (:func:`clsky.anim.animate.lookup_of`, chosen by the client)."""

    token: str
    config: object
    payload: dict
    lookup: str | None


#: On a worker: the jobs its plugins delivered ({token: _Job}) and their states, built on first use.
_JOBS: dict = {}
_STATES: dict = {}
_STATES_LOCK = threading.Lock()


class _JobPlugin(_WorkerPlugin):
    """Delivers a job to every worker (those joining later too) and forgets it at the end of the run."""

    def __init__(self, job: _Job):
        self.job = job
        self.name = f"clsky-animation-{job.token}"

    def setup(self, worker):
        _JOBS[self.job.token] = self.job

    def teardown(self, worker):
        _JOBS.pop(self.job.token, None)
        with _STATES_LOCK:
            state = _STATES.pop(self.job.token, None)
        if state is not None:
            state.close()


class _WorkerState:
    """A worker's renderer of one job: the table loaded from its payload, the worker's own OpenCL
    context (the process's default), the camera's directions and the display pipeline."""

    def __init__(self, job: _Job):
        from .animate import _camera, display, renderer_of

        self.config, self.lookup = job.config, job.lookup
        self.table = load_table_payload(job.payload)
        self.renderer = renderer_of(self.config, self.table)
        try:
            directions, self.valid = _camera(self.config).directions()
            self.prepared = self.renderer.prepare(directions, self.valid)
            self.pipeline = display(self.config, self.table)
        except BaseException:
            self.close()
            raise
        self.lock = threading.Lock()          # kernel calls are not thread-safe (a worker of several threads)

    def close(self):
        with contextlib.suppress(Exception):
            self.renderer.close()


def _state(token) -> _WorkerState:
    with _STATES_LOCK:
        if token not in _STATES:
            if token not in _JOBS:
                raise RuntimeError(f"this worker has no clsky animation {token} (its plugin was not delivered)")
            _STATES[token] = _WorkerState(_JOBS[token])
        return _STATES[token]


def _render(token, sun):
    """Task: the HDR frames of sun position ``sun`` (:func:`clsky.anim.animate.render_frame`)."""
    from clsky._cl import host_blas_single_threaded

    from .animate import render_frame

    state = _state(token)
    with state.lock, host_blas_single_threaded():
        return render_frame(state.renderer, state.prepared, sun.direction, state.config, state.lookup)


def _meter(token, hdr):
    """Task: the metered EV of a frame's HDR frames (auto-exposure, before smoothing)."""
    from clsky._cl import host_blas_single_threaded

    from .animate import metered_exposure

    state = _state(token)
    with host_blas_single_threaded():
        return metered_exposure(state.pipeline, hdr, state.valid)


def _finish(token, hdr, sun, index, ev):
    """Task: :func:`clsky.anim.animate.frame_outputs` of frame ``index`` at exposure ``ev``."""
    from clsky._cl import host_blas_single_threaded

    from .animate import frame_outputs

    state = _state(token)
    with host_blas_single_threaded():
        return frame_outputs(state.pipeline, hdr, state.valid, state.config, sun, index, ev=ev)


def animation_frames(farm: Farm, config, table, positions, lookup, window=None):
    """The frame source of an animation on ``farm`` (:func:`clsky.anim.animate.render_animation`'s
    ``farm=``): ``frames(pipeline_of)`` yields each frame's :class:`~clsky.anim.animate.FrameOutputs` in
    order, rendered by the workers (module docstring), with the lookup ``lookup`` (the client's
    :func:`clsky.anim.animate.lookup_of`); ``pipeline_of()`` returns the client's display pipeline, which
    smooths the auto-exposure. At most ``window`` frames are in flight (default: twice the workers'
    threads, at least 4), so that a long or large animation holds a bounded number of HDR frames;
    ValueError naming ``window`` unless it is None or an integer in [1, :data:`clsky.farm.MAX_WINDOW`]."""
    window = check_window(window)

    def frames(pipeline_of):
        pipeline = pipeline_of()
        client = farm.client
        size = window or max(4, 2 * farm.threads)
        job = _Job(farm.new_token(), config, table_payload(table), lookup)
        plugin = _JobPlugin(job)
        rendered, metered, finishing = {}, {}, collections.deque()
        submitted = 0
        try:
            with translate_errors():
                client.register_plugin(plugin)

                def key(stage, index):
                    return f"clsky-{stage}-{job.token}-{index}"

                for index in range(len(positions)):
                    while submitted < min(len(positions), index + size):
                        rendered[submitted] = client.submit(_render, job.token, positions[submitted],
                                                            key=key("render", submitted), pure=False)
                        if pipeline.auto_exposure is not None:
                            metered[submitted] = client.submit(_meter, job.token, rendered[submitted],
                                                               key=key("meter", submitted), pure=False)
                        submitted += 1
                    ev = pipeline.next_ev(result_of(metered.pop(index)) if index in metered else None)
                    finishing.append(client.submit(_finish, job.token, rendered.pop(index), positions[index], index,
                                                   ev, key=key("finish", index), pure=False))
                    while finishing and (finishing[0].done() or len(finishing) >= size):
                        yield result_of(finishing.popleft())
                while finishing:
                    yield result_of(finishing.popleft())
        finally:
            left = list(rendered.values()) + list(metered.values()) + list(finishing)
            with contextlib.suppress(Exception):
                if left:
                    client.cancel(left)
            with contextlib.suppress(Exception):
                client.unregister_worker_plugin(plugin.name)
    return frames
