"""The Beads widget: every bead of the current frame fitted as a sphere, shown as points and a table."""

from __future__ import annotations

import numpy as np
from magicgui.widgets import FloatSpinBox, Table

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.widgets.choices import LayerChoice, image_layer_choices
from napari_ssdpc._napari.widgets.common import StepWidget, follow_layers, frame_index, run_buttons, show_layer
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.reconstruction.beads import measure_beads

__all__ = ["BeadsWidget", "bead_table"]

#: The table's columns: (title, the bead's value).
COLUMNS = (
    ("x (µm)", lambda b: round(b.centre_um[0], 2)),
    ("y (µm)", lambda b: round(b.centre_um[1], 2)),
    ("z (µm)", lambda b: round(b.centre_um[2], 2)),
    ("diameter (µm)", lambda b: round(b.diameter_um, 3)),
    ("RI", lambda b: round(b.ri, 4)),
    ("residual / noise", lambda b: None if b.residual_over_noise is None else round(b.residual_over_noise, 1)),
    ("voxels / sphere", lambda b: None if b.first_answer_ratio is None else round(b.first_answer_ratio, 2)),
    ("check", lambda b: b.note or "ok"),
)


def bead_table(beads) -> dict:
    """The beads as table columns.

    Parameters
    ----------
    beads : list of Bead

    Returns
    -------
    dict
        {column title: list of values}, one row per bead.
    """
    return {title: [get(b) for b in beads] for title, get in COLUMNS}


class BeadsWidget(StepWidget):
    """Fit every bead of the current frame as a sphere (centre, diameter, RI): points and a table.

    It uses the dock's calibration, flat and settings (the operators already built are reused).
    """

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer)
        self.raw = LayerChoice(
            label="raw frame",
            choices=image_layer_choices(napari_viewer),
            tooltip="the light-field frame with the beads (the frame on the time slider of a series)",
        )
        self.search = FloatSpinBox(
            label="depth search (µm)",
            min=0.0,
            max=60.0,
            step=1.0,
            value=12.0,
            tooltip="look for each bead this far above and below the depth of the first ('tv') answer, µm",
        )
        self.run_button, self.cancel_button, self.status = run_buttons(
            "Fit beads", "fit every bead of the frame as a sphere with the multislice model of the views"
        )
        self.table = Table(value=bead_table([]))
        self.extend([self.raw, self.search, self.run_button, self.cancel_button, self.status, self.table])
        self.runner = JobRunner("Beads", self.run_button, self.cancel_button, self.status)
        self.run_button.changed.connect(self.run)
        follow_layers(napari_viewer, self)

    def run(self, *_):
        """Fit the beads of the chosen frame in the background."""
        layer = self.raw.value
        if layer is None:
            notify.error("no raw frame: open a light-field frame of beads (or the sample data) first")
            return None
        try:
            job = self.session.job()
        except SsdpcError as e:
            notify.error(e)
            return None
        t = frame_index(self.viewer, layer)
        frame = np.asarray(layer.data if t is None else layer.data[t])
        built = self.session.matching(job)
        search = float(self.search.value)

        def work(progress, should_stop):
            rec = built if built is not None else job.build(progress=progress)
            return rec, measure_beads(rec, frame, progress=progress, should_stop=should_stop, z_search_um=search)

        return self.runner.start(work, lambda r: self._done(job, layer.name, *r), "Fit beads")

    def _done(self, job, source, rec, beads):
        self.session.built = (job, rec)
        self.table.value = bead_table(beads)
        if beads:
            centres = np.array([[b.centre_um[2], b.centre_um[1], b.centre_um[0]] for b in beads])
            kwargs = {
                "name": f"{source} beads",
                "size": [b.diameter_um for b in beads],
                "features": bead_table(beads),
                "face_color": "transparent",
                "border_color": ["yellow" if not b.note else "red" for b in beads],
                "units": ("µm", "µm", "µm"),
            }
            show_layer(self.viewer, centres, kwargs, "points")
        flagged = sum(1 for b in beads if b.note)
        return f"{source}: {len(beads)} bead(s)" + (f", {flagged} to check (red)" if flagged else "")
