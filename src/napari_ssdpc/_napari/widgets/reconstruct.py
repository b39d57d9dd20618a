"""The Reconstruct widget: the current frame, or every frame of a series, into RI layers."""

from __future__ import annotations

import weakref

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Container, FloatSpinBox, SpinBox

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.reader import result_layer
from napari_ssdpc._napari.widgets.common import follow_layers, frame_index, image_layer_choices, run_buttons, show_layer
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc._napari.widgets.session import build_reconstructor, session_for
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.reconstruction import ReconstructionSettings

__all__ = ["OUTPUTS", "ReconstructWidget", "result_arrays"]


OUTPUTS = {  # checkbox attribute -> (label, quantities)
    "out_delta_n": ("Δn", ("delta_n",)),
    "out_phase": ("phase", ("phase",)),
    "out_absorption": ("absorption", ("absorption",)),
    "out_dpc": ("DPC", ("dpc_ud", "dpc_lr")),
    "out_stacks": ("directional stacks", ("stack_up", "stack_down", "stack_left", "stack_right")),
}


def result_arrays(res) -> dict:
    """Every quantity of a core Result as (z, y, x) float32 arrays (missing ones left out)."""
    out = {"ri": res.ri, "delta_n": res.delta_n, "phase": res.phase}
    if res.absorption is not None:
        out["absorption"] = res.absorption
    out.update({f"dpc_{k}": v for k, v in (res.dpc or {}).items()})
    out.update({f"stack_{k}": v for k, v in (res.stacks or {}).items()})
    return out


class ReconstructWidget(Container):
    """Reconstruct the current frame, or every frame of a (t, y, x) series, into RI layers."""

    def __init__(self, napari_viewer):
        super().__init__(labels=True)
        self.viewer = napari_viewer
        self.session = session_for(napari_viewer)
        self.session.reconstruct_widget = weakref.ref(self)
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
        for attr, (label, _) in OUTPUTS.items():
            setattr(
                self,
                attr,
                CheckBox(text=f"add {label}", value=False, tooltip=f"also add the {label} layer(s) (µm scale)"),
            )
        self.run_button, self.cancel_button, self.status = run_buttons("Reconstruct", "RI volume of the frame(s)")
        self.extend(
            [
                self.raw,
                self.flat,
                self.iterations,
                self.alpha,
                self.frames,
                *(getattr(self, a) for a in OUTPUTS),
                self.run_button,
                self.cancel_button,
                self.status,
            ]
        )
        self.runner = JobRunner("Reconstruct", self.run_button, self.cancel_button, self.status)
        self.run_button.changed.connect(self.run)
        self.session.optics_loaded.connect(self._defaults)
        follow_layers(napari_viewer, self)

    def _defaults(self, optics):
        rec = ReconstructionSettings().to_dict()
        self.iterations.value = int(rec["rl_iterations"])
        self.alpha.value = float(rec["tikhonov_alpha"] or 0.0)

    def operator_settings(self) -> dict:
        flat = self.flat.value
        return {"flat": None if flat is None else flat.data, "alpha": float(self.alpha.value) or None}

    def quantities(self) -> list[str]:
        out = ["ri"]
        for attr, (_, qs) in OUTPUTS.items():
            if getattr(self, attr).value:
                out += list(qs)
        return out

    def run(self, *_):
        layer = self.raw.value
        if layer is None:
            notify.error("no raw frame: open a light-field frame (or the sample data) first")
            return None
        try:
            spec = self.session.spec()
        except SsdpcError as e:
            notify.error(e)
            return None
        wanted = self.quantities()
        needs_rl = [q for q in wanted if q.startswith(("dpc", "stack")) or q == "absorption"]
        if needs_rl and not spec["stacks"] and spec["method"] != "rl":
            notify.error(f"{needs_rl[0]} needs the directional stacks: tick 'directional stacks' in Operators")
            return None
        data = layer.data
        t = frame_index(self.viewer, layer)
        series = t is not None and self.frames.value == "all frames"
        indices = list(range(data.shape[0])) if series else [t]
        built = self.session.matching(spec)
        iterations = int(self.iterations.value)

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
                arrays = result_arrays(res)
                for q in wanted:
                    if q in arrays:
                        collected.setdefault(q, []).append(arrays[q])
            out = {q: (np.stack(v) if series else v[0]) for q, v in collected.items()}
            return rec, out, res

        return self.runner.start(work, lambda r: self._done(spec, layer.name, indices, *r), "Reconstruct")

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
        shape = next(iter(arrays.values())).shape
        return f"{source}: {' × '.join(map(str, shape))} voxels of {' × '.join(f'{v:.3g}' for v in res.voxel_um)} µm"
