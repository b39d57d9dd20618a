"""The Reconstruct widget: the current frame, or every frame of a series, into RI layers."""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, FileEdit, FloatSpinBox, SpinBox
from qtpy.QtCore import QTimer

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.layers import axial_fwhm_um, resolution_text, result_arrays, result_layer
from napari_ssdpc._napari.store_view import StoreView
from napari_ssdpc._napari.turns import later
from napari_ssdpc._napari.widgets.camera import LiveCamera
from napari_ssdpc._napari.widgets.choices import (
    LayerChoice,
    image_layer_choices,
    same_recording_flat,
    shapes_layer_choices,
)
from napari_ssdpc._napari.widgets.common import (
    StepWidget,
    follow_layers,
    frame_index,
    region_um,
    run_buttons,
    show_in_turns,
)
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc._napari.widgets.live import LiveFollow
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.pipeline.run import Pipeline
from napari_ssdpc.pipeline.sinks import MemorySink, ZarrSink
from napari_ssdpc.settings.base import field_range
from napari_ssdpc.settings.outputs import QUANTITIES
from napari_ssdpc.settings.reconstruction import ReconstructionSettings, RlSettings, alpha_section

__all__ = ["WATCH_MS", "ReconstructWidget"]

#: How often a series written to disk is shown again while it runs, ms.
WATCH_MS = 1000


class ReconstructWidget(StepWidget):
    """Reconstruct the current frame, or every frame of a (t, y, x) series, into RI layers."""

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer, "reconstruct_widget")
        rec = ReconstructionSettings()
        self.raw = LayerChoice(
            label="raw frame(s)",
            choices=image_layer_choices(napari_viewer),
            tooltip="raw light-field frame (y, x) or series (t, y, x), camera units (default: the newest frame "
            "that is neither a white nor a flat frame)",
        )
        self.flat = LayerChoice(
            prefer=same_recording_flat(self.raw),
            label="flat frame",
            choices=image_layer_choices(napari_viewer, (2,), "none (model)", "flat"),
            tooltip="flat frame (no sample) at the sample's condenser setting, for flat-fielding (default: the "
            "flat of the raw frame's recording); none: each view is normalised by its median",
        )
        self.raw.changed.connect(lambda *_: self.flat.follow())
        lo, hi = field_range(RlSettings, "iterations")
        self.iterations = SpinBox(
            label="RL iterations",
            min=int(lo),
            max=int(hi),
            value=rec.rl.iterations,
            tooltip="Richardson–Lucy iterations per directional stack (no unit; 10–20 usual)",
        )
        self.alpha = FloatSpinBox(
            label="Tikhonov α",
            min=0.0,
            max=100.0,
            step=1e-4,
            value=0.0,
            tooltip="Tikhonov regularisation of the phase inversion (no unit; paper Eq. 7), "
            "relative to the strongest transfer function; 0 = the method's default",
        )
        self.region = LayerChoice(
            label="multislice region",
            choices=shapes_layer_choices(napari_viewer, "around the objects"),
            tooltip="method 'multislice': a Shapes layer whose shapes (a rectangle drawn over the views or the "
            "RI, µm) bound the region the nonlinear model covers; default: the objects of the 'tv' start "
            "plus a margin",
        )
        self.frames = ComboBox(
            label="frames",
            choices=["current frame", "all frames"],
            value="current frame",
            tooltip="for a (t, y, x) series: only the frame on the time slider, or every frame "
            "into a (t, z, y, x) layer",
        )
        self.outputs = {  # one checkbox per quantity of the registry beside RI
            name: CheckBox(
                text=f"add {q.label}" + (" (RL stacks)" if q.needs_stacks else ""),
                value=False,
                tooltip=f"also add {q.description} ({'2D map' if q.kind == 'map' else 'volume'}, µm scale)",
            )
            for name, q in QUANTITIES.items()
            if name != "ri"
        }
        for name, box in self.outputs.items():
            setattr(self, f"out_{name}", box)
        self.store = FileEdit(mode="w", filter="*.zarr")
        self.store.label = "series to"
        self.store.tooltip = (
            "OME-Zarr folder (NAME.zarr) for 'all frames': each frame is written as it finishes and shown "
            "from disk (the series is never held in memory; a rerun resumes); empty: keep the frames in memory. "
            "Also the store that 'Follow a recording' writes"
        )
        self.run_button, self.cancel_button, self.status = run_buttons("Reconstruct", "RI volume of the frame(s)")
        self.live = LiveFollow(self)  # a recording still being written, into the same store
        self.camera = LiveCamera(self)  # the frames of a Micro-Manager core, as they are acquired
        self.extend(
            [
                self.raw,
                self.flat,
                self.iterations,
                self.alpha,
                self.region,
                self.frames,
                self.store,
                *self.outputs.values(),
                self.run_button,
                *self.live.widgets,
                *self.camera.widgets,
                self.cancel_button,
                self.status,
            ]
        )
        self.runner = JobRunner("Reconstruct", self.run_button, self.cancel_button, self.status)
        self._watch, self.store_view = None, None  # a store being written, shown as it grows (watch)
        self.run_button.changed.connect(self.run)
        self.session.optics_loaded.connect(self._defaults)
        self.session.settings_loaded.connect(self.show_settings)
        follow_layers(napari_viewer, self)

    def _defaults(self, optics):
        self.iterations.value = ReconstructionSettings().rl.iterations
        self.alpha.value = 0.0

    def show_settings(self, rec: ReconstructionSettings) -> None:
        """Show loaded reconstruction settings (RL iterations, Tikhonov α; 0 = the default).

        Parameters
        ----------
        rec : ReconstructionSettings
        """
        self.iterations.value = rec.rl.iterations
        default = getattr(ReconstructionSettings(), alpha_section(rec.method)).alpha
        self.alpha.value = 0.0 if rec.alpha == default else rec.alpha

    def settings_changes(self) -> dict:
        """The reconstruction keys this widget shows (see :meth:`Session.settings`).

        Returns
        -------
        dict
            RL iterations, the chosen method's α unless 0 (its default), and the multislice region
            when a Shapes layer is chosen.
        """
        alpha = float(self.alpha.value)
        out = {"rl": {"iterations": int(self.iterations.value)}, **({"*": {"alpha": alpha}} if alpha else {})}
        if self.region.value is not None:
            out["multislice"] = {"roi_um": region_um(self.region.value)}
        return out

    def inputs(self) -> dict:
        """The flat frame's data, or None (see :meth:`Session.job`)."""
        flat = self.flat.value
        return {"flat": None if flat is None else flat.data}

    def quantities(self) -> list[str]:
        """Registry names to show: RI and every ticked output."""
        return ["ri"] + [name for name, box in self.outputs.items() if box.value]

    def run(self, *_):
        """Reconstruct the current frame, or every frame of a series (in memory or into an OME-Zarr store)."""
        layer = self.raw.value
        if layer is None:
            notify.error("no raw frame: open a light-field frame (or the sample data) first")
            return None
        wanted = self.quantities()
        try:
            job = self.session.job(save=[q for q in wanted if q != "ri"])
            self.session.remember()
        except SsdpcError as e:
            notify.error(e)
            return None
        data, source = layer.data, layer.name
        t = frame_index(self.viewer, layer)
        series = t is not None and self.frames.value == "all frames"
        indices = list(range(data.shape[0])) if series else [t]
        built = self.session.matching(job)
        store = str(self.store.value or "")
        if series and store.endswith(".zarr"):
            return self._stream(layer, job, built, Path(store))
        frames = data if series or t is None else data[t]  # read in the worker: a lazy frame may still be simulated

        def work(progress, should_stop):
            pipeline = Pipeline(job, reconstructor=built, progress=progress)
            todo = frames if series else np.asarray(frames)
            if not series:  # a quick first answer on screen while an iterative method works
                first = pipeline.reconstructor.first_answer(todo)
                if first is not None:
                    rec = pipeline.reconstructor
                    shown = result_layers(source, indices, rec, result_arrays(first, wanted), first)
                    progress.partial((rec, first, *shown))
            sink = MemorySink(keep=lambda res: (result_arrays(res, wanted), res))
            label = {"t": 0}

            def per_frame(t, done, total, result):
                label["t"] = t + 1

            def within(d, n, lab):
                prefix = f"frame {indices[label['t']]} ({label['t'] + 1}/{len(indices)}): " if series else ""
                progress(d, n, prefix + lab)

            pipeline.run(
                todo, sink, progress=False, on_frame=per_frame, iteration_progress=within, should_stop=should_stop
            )
            kept = [sink.frames[i] for i in sorted(sink.frames)]
            out = {q: (np.stack([k[0][q] for k in kept]) if series else kept[0][0][q]) for q in kept[-1][0]}
            rec, res = pipeline.reconstructor, kept[-1][1]
            # the display limits read the data: here, not on the GUI thread
            return (rec, res, *result_layers(source, indices, rec, out, res))

        self._replaced = None
        worker = self.runner.start(
            work,
            lambda r: self._done(job, source, *r),
            "Reconstruct",
            on_partial=lambda r: self._first(source, *r),
        )
        if worker is not None:
            worker.finished.connect(self._take_back_first)
        return worker

    def _first(self, source, rec, res, info, layers):
        """Show the first answer (the layers the result will replace) while the method works."""
        current = {lyr.name: lyr.data for lyr in self.viewer.layers}
        self._replaced = {kw["name"]: current.get(kw["name"]) for _, kw, _ in layers}
        show_in_turns(self.viewer, layers)
        return f"{source}: first answer shown ({res.settings['first_answer']}); {rec.method.name} working…"

    def _take_back_first(self) -> None:
        """A job cancelled or failed after its first answer was shown: its layers go back to what
        they were (removed where they are new); a first answer is never left as the result. On a
        turn after the first answer's own (:func:`..turns.later`)."""
        replaced, self._replaced = self._replaced, None
        if replaced:
            later(partial(_put_back, self.viewer, replaced))

    def _stream(self, layer, job, built, store: Path):
        """Every frame of a series into the OME-Zarr ``store``, shown from disk as frames finish."""
        path = layer.metadata.get("ssdpc", {}).get("path")
        frames = path if path and Path(path).is_file() else layer.data  # a file streams from disk
        try:
            sink = ZarrSink(store, job.config.outputs.save, job.metadata(layer.name))
        except SsdpcError as e:
            notify.error(e)
            return None

        def work(progress, should_stop):
            pipeline = Pipeline(job, reconstructor=built, progress=progress)
            report = pipeline.run(
                frames,
                sink,
                progress=False,
                should_stop=should_stop,
                on_frame=lambda t, done, total, _res: progress(done, total, f"frame {t} written to {store.name}"),
            )
            return pipeline.reconstructor, report

        worker = self.runner.start(work, lambda r: self._streamed(job, *r, store), "Reconstruct")
        if worker is not None:
            self.watch(store, worker)
        return worker

    def watch(self, store: Path, worker, on_shown=None, every_ms: int = WATCH_MS) -> None:
        """Show the store's frames as they are written (unwritten frames are NaN), every
        ``every_ms`` while ``worker`` runs and once more when it has ended.

        Parameters
        ----------
        store : Path
            The OME-Zarr series store being written.
        worker : napari worker
            The job writing it.
        on_shown : callable, optional
            See :class:`~..store_view.StoreView`.
        every_ms : int
            Time between two looks at the store, ms.
        """
        self.store_view = StoreView(self.viewer, on_shown)
        self._watch = QTimer()
        self._watch.timeout.connect(lambda: self.store_view.refresh(store))
        self._watch.start(every_ms)
        worker.finished.connect(lambda: self._watched(store))

    def _watched(self, store: Path) -> None:
        """The job has ended (finished, cancelled or failed): the last look at the store."""
        if self._watch is not None:
            self._watch.stop()
            self._watch = None
        self.store_view.refresh(store)

    def _streamed(self, job, rec, report, store: Path):
        self.session.built = (job, rec)
        self.session.operators_built.emit(rec)
        frames = report.skipped + report.written
        return f"{store.name}: {frames} frames written; {resolution_text(axial_fwhm_um(rec.optics))}"

    def _done(self, job, source, rec, res, info, layers):
        self._replaced = None  # the answer replaces the first one
        self.session.built = (job, rec)
        self.session.operators_built.emit(rec)
        show_in_turns(self.viewer, layers)
        shape = layers[0][0].shape
        return (
            f"{source}: {' × '.join(map(str, shape))} voxels of {' × '.join(f'{v:.3g}' for v in res.voxel_um)} µm; "
            f"{resolution_text(info['axial_fwhm_um'])}"
        )


def _put_back(viewer, replaced: dict) -> None:
    """Layers back to the data they had (``{name: data}``; removed where data is None)."""
    for name, data in replaced.items():
        if name not in viewer.layers:
            continue
        if data is None:
            viewer.layers.remove(name)
        else:
            viewer.layers[name].data = data


def result_layers(source: str, indices, rec, arrays: dict, res) -> tuple[dict, list]:
    """The layer data of a result with their display limits (which read the data: called in the
    worker, not on the GUI thread).

    Parameters
    ----------
    source : str
        The raw layer's name (the layers' name stem).
    indices : list of int or None
        The frames reconstructed.
    rec : Reconstructor
    arrays : dict
        {quantity: array}: (z, y, x) volumes or (y, x) maps, with a leading t axis for a series.
    res : Result
        The (last) frame's result: its grid and settings.

    Returns
    -------
    info : dict
        The metadata the layers carry.
    layers : list of (data, kwargs, 'image')
    """
    optics = rec.optics
    info = {
        "source": source,
        "medium_index": optics.medium_index,
        "wavelength_um": optics.wavelength_um,
        "settings": res.settings,
        "frames": [i for i in indices if i is not None],
        "optics": optics.to_dict(),
        "axial_fwhm_um": axial_fwhm_um(optics),
    }
    origin = (float(res.z_um[0]), float(res.y_um[0]), float(res.x_um[0]))
    return info, [result_layer(a, q, res.voxel_um, origin, name=source, info=info) for q, a in arrays.items()]
