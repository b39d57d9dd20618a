"""The Reconstruct widget: the current frame, or every frame of a series, into RI layers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, FileEdit, FloatSpinBox, SpinBox
from qtpy.QtCore import QTimer

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.layers import result_layer
from napari_ssdpc._napari.placement import scale_bar
from napari_ssdpc._napari.widgets.common import (
    StepWidget,
    follow_layers,
    frame_index,
    image_layer_choices,
    run_buttons,
    show_layer,
)
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc._napari.widgets.session import build_reconstructor
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.outputs import QUANTITIES
from napari_ssdpc.settings.reconstruction import ReconstructionSettings

__all__ = ["WATCH_MS", "ReconstructWidget", "result_arrays"]

#: How often a series written to disk is shown again while it runs, ms.
WATCH_MS = 1000


def result_arrays(res, wanted) -> dict:
    """The wanted quantities of a core Result, channels split ('dpc_ud', 'stack_up', ...).

    Parameters
    ----------
    res : Result
        One reconstructed frame.
    wanted : iterable of str
        Registry names ('ri', 'opd_nm', 'dpc', ...).

    Returns
    -------
    dict
        {layer key: (z, y, x) volume or (y, x) map}; quantities the result does not hold are left out.
    """
    out = {}
    for name in wanted:
        q = QUANTITIES[name]
        value = q.get(res)
        if value is None or (q.kind == "channels" and not value):
            continue
        if q.kind == "channels":
            out.update({k: np.asarray(value[c]) for c, k in zip(q.channels, q.channel_keys())})
        else:
            out[name] = np.asarray(value)
    return out


class ReconstructWidget(StepWidget):
    """Reconstruct the current frame, or every frame of a (t, y, x) series, into RI layers."""

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer, "reconstruct_widget")
        rec = ReconstructionSettings().to_dict()
        self.raw = ComboBox(
            label="raw frame(s)",
            choices=image_layer_choices(napari_viewer),
            tooltip="raw light-field frame (y, x) or series (t, y, x), camera units",
        )
        self.flat = ComboBox(
            label="flat frame",
            choices=image_layer_choices(napari_viewer, (2,), "none (model)", "flat"),
            tooltip="flat frame (no sample) at the sample's condenser setting, for flat-fielding; "
            "none: each view is normalised by its median",
        )
        self.iterations = SpinBox(
            label="RL iterations",
            min=1,
            max=10000,
            value=int(rec["rl_iterations"]),
            tooltip="Richardson–Lucy iterations per directional stack (no unit; 10–20 usual)",
        )
        self.alpha = FloatSpinBox(
            label="Tikhonov α",
            min=0.0,
            max=100.0,
            step=1e-4,
            value=float(rec["tikhonov_alpha"] or 0.0),
            tooltip="Tikhonov regularisation of the phase inversion (no unit; paper Eq. 7), "
            "relative to the strongest transfer function; 0 = the method's default",
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
            "from disk (the series is never held in memory; a rerun resumes); empty: keep the frames in memory"
        )
        self.run_button, self.cancel_button, self.status = run_buttons("Reconstruct", "RI volume of the frame(s)")
        self.extend(
            [
                self.raw,
                self.flat,
                self.iterations,
                self.alpha,
                self.frames,
                self.store,
                *self.outputs.values(),
                self.run_button,
                self.cancel_button,
                self.status,
            ]
        )
        self.runner = JobRunner("Reconstruct", self.run_button, self.cancel_button, self.status)
        self._watch, self._shown_frames = None, -1  # the store being written, shown as it grows
        self.run_button.changed.connect(self.run)
        self.session.optics_loaded.connect(self._defaults)
        self.session.settings_loaded.connect(self.show_settings)
        follow_layers(napari_viewer, self)

    def _defaults(self, optics):
        rec = ReconstructionSettings().to_dict()
        self.iterations.value = int(rec["rl_iterations"])
        self.alpha.value = float(rec["tikhonov_alpha"] or 0.0)

    def show_settings(self, rec: ReconstructionSettings) -> None:
        """Show loaded reconstruction settings (RL iterations, Tikhonov α; 0 = the default).

        Parameters
        ----------
        rec : ReconstructionSettings
        """
        self.iterations.value = rec.rl_iterations
        self.alpha.value = rec.tikhonov_alpha or 0.0

    def run_settings(self) -> dict:
        """Settings of this widget that the operators do not depend on."""
        return {"rl_iterations": int(self.iterations.value)}

    def operator_settings(self) -> dict:
        """What this widget sets of the operators (see Session.spec).

        Returns
        -------
        dict
            ``flat`` (the flat frame's data or None) and ``alpha`` (None: the method's default).
        """
        flat = self.flat.value
        return {"flat": None if flat is None else flat.data, "alpha": float(self.alpha.value) or None}

    def quantities(self) -> list[str]:
        """Registry names to show: RI and every ticked output."""
        return ["ri"] + [name for name, box in self.outputs.items() if box.value]

    def run(self, *_):
        """Reconstruct the current frame, or every frame of a series (in memory or into an OME-Zarr store)."""
        layer = self.raw.value
        if layer is None:
            notify.error("no raw frame: open a light-field frame (or the sample data) first")
            return None
        try:
            spec = self.session.spec()
            self.session.remember()
        except SsdpcError as e:
            notify.error(e)
            return None
        wanted = self.quantities()
        needs_rl = [q for q in wanted if QUANTITIES[q].needs_stacks]
        if needs_rl and not spec["stacks"] and spec["method"] != "rl":
            notify.error(f"{needs_rl[0]} needs the directional stacks: tick 'directional stacks' in Operators")
            return None
        data = layer.data
        t = frame_index(self.viewer, layer)
        series = t is not None and self.frames.value == "all frames"
        indices = list(range(data.shape[0])) if series else [t]
        built = self.session.matching(spec)
        iterations = int(self.iterations.value)
        if series and str(self.store.value or "").endswith(".zarr"):
            return self._stream(layer, spec, wanted, built, iterations, Path(self.store.value))

        def work(progress, should_stop):
            rec = built or build_reconstructor(spec, progress)
            rec.iterations = iterations  # a run-time setting: the operators do not depend on it
            collected, res = {}, None
            for i, ti in enumerate(indices):
                if series:
                    progress(i, len(indices), "reading frames")
                frame = np.asarray(data if ti is None else data[ti])
                prefix = f"frame {ti} ({i + 1}/{len(indices)}): " if series else ""
                res = rec.reconstruct(
                    frame,
                    progress=lambda d, n, lab: progress(d, n, prefix + lab),  # noqa: B023
                    should_stop=should_stop,
                )
                for q, a in result_arrays(res, wanted).items():
                    collected.setdefault(q, []).append(a)
            out = {q: (np.stack(v) if series else v[0]) for q, v in collected.items()}
            return rec, out, res

        return self.runner.start(work, lambda r: self._done(spec, layer.name, indices, *r), "Reconstruct")

    def _stream(self, layer, spec, wanted, built, iterations, store: Path):
        """Every frame of a series into the OME-Zarr ``store``, shown from disk as frames finish."""
        from napari_ssdpc.io.frame_source import FrameSource
        from napari_ssdpc.io.series import Recipe, reconstruct_series

        try:
            settings = self.session.settings()
        except SsdpcError as e:
            notify.error(e)
            return None
        flat = None if spec["flat"] is None else np.asarray(spec["flat"])
        recipe = Recipe(spec["optics"], spec["calibration"], dict(settings=settings, stacks=spec["stacks"]), flat)
        path = layer.metadata.get("ssdpc", {}).get("path")
        frames = path if path and Path(path).is_file() else layer.data  # a file streams from disk
        optics = spec["optics"]
        meta = {"source": layer.name, "optics": optics.to_dict(), "medium_index": optics.medium_index}

        def work(progress, should_stop):
            rec = built or build_reconstructor(spec, progress)
            rec.iterations = iterations
            reconstruct_series(
                FrameSource(frames),
                store,
                recipe,
                save=[q for q in wanted if q != "ri"],
                meta=meta,
                progress=False,
                rec=rec,
                on_frame=lambda t, done, total: progress(done, total, f"frame {t} written to {store.name}"),
            )
            return rec

        worker = self.runner.start(work, lambda rec: self._streamed(spec, rec, store), "Reconstruct")
        if worker is not None:
            self._shown_frames = -1
            self._watch = QTimer()
            self._watch.timeout.connect(lambda: self._show_store(store))
            self._watch.start(WATCH_MS)
        return worker

    def _show_store(self, store: Path) -> None:
        """Show the store's frames written so far (unwritten frames are NaN); stop with the job."""
        from napari_ssdpc._napari.reader import read_result
        from napari_ssdpc.io.store import done_frames

        running = self.runner.running
        if store.is_dir() and (store / "ri").is_dir():
            n = len(done_frames(store))
            if n != self._shown_frames and n > 0:
                self._shown_frames = n
                for data, kwargs, kind in read_result(store):
                    if kwargs["name"] in self.viewer.layers:  # new frames: keep the display as it is
                        kwargs = {k: v for k, v in kwargs.items() if k != "contrast_limits"}
                    show_layer(self.viewer, data, kwargs, kind)
        if not running and self._watch is not None:
            self._watch.stop()
            self._watch = None

    def _streamed(self, spec, rec, store: Path):
        self.session.built = (spec, rec)
        self.session.operators_built.emit(rec)
        self._show_store(store)
        return f"{store.name}: {self._shown_frames} frames written"

    def _done(self, spec, source, indices, rec, arrays, res):
        self.session.built = (spec, rec)
        self.session.operators_built.emit(rec)
        optics = rec.optics
        info = {
            "source": source,
            "medium_index": optics.medium_index,
            "wavelength_um": optics.wavelength_um,
            "settings": res.settings,
            "frames": [i for i in indices if i is not None],
            "optics": optics.to_dict(),
        }
        origin = (float(res.z_um[0]), float(res.y_um[0]), float(res.x_um[0]))
        first = f"{source} RI" not in self.viewer.layers
        for q, a in arrays.items():
            data, kwargs, _ = result_layer(a, q, res.voxel_um, origin, name=source, info=info)
            show_layer(self.viewer, data, kwargs)
        if first:
            # the raw frames live in sensor pixels, the results in µm: hide the inputs, show the volume
            for lyr in self.viewer.layers:
                if lyr.name == source or lyr.metadata.get("ssdpc", {}).get("kind") in ("raw", "calibration"):
                    lyr.visible = False
            self.viewer.fit_to_view(layers=[self.viewer.layers[f"{source} RI"]])
            scale_bar(self.viewer).visible = True  # every layer is in µm now
        shape = next(iter(arrays.values())).shape
        return f"{source}: {' × '.join(map(str, shape))} voxels of {' × '.join(f'{v:.3g}' for v in res.voxel_um)} µm"
