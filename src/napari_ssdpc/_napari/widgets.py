"""napari dock widgets: Optics, Calibrate, Operators, Reconstruct (the line-profile dock is in
``_profiles.py``).

The widgets are thin: they collect settings, call ``core`` and turn the results into layers.
The four widgets of one viewer share a ``Session`` (the optics, the built operators).

Threading: every long step runs in a generator ``thread_worker``. The core
function runs in a helper thread and reports ``progress(done, total, label)``; the generator
relays each report with ``yield``, so napari's progress bar and the widget's status follow it.
Cancel sets a stop flag that the core checks every iteration (``should_stop``) and that the
progress callback checks at every report, so a job stops within one iteration. Layers are only
touched in the ``yielded``/``returned`` callbacks, on the main thread. A ``SsdpcError`` from
``core`` becomes a napari error notification with the core's one-line message, a
``SsdpcWarning`` a napari warning (once per job).
"""

from __future__ import annotations

import queue
import textwrap
import threading
import warnings
import weakref
from dataclasses import dataclass

import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Container, FileEdit, FloatSpinBox, Label, LineEdit, PushButton, SpinBox
from napari.qt.threading import create_worker
from napari.utils import progress as napari_progress
from napari.utils.notifications import show_error, show_info, show_warning
from psygnal import Signal

from napari_ssdpc._napari.reader import calibration_layers, result_layer
from napari_ssdpc.errors import SsdpcError, SsdpcWarning
from napari_ssdpc.physics.design import design
from napari_ssdpc.settings.base import field_range
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import PHASE_METHODS, SIGNS, TRANSFER_MODELS, ReconstructionSettings


# =============================================================================== session
class Session:
    """State shared by the widgets of one viewer: the optics and the last built operators."""

    optics_changed = Signal(object)  # any edit of the optics
    optics_loaded = Signal(object)  # a new optics file/preset: widgets reset their defaults
    operators_built = Signal(object)

    def __init__(self):
        self.optics = Optics.paper()
        self.built = None  # (spec, Reconstructor)
        self.operators_widget = None  # weak references, set by the widgets
        self.reconstruct_widget = None

    def set_optics(self, optics: Optics, loaded: bool = False):
        self.optics = optics
        self.optics_changed.emit(optics)
        if loaded:
            self.optics_loaded.emit(optics)

    def spec(self) -> dict:
        """Everything a Reconstructor is built from: the Operators widget's z range, dz, model,
        method and calibration, and the Reconstruct widget's flat frame and α."""
        rec = ReconstructionSettings().to_dict()
        spec = {
            "optics": self.optics,
            "calibration": None,
            "z": (float(rec["z_min_um"]), float(rec["z_max_um"])),
            "dz": float(rec["dz_um"]),
            "model": rec["model"],
            "method": rec["method"],
            "stacks": False,  # RL stacks only when DPC, stacks, absorption or the PSF are asked for
            "alpha": rec["tikhonov_alpha"],
            "tv": {k: rec[k] for k in ("sign", "tv_lambda", "tv_iterations")},
            "flat": None,
        }
        for ref in (self.operators_widget, self.reconstruct_widget):
            w = ref() if ref is not None else None
            if w is not None:
                spec.update(w.operator_settings())
        return spec

    def matching(self, spec):
        """The built Reconstructor if it was made from exactly ``spec``, else None."""
        if self.built is None:
            return None
        old, rec = self.built
        same = all((old[k] is spec[k]) if k in ("optics", "calibration", "flat") else old[k] == spec[k] for k in spec)
        return rec if same else None


_SESSIONS: dict[int, tuple] = {}


def real_viewer(viewer):
    """The viewer behind napari's plugin proxy.

    napari hands every dock widget opened from the Plugins menu its own ``PublicOnlyProxy`` of
    the viewer; keyed on the proxy, each widget would get its own session and never see the
    calibration or the optics another one set.
    """
    while hasattr(type(viewer), "__wrapped__") or type(viewer).__name__ == "PublicOnlyProxy":
        inner = getattr(viewer, "__wrapped__", None)
        if inner is None or inner is viewer:
            break
        viewer = inner
    return viewer


def session_for(viewer) -> Session:
    """The Session of ``viewer`` (one per real viewer, created on first use; proxies share it)."""
    viewer = real_viewer(viewer)
    key = id(viewer)
    ref, session = _SESSIONS.get(key, (None, None))
    if ref is None or ref() is not viewer:
        session = Session()
        _SESSIONS[key] = (weakref.ref(viewer), session)
        weakref.finalize(viewer, _SESSIONS.pop, key, None)  # free the operators with the viewer
    return session


def calibration_of(layer):
    """The Calibration stored in a calibration layer's metadata (cached on the metadata dict)."""
    from napari_ssdpc.calibration.calibrate import Calibration

    info = layer.metadata.get("ssdpc", {})
    if "_object" not in info:
        info["_object"] = Calibration.from_dict(info["calibration"], source=f"layer '{layer.name}'")
    return info["_object"]


def build_reconstructor(spec, progress=None):
    """A core Reconstructor from a session spec (called in the worker thread)."""
    from napari_ssdpc.reconstruction.pipeline import Reconstructor

    if spec["calibration"] is None:
        raise SsdpcError("no calibration: run Calibrate on a white frame, or open a calibration JSON")
    flat = None if spec["flat"] is None else np.asarray(spec["flat"])
    return Reconstructor(
        spec["optics"],
        spec["calibration"],
        ReconstructionSettings.from_dict(spec["tv"], source="TV settings"),
        z=spec["z"],
        dz=spec["dz"],
        model=spec["model"],
        method=spec["method"],
        stacks=spec["stacks"],
        alpha=spec["alpha"],
        flat=flat,
        progress=progress,
    )


# ================================================================================== jobs
@dataclass
class Outcome:
    value: object = None
    error: str | None = None
    cancelled: bool = False


def _relay(fn, stop: threading.Event):
    """Run ``fn(progress, should_stop)`` in a helper thread and yield its progress reports
    ``(done, total, label)`` as they arrive; return its result or raise its exception."""
    from napari_ssdpc.reconstruction.pipeline import Cancelled

    reports: queue.Queue = queue.Queue()
    box = {}

    def progress(done, total, label=""):
        if stop.is_set():
            raise Cancelled("cancelled")
        reports.put((int(done), int(total), str(label)))

    def target():
        try:
            box["value"] = fn(progress, stop.is_set)
        except BaseException as e:  # handed to the generator, re-raised there
            box["error"] = e
        finally:
            reports.put(None)

    thread = threading.Thread(target=target, name="napari-ssdpc job", daemon=True)
    thread.start()
    try:
        while (msg := reports.get()) is not None:
            yield msg
    finally:
        if thread.is_alive():  # closed early: stop the core at its next iteration
            stop.set()
        thread.join()
    if "error" in box:
        raise box["error"]
    return box["value"]


def _job(fn, stop):
    """Generator run by the thread_worker: progress reports, then an Outcome."""
    from napari_ssdpc.reconstruction.pipeline import Cancelled

    try:
        value = yield from _relay(fn, stop)
    except Cancelled:
        return Outcome(cancelled=True)
    except SsdpcError as e:
        return Outcome(error=str(e))
    return Outcome(value=value)


class JobRunner:
    """Run/Cancel buttons, a status line and a napari progress bar around one job at a time."""

    def __init__(self, title: str, run: PushButton, cancel: PushButton, status: Label):
        self.title, self.run_button, self.cancel_button, self.status = title, run, cancel, status
        self.worker = None
        self._stop = None
        self._pbar = None
        self._in_update = False
        cancel.enabled = False
        cancel.changed.connect(self.cancel)

    @property
    def running(self) -> bool:
        return self.worker is not None

    def start(self, fn, on_result, label: str):
        if self.running:
            show_info(f"{self.title} is already running; cancel it first")
            return None
        self._stop = threading.Event()
        self._warned = set()
        self._pbar = napari_progress(total=0, desc=label)
        self.status.value = f"{label}…"
        self.run_button.enabled = False
        self.cancel_button.enabled = True
        worker = create_worker(_job, fn, self._stop, _start_thread=False)
        worker.yielded.connect(self._on_progress)
        worker.warned.connect(self._on_warning)
        worker.returned.connect(lambda out: self._on_returned(out, on_result))
        worker.aborted.connect(self._on_aborted)
        worker.finished.connect(self._on_finished)
        self.worker = worker
        worker.start()
        return worker

    def cancel(self, *_):
        if self._stop is not None:
            self._stop.set()
            self.status.value = "cancelling…"

    def _on_progress(self, msg):
        done, total, label = msg
        pbar = self._pbar
        if pbar is None:
            return
        self.status.value = f"{label} {done}/{total}" if total else label
        if self._in_update:  # napari's progress bar may process events while it repaints
            return
        self._in_update = True
        try:
            if pbar.total != total:
                pbar.total = total
            pbar.set_description(label)
            pbar.update(done - pbar.n)
        finally:
            self._in_update = False

    def _on_aborted(self):
        """napari's own cancel (worker.quit): stop the core too."""
        if self._stop is not None:
            self._stop.set()
        self.status.value = "cancelled"

    def _on_warning(self, args):
        """A warning raised while the job ran (worker.warned gives showwarning's arguments): core
        warnings become napari warnings, each message once per job."""
        message, category = args[0], args[1]
        if issubclass(category, SsdpcWarning) and str(message) not in self._warned:
            self._warned.add(str(message))
            show_warning(str(message))

    def _on_returned(self, out: Outcome, on_result):
        if out.cancelled:
            self.status.value = "cancelled"
            show_info(f"{self.title}: cancelled")
        elif out.error is not None:
            self.status.value = f"error: {out.error}"
            show_error(out.error)
        else:
            try:
                msg = on_result(out.value)
            except SsdpcError as e:
                self.status.value = f"error: {e}"
                show_error(str(e))
            else:
                self.status.value = msg or "done"

    def _on_finished(self):
        if self._pbar is not None:
            self._pbar.close()
        self._pbar = None
        self.worker = None
        self.run_button.enabled = True
        self.cancel_button.enabled = False


# ================================================================================ helpers
def _notify_error(e: Exception):
    show_error(str(e))


def _image_layers(viewer, ndims=(2, 3), allow_none: str | None = None, prefer: str = ""):
    """Choices callable for a ComboBox of raw image layers: the top of the layer list first, layers
    whose name contains ``prefer`` before all others (the default choice), then ``allow_none``."""
    from napari.layers import Image

    def choices(_widget=None):
        layers = [
            lyr
            for lyr in reversed(viewer.layers)
            if isinstance(lyr, Image) and lyr.ndim in ndims and lyr.metadata.get("ssdpc", {}).get("kind") != "result"
        ]
        first = [lyr for lyr in layers if prefer and prefer in lyr.name.lower()]
        rest = [lyr for lyr in layers if lyr not in first]
        none = [(allow_none, None)] if allow_none else []
        return [(lyr.name, lyr) for lyr in first] + none + [(lyr.name, lyr) for lyr in rest]

    return choices


def _calibration_layers(viewer):
    def choices(_widget=None):
        return [
            (lyr.name, lyr)
            for lyr in viewer.layers
            if lyr.metadata.get("ssdpc", {}).get("kind") == "calibration" and lyr._type_string == "shapes"
        ]

    return choices


def _follow_layers(viewer, container: Container):
    """Refresh the container's layer choices when layers come, go, move or are renamed (also when
    the widget is used outside a dock); a closed widget is left alone."""
    ref = weakref.ref(container)

    def refresh(*_):
        w = ref()
        if w is not None:
            try:
                w.reset_choices()
            except RuntimeError:  # the Qt widget was deleted with its dock
                pass

    ev = viewer.layers.events
    for e in (ev.inserted, ev.removed, ev.reordered):
        e.connect(refresh)
    ev.inserted.connect(lambda event: event.value.events.name.connect(refresh))


def frame_index(viewer, layer) -> int | None:
    """Time index of ``layer`` (t, y, x) at the viewer's current position; None for a 2D frame."""
    if layer.ndim < 3:
        return None
    pos = layer.world_to_data(viewer.dims.point)
    return int(np.clip(round(float(pos[0])), 0, layer.data.shape[0] - 1))


def show_layer(viewer, data, kwargs: dict, layer_type: str = "image"):
    """Add a layer, or update the one of the same name in place (same object, same position).
    A layer whose dimensionality changes (a frame, then a series) is replaced at its position."""
    name = kwargs["name"]
    if name in viewer.layers:
        old = viewer.layers[name]
        if layer_type == "image" and old._type_string == "image" and old.ndim == np.ndim(data):
            old.data = data
            # the display choices (colormap, rendering, ...) stay as the user left them
            for key in ("scale", "translate", "metadata", "contrast_limits", "axis_labels", "units"):
                if key in kwargs:
                    setattr(old, key, kwargs[key])
            return old
        index = viewer.layers.index(old)
        viewer.layers.remove(old)
        new = getattr(viewer, f"add_{layer_type}")(data, **kwargs)
        viewer.layers.move(viewer.layers.index(new), index)
        return new
    return getattr(viewer, f"add_{layer_type}")(data, **kwargs)


def _catch_warnings(fn, *args, **kwargs):
    """Call fn; show each SsdpcWarning it raises as a napari warning notification."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SsdpcWarning)
        out = fn(*args, **kwargs)
    for w in caught:
        if issubclass(w.category, SsdpcWarning):
            show_warning(str(w.message))
    return out


def _buttons(run_text: str, run_tip: str):
    run = PushButton(text=run_text, tooltip=run_tip)
    cancel = PushButton(text="Cancel", tooltip="stop the running job within one iteration")
    status = Label(value="")
    return run, cancel, status


# ================================================================================= optics
# attribute, label, tooltip, (min, max, step) or "int"/"bool"
OPTICS_FIELDS = [
    (
        "wavelength_um",
        "wavelength (µm)",
        "vacuum wavelength of the illumination, µm (520 nm = 0.52)",
        (0.2, 2.0, 0.001),
    ),
    (
        "medium_index",
        "medium index",
        "refractive index of the immersion / embedding medium (no unit)",
        (1.0, 2.5, 0.001),
    ),
    (
        "condenser_na",
        "condenser NA",
        "illumination NA (no unit); must stay below the objective NA (σ < 1) for phase contrast",
        (0.0, 1.6, 0.01),
    ),
    ("magnification", "objective M", "objective magnification (×)", (1.0, 200.0, 1.0)),
    ("na", "objective NA", "objective numerical aperture (no unit)", (0.01, 1.7, 0.01)),
    ("tube_lens_mm", "tube lens (mm)", "focal length of the tube lens, mm", (20.0, 1000.0, 1.0)),
    ("fourier_lens_mm", "Fourier lens (mm)", "focal length of the Fourier lens f_fl, mm", (5.0, 2000.0, 0.5)),
    ("pitch_um", "MLA pitch (µm)", "microlens pitch, µm", (10.0, 10000.0, 1.0)),
    ("mla_focal_length_mm", "MLA focal length (mm)", "microlens focal length f_ml, mm", (0.1, 500.0, 0.1)),
    ("lenslet_radius_um", "lenslet radius (µm)", "clear radius of one microlens, µm", (5.0, 10000.0, 1.0)),
    ("pixel_um", "camera pixel (µm)", "camera pixel size, µm", (0.5, 50.0, 0.01)),
    ("width_px", "sensor width (px)", "sensor width, pixels", "int"),
    ("height_px", "sensor height (px)", "sensor height, pixels", "int"),
    (
        "iris_radius_um",
        "iris radius (µm)",
        "field-iris radius at the native image plane, µm; 0 = EIs tangent (paper Eq. 9)",
        (0.0, 100000.0, 1.0),
    ),
    ("flip_x", "camera flipped in x", "the camera image is mirrored left-right", "bool"),
    ("flip_y", "camera flipped in y", "the camera image is mirrored up-down", "bool"),
]


def design_text(optics: Optics) -> str:
    """The design numbers (paper Eqs. 8-14), a few short lines."""
    d = design(optics)
    return "\n".join(
        [
            f"FOV {d['fov_um']:.1f} µm · R_xy {d['r_xy_um']:.2f} µm",
            f"R_z {d['r_z_ffl_um']:.2f} µm (tanθ = √2·d/f_fl: matches the",
            f"    paper's measured 21.96 µm); {d['r_z_printed_um']:.2f} µm with Eq. 13 as printed",
            f"DOF {d['dof_full_um']:.1f} µm full width (FWHM {d['dof_fwhm_um']:.1f} µm)",
            f"usable depth {d['dof_um']:.1f} µm",
            f"lenslets: {d['lenslets_in_pupil']} in the pupil, {d['lenslets_usable']} usable (≥ 50 % inside)",
            f"source disk: {d['lenslets_inside']} inside, {d['lenslets_straddling']} straddling, "
            f"{d['lenslets_outside']} outside",
            f"σ {d['sigma']:.2f} · M_EI {d['m_ei']:.3f} · object pixel {d['object_pixel_um']:.4f} µm",
            f"pitch {d['pitch_px']:.2f} px · EI radius {d['ei_radius_px']:.2f} px",
        ]
    )


class OpticsWidget(Container):
    """Load, edit and save the optics; the design numbers update live."""

    def __init__(self, napari_viewer):
        super().__init__(labels=True, scrollable=True)
        self.viewer = napari_viewer
        self.session = session_for(napari_viewer)
        self.fields = {}
        for attr, label, tip, spec in OPTICS_FIELDS:
            if spec == "bool":
                w = CheckBox(text=label, tooltip=tip)
            elif spec == "int":
                w = SpinBox(label=label, tooltip=tip, min=16, max=100000, step=1)
            else:
                w = FloatSpinBox(label=label, tooltip=tip, min=spec[0], max=spec[1], step=spec[2])
            self.fields[attr] = w
        self.name = LineEdit(label="name", tooltip="a name for this instrument (free text)")
        self.path = FileEdit(mode="r", filter="*.yaml *.yml")
        self.path.label = "optics YAML"
        self.path.tooltip = "optics file in the schema of docs/paper-optics.yaml (lengths carry their unit)"
        self.load_button = PushButton(text="Load YAML", tooltip="read the optics from the YAML file above")
        self.save_button = PushButton(text="Save YAML…", tooltip="write the optics to a YAML file")
        self.paper_button = PushButton(text="Paper optics", tooltip="the paper's instrument (20×/0.4, f_fl 75 mm)")
        self.layer_button = PushButton(
            text="From selected layer", tooltip="adopt the optics stored with the selected layer (sample data)"
        )
        self.design = Label(value="")
        self.design.tooltip = "design numbers of paper Eqs. 8-14 (µm)"
        self.extend(
            [
                self.path,
                self.load_button,
                self.save_button,
                self.paper_button,
                self.layer_button,
                self.name,
                *self.fields.values(),
                self.design,
            ]
        )
        self._last_error = None
        self._updating = False
        self._show(self.session.optics)
        for w in [*self.fields.values(), self.name]:
            w.changed.connect(self._edited)
        self.load_button.changed.connect(self.load)
        self.save_button.changed.connect(self._save_dialog)
        self.paper_button.changed.connect(lambda *_: self.set_optics(Optics.paper()))
        self.layer_button.changed.connect(self._from_layer)
        self.session.optics_loaded.connect(self._show)

    # ----------------------------------------------------------------------------
    def _show(self, optics: Optics):
        """Fill the fields from ``optics`` without triggering edits."""
        self._updating = True
        try:
            for attr, w in self.fields.items():
                v = getattr(optics, attr)
                w.value = 0.0 if v is None else v
            self.name.value = optics.name
        finally:
            self._updating = False
        self.design.value = design_text(optics)

    def values(self) -> dict:
        v = {attr: w.value for attr, w in self.fields.items()}
        v["iris_radius_um"] = v["iris_radius_um"] or None
        v["name"] = self.name.value
        return v

    def _edited(self, *_):
        if self._updating:
            return
        try:
            optics = _catch_warnings(self.session.optics.replace, **self.values())
        except SsdpcError as e:
            self.design.value = "⚠ " + "\n".join(textwrap.wrap(str(e), 60))
            if str(e) != self._last_error:
                show_error(str(e))
            self._last_error = str(e)
            return
        self._last_error = None
        self.design.value = design_text(optics)
        self.session.set_optics(optics)

    def set_optics(self, optics: Optics):
        self._show(optics)
        self.session.set_optics(optics, loaded=True)

    def load(self, *_):
        try:
            self.set_optics(_catch_warnings(Optics.from_yaml, self.path.value))
        except SsdpcError as e:
            _notify_error(e)

    def save(self, path):
        try:
            self.session.optics.to_yaml(path)
        except OSError as e:
            show_error(f"could not write {path}: {e.strerror}; choose a writable folder")

    def _save_dialog(self, *_):
        from magicgui.widgets import request_values

        got = request_values(
            path={"annotation": "pathlib.Path", "options": {"mode": "w", "filter": "*.yaml"}}, title="Save optics YAML"
        )
        if got and got.get("path"):
            self.save(got["path"])

    def _from_layer(self, *_):
        layer = self.viewer.layers.selection.active
        d = None if layer is None else layer.metadata.get("ssdpc", {}).get("optics")
        if d is None:
            show_error("the selected layer carries no optics; select a sample-data layer or load a YAML")
            return
        try:
            self.set_optics(_catch_warnings(Optics.from_dict, d, source=f"layer '{layer.name}'"))
        except SsdpcError as e:
            _notify_error(e)


# ============================================================================== calibrate
class CalibrateWidget(Container):
    """Detect the lenslet grid on an image layer; adds EI circles and centres layers."""

    def __init__(self, napari_viewer):
        super().__init__(labels=True)
        self.viewer = napari_viewer
        self.session = session_for(napari_viewer)
        self.image = ComboBox(
            label="frame",
            choices=_image_layers(napari_viewer, prefer="white"),
            tooltip="raw frame to calibrate on: best a white frame (condenser fully open); a "
            "flat or sample frame also works, less precisely (±0.5 px)",
        )
        self.kind = ComboBox(
            label="frame kind",
            choices=["auto", "white", "flat", "sample"],
            value="auto",
            tooltip="white: condenser fully open (σ = 1); flat/sample: the sample's condenser "
            "setting; auto: decided from the number of lit lenslets",
        )
        self.run_button, self.cancel_button, self.status = _buttons(
            "Calibrate", "find the lattice and the optical axis"
        )
        self.result = Label(value="")
        self.result.tooltip = "optical axis position (px), lenslet pitch (px), MLA rotation (degrees)"
        self.path = FileEdit(mode="w", filter="*.json")
        self.path.label = "save as"
        self.path.tooltip = "calibration JSON to write (open it again with File > Open)"
        self.save_button = PushButton(text="Save calibration JSON", tooltip="write the last calibration to the path")
        self.extend(
            [
                self.image,
                self.kind,
                self.run_button,
                self.cancel_button,
                self.status,
                self.result,
                self.path,
                self.save_button,
            ]
        )
        self.runner = JobRunner("Calibrate", self.run_button, self.cancel_button, self.status)
        self.calibration = None
        self.run_button.changed.connect(self.run)
        self.save_button.changed.connect(lambda *_: self.save(self.path.value))
        _follow_layers(napari_viewer, self)

    def run(self, *_):
        layer = self.image.value
        if layer is None:
            show_error("no image layer to calibrate: open a white frame (or the sample data) first")
            return None
        data, t, kind, optics = layer.data, frame_index(self.viewer, layer), self.kind.value, self.session.optics

        def work(progress, should_stop):
            from napari_ssdpc.calibration.calibrate import calibrate

            progress(0, 1, "calibrating")
            frame = np.asarray(data if t is None else data[t])
            cal = calibrate(frame, optics, kind=kind)
            progress(1, 1, "calibrated")
            return cal

        return self.runner.start(work, lambda cal: self._done(cal, layer.name), "Calibrate")

    def _done(self, cal, source: str):
        self.calibration = cal
        for data, kwargs, kind in calibration_layers(cal, source):
            show_layer(self.viewer, data, kwargs, kind)
        g = cal.grid
        self.result.value = (
            f"axis (x, y) = ({g.axis_px[0]:.2f}, {g.axis_px[1]:.2f}) px\n"
            f"pitch {g.pitch_px:.3f} px · rotation {g.rotation_deg:+.3f}°\n"
            f"{len(cal.lenslets)} lenslets · lattice rms {cal.residual_px:.3f} px · {cal.kind} frame"
        )
        return f"calibrated on '{source}'"

    def save(self, path):
        if self.calibration is None:
            show_error("nothing to save: run Calibrate first")
            return
        try:
            self.calibration.to_json(path)
        except SsdpcError as e:
            _notify_error(e)


# ============================================================================== operators
class OperatorsWidget(Container):
    """z range, dz and model; builds the PSFs and transfer functions once (a Reconstructor)."""

    def __init__(self, napari_viewer):
        super().__init__(labels=True)
        self.viewer = napari_viewer
        self.session = session_for(napari_viewer)
        self.session.operators_widget = weakref.ref(self)
        rec = ReconstructionSettings().to_dict()
        self.calibration = ComboBox(
            label="calibration",
            choices=_calibration_layers(napari_viewer),
            tooltip="EI-circles layer made by Calibrate or opened from a calibration JSON",
        )
        self.z_min = FloatSpinBox(
            label="z min (µm)",
            min=-5000,
            max=5000,
            step=1,
            value=rec["z_min_um"],
            tooltip="first plane, µm from the focal plane (z > 0: farther from the objective)",
        )
        self.z_max = FloatSpinBox(
            label="z max (µm)",
            min=-5000,
            max=5000,
            step=1,
            value=rec["z_max_um"],
            tooltip="last plane, µm from the focal plane",
        )
        self.dz = FloatSpinBox(
            label="dz (µm)",
            min=0.05,
            max=100,
            step=0.05,
            value=rec["dz_um"],
            tooltip="plane spacing, µm (the paper's axial resolution is about 21 µm)",
        )
        self.model = ComboBox(
            label="transfer model",
            choices=list(TRANSFER_MODELS),
            value=rec["model"],
            tooltip="lenslet: the MLA splits the detection pupil (default); paper: half-disk "
            "sources as in the paper's Eq. 4",
        )
        self.method = ComboBox(
            label="phase method",
            choices=list(PHASE_METHODS),
            value=rec["method"],
            tooltip="tv: all views inverted with total variation, the sign of Δn and the field stop (default);"
            " wotf: 3D Tikhonov with each lenslet's defocused transfer function (fast);"
            " rl: Richardson–Lucy stacks, DPC and Tikhonov per slice (the paper's route)",
        )
        fields = ReconstructionSettings.model_fields
        self.sign = ComboBox(
            label="sign of Δn (tv)", choices=list(SIGNS), value=rec["sign"], tooltip=fields["sign"].description
        )
        lo, hi = field_range(ReconstructionSettings, "tv_lambda")
        self.tv_lambda = FloatSpinBox(
            label="TV weight (tv)",
            min=0.0,
            max=hi,
            step=0.1,
            value=0.0,
            tooltip=f"{fields['tv_lambda'].description}; 0 = automatic, else {lo:g} to {hi:g}",
        )
        lo, hi = field_range(ReconstructionSettings, "tv_iterations")
        self.tv_iterations = SpinBox(
            label="TV iterations (tv)",
            min=int(lo),
            max=int(hi),
            value=rec["tv_iterations"],
            tooltip=fields["tv_iterations"].description,
        )
        self.stacks = CheckBox(
            text="directional stacks (Richardson–Lucy)",
            value=False,
            tooltip="also deconvolve the four halves: needed for DPC, stacks, absorption and the PSF view",
        )
        self.run_button, self.cancel_button, self.status = _buttons(
            "Build operators", "compute the PSFs and transfer functions"
        )
        self.lenslet = ComboBox(
            label="PSF of lenslet",
            choices=self._lenslet_choices,
            tooltip="(row, col) of a lit lenslet of the built operators",
        )
        self.psf_button = PushButton(
            text="Show PSF stack", tooltip="add this lenslet's PSF (z, y, x) as a layer (scale in µm)"
        )
        self.extend(
            [
                self.calibration,
                self.z_min,
                self.z_max,
                self.dz,
                self.model,
                self.method,
                self.sign,
                self.tv_lambda,
                self.tv_iterations,
                self.stacks,
                self.run_button,
                self.cancel_button,
                self.status,
                self.lenslet,
                self.psf_button,
            ]
        )
        self.runner = JobRunner("Operators", self.run_button, self.cancel_button, self.status)
        self.run_button.changed.connect(self.run)
        self.psf_button.changed.connect(self.show_psf)
        self.session.optics_loaded.connect(self._defaults)
        self.session.optics_changed.connect(self._stale)
        self.session.operators_built.connect(self._refresh_lenslets)
        _follow_layers(napari_viewer, self)

    def _defaults(self, optics):
        rec = ReconstructionSettings().to_dict()
        self.z_min.value, self.z_max.value, self.dz.value = rec["z_min_um"], rec["z_max_um"], rec["dz_um"]
        self.model.value, self.method.value = rec["model"], rec["method"]

    def _stale(self, _optics):
        if self.session.built is not None and not self.runner.running:
            self.status.value = "optics changed: the operators are rebuilt at the next run"

    def _refresh_lenslets(self, _rec):
        self.lenslet.reset_choices()

    def _lenslet_choices(self, _widget=None):
        rec = self.session.built[1] if self.session.built else None
        if rec is None:
            return []
        return [(f"({ln.row}, {ln.col})", i) for i, ln in enumerate(rec.lenslets)]

    def operator_settings(self) -> dict:
        layer = self.calibration.value
        return {
            "calibration": None if layer is None else calibration_of(layer),
            "z": (float(self.z_min.value), float(self.z_max.value)),
            "dz": float(self.dz.value),
            "model": self.model.value,
            "method": self.method.value,
            "stacks": bool(self.stacks.value),
            "tv": {
                "sign": self.sign.value,
                "tv_lambda": float(self.tv_lambda.value) or None,
                "tv_iterations": int(self.tv_iterations.value),
            },
        }

    def run(self, *_):
        try:
            spec = self.session.spec()
        except SsdpcError as e:
            _notify_error(e)
            return None

        def work(progress, should_stop):
            return build_reconstructor(spec, progress)

        return self.runner.start(work, lambda rec: self._done(spec, rec), "Operators")

    def _done(self, spec, rec):
        self.session.built = (spec, rec)
        self.session.operators_built.emit(rec)
        return (
            f"built: {len(rec.z_um)} planes {rec.z_um[0]:g}…{rec.z_um[-1]:g} µm, {len(rec.lenslets)} lit "
            f"lenslets, {rec.build_seconds:.1f} s"
        )

    def show_psf(self, *_):
        rec = self.session.built[1] if self.session.built else None
        if rec is None or getattr(rec, "psf", None) is None:
            show_error("no PSF operators: tick 'directional stacks' and press Build operators first")
            return None
        k = self.lenslet.value or 0
        ln = rec.lenslets[k]

        def work(progress, should_stop):
            out = []
            for i, z in enumerate(rec.z_um):
                out.append(rec.psf.kernels(float(z))[k])
                progress(i + 1, len(rec.z_um), "PSF")
            return np.stack(out)

        def done(stack):
            info = {"source": f"lenslet ({ln.row}, {ln.col})", "medium_index": rec.optics.medium_index}
            data, kwargs, _ = result_layer(
                stack,
                "psf",
                (rec.dz, rec.pixel_um, rec.pixel_um),
                (rec.z_um[0], -(stack.shape[1] // 2) * rec.pixel_um, -(stack.shape[2] // 2) * rec.pixel_um),
                name=f"lenslet ({ln.row}, {ln.col})",
                info=info,
            )
            show_layer(self.viewer, data, kwargs)
            return f"PSF of lenslet ({ln.row}, {ln.col})"

        return self.runner.start(work, done, "PSF")


# ============================================================================ reconstruct
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
            choices=_image_layers(napari_viewer),
            tooltip="raw light-field frame (y, x) or series (t, y, x), camera units",
        )
        self.flat = ComboBox(
            label="flat frame",
            choices=_image_layers(napari_viewer, (2,), "none (model)", "flat"),
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
        self.run_button, self.cancel_button, self.status = _buttons("Reconstruct", "RI volume of the frame(s)")
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
        _follow_layers(napari_viewer, self)

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
            show_error("no raw frame: open a light-field frame (or the sample data) first")
            return None
        try:
            spec = self.session.spec()
        except SsdpcError as e:
            _notify_error(e)
            return None
        wanted = self.quantities()
        needs_rl = [q for q in wanted if q.startswith(("dpc", "stack")) or q == "absorption"]
        if needs_rl and not spec["stacks"] and spec["method"] != "rl":
            show_error(f"{needs_rl[0]} needs the directional stacks: tick 'directional stacks' in Operators")
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
