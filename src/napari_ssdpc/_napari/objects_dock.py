"""The Objects dock: measure the objects of a result layer over time, show their tracks, a table
and plots of dry mass and position against time, and save the table as CSV.

The measurement runs in a worker thread (:func:`napari.qt.threading.create_worker`); the rule and
its parameters are those of ``ssdpc measure`` (docs/measurements.md).
"""

from __future__ import annotations

from pathlib import Path

from magicgui.widgets import ComboBox, Container, FileEdit, FloatSpinBox, Label, PushButton
from qtpy.QtWidgets import QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.tracks import measure_layer, tracks_layer
from napari_ssdpc._napari.widgets.common import scrolling
from napari_ssdpc.analysis.objects import DEFAULT_RULE, ObjectRule
from napari_ssdpc.analysis.table import write_csv
from napari_ssdpc.analysis.tracks import DEFAULT_MAX_STEP_UM
from napari_ssdpc.errors import SsdpcError

__all__ = ["ObjectsDock"]

#: The table's columns (all of the CSV's but the bookkeeping ones).
SHOWN = ("t", "track", "x_um", "y_um", "z_um", "volume_um3", "mean_ri", "peak_ri", "dry_mass_pg")


def _result_layers(viewer):
    from napari.layers import Image

    def choices(_widget=None):
        return [
            (lyr.name, lyr)
            for lyr in reversed(viewer.layers)
            if isinstance(lyr, Image) and lyr.metadata.get("ssdpc", {}).get("quantity") in ("ri", "delta_n")
        ]

    return choices


class ObjectsDock(QWidget):
    """Objects over time of a result layer: tracks, table, plots of dry mass and position.

    Parameters
    ----------
    napari_viewer : napari.Viewer
    """

    def __init__(self, napari_viewer):
        super().__init__()
        self.viewer = napari_viewer
        self.rows: list[dict] | None = None
        rule = DEFAULT_RULE
        self.layer = ComboBox(label="result (RI)", choices=_result_layers(napari_viewer))
        self.k = FloatSpinBox(label="seed k (σ)", value=rule.k, min=0.1, max=1000, step=0.5)
        self.k_low = FloatSpinBox(label="extent k_low (σ)", value=rule.k_low, min=0.1, max=1000, step=0.5)
        self.fraction = FloatSpinBox(label="seed ≥ peak x", value=rule.fraction, min=0, max=0.99, step=0.05)
        self.fraction_low = FloatSpinBox(label="extent ≥ peak x", value=rule.fraction_low, min=0, max=0.99, step=0.01)
        self.min_volume = FloatSpinBox(label="min volume (µm³)", value=rule.min_volume_um3, min=0, max=1e7)
        self.fwhm_z = FloatSpinBox(label="FWHM z (µm)", value=rule.resolution_um[0], min=0, max=500)
        self.fwhm_xy = FloatSpinBox(label="FWHM xy (µm)", value=rule.resolution_um[1], min=0, max=100)
        self.sign = ComboBox(label="objects", choices=["denser", "lighter"], value=rule.sign)
        self.max_step = FloatSpinBox(label="max step (µm)", value=DEFAULT_MAX_STEP_UM, min=0.1, max=1000)
        self.run = PushButton(text="Measure objects")
        self.path = FileEdit(label="table", mode="w", filter="*.csv")
        self.save = PushButton(text="Save table (CSV)")
        self.status = Label(value="")
        self.run.changed.connect(self.measure)
        self.save.changed.connect(self.save_table)
        self.controls = Container(
            widgets=[
                self.layer,
                self.k,
                self.k_low,
                self.fraction,
                self.fraction_low,
                self.min_volume,
                self.fwhm_z,
                self.fwhm_xy,
                self.sign,
                self.max_step,
                self.run,
                self.path,
                self.save,
                self.status,
            ]
        )
        from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
        from matplotlib.figure import Figure

        self.figure = Figure(figsize=(4, 4), tight_layout=True)
        self.canvas = FigureCanvasQTAgg(self.figure)
        self.canvas.setMinimumHeight(260)
        self.table = QTableWidget(0, len(SHOWN))
        self.table.setHorizontalHeaderLabels(list(SHOWN))
        inner = QWidget()
        column = QVBoxLayout(inner)
        column.addWidget(self.controls.native)
        column.addWidget(self.canvas)
        column.addWidget(self.table)
        scrolling(inner, into=self)  # it scrolls: with every dock open the window still fits the screen
        for e in (napari_viewer.layers.events.inserted, napari_viewer.layers.events.removed):
            e.connect(lambda *_: self.controls.reset_choices())

    def rule(self) -> ObjectRule:
        """The rule the controls set.

        Returns
        -------
        ObjectRule
        """
        return ObjectRule(
            k=self.k.value,
            k_low=self.k_low.value,
            fraction=self.fraction.value,
            fraction_low=self.fraction_low.value,
            min_volume_um3=self.min_volume.value,
            resolution_um=(self.fwhm_z.value, self.fwhm_xy.value),
            sign=self.sign.value,
        )

    def measure(self, *_):
        """Measure the chosen layer in a worker thread; show the result when it returns.

        Returns
        -------
        napari worker or None
            None when the input is refused (the reason is shown).
        """
        from napari.qt.threading import create_worker

        layer = self.layer.value
        try:
            if layer is None:
                raise SsdpcError("open or reconstruct a result first: no RI layer to measure")
            rule = self.rule()
        except SsdpcError as e:
            notify.error(e)
            return None
        self.status.value = f"measuring {layer.name} ..."
        self.run.enabled = False
        worker = create_worker(
            measure_layer,
            layer.data,
            tuple(layer.scale),
            tuple(layer.translate),
            dict(layer.metadata.get("ssdpc", {})),
            rule=rule,
            max_step_um=self.max_step.value,
            _start_thread=False,
        )
        worker.returned.connect(lambda rows: self.show_rows(rows, f"{layer.name} objects"))
        worker.errored.connect(self._failed)
        worker.finished.connect(lambda: setattr(self.run, "enabled", True))
        worker.start()
        return worker

    def _failed(self, e):
        self.status.value = "measurement failed"
        notify.error(e)

    def show_rows(self, rows: list[dict], name: str = "objects") -> None:
        """Show measured rows: the Tracks layer, the table and the plots.

        Parameters
        ----------
        rows : list of dict
            Rows of an objects table.
        name : str
            Name of the Tracks layer.
        """
        self.rows = rows
        tracks = sorted({r["track"] for r in rows})
        self.status.value = f"{len(rows)} objects in {len({r['t'] for r in rows})} frame(s), {len(tracks)} track(s)"
        if rows:
            data, kwargs, _ = tracks_layer(rows, name)
            if name in self.viewer.layers:
                self.viewer.layers.remove(name)
            self.viewer.add_tracks(data, **kwargs)
        self.table.setRowCount(len(rows))
        for i, r in enumerate(rows):
            for j, c in enumerate(SHOWN):
                v = r[c]
                self.table.setItem(i, j, QTableWidgetItem(f"{v:.5g}" if isinstance(v, float) else str(v)))
        self._plot(rows, tracks)

    def _plot(self, rows, tracks) -> None:
        self.figure.clear()
        mass, where = self.figure.subplots(2, 1, sharex=True)
        for k in tracks:
            mine = [r for r in rows if r["track"] == k]
            t = [r["t"] for r in mine]
            (line,) = mass.plot(t, [r["dry_mass_pg"] for r in mine], "o-", ms=3, label=f"track {k}")
            for axis, style in (("x_um", "-"), ("y_um", "--"), ("z_um", ":")):
                where.plot(t, [r[axis] for r in mine], style, color=line.get_color())
        mass.set_ylabel("dry mass (pg)")
        where.set_ylabel("x — y -- z ··· (µm)")
        where.set_xlabel("t (frame)")
        if 0 < len(tracks) <= 8:
            mass.legend(fontsize="small")
        self.canvas.draw_idle()

    def save_table(self, *_) -> Path | None:
        """Write the shown rows to the chosen CSV (a file napari-ssdpc did not write is refused).

        Returns
        -------
        Path or None
        """
        try:
            if self.rows is None:
                raise SsdpcError("measure the objects first")
            path = write_csv(self.rows, Path(str(self.path.value)))
        except SsdpcError as e:
            notify.error(e)
            return None
        self.status.value = f"wrote {path}"
        return path
