"""The Movie widget: a turn around a reconstructed volume, or a series played in time, to a file.

Built on napari-animation: key frames are captured from the viewer and interpolated, and the
canvas is rendered frame by frame into an MP4 (or a GIF). Rendering needs the GUI thread, so the
export runs there, with napari's progress bar.
"""

from __future__ import annotations

from pathlib import Path

from magicgui.widgets import ComboBox, FileEdit, SpinBox

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.widgets.choices import LayerChoice, result_layer_choices
from napari_ssdpc._napari.widgets.common import StepWidget, follow_layers, run_buttons

__all__ = ["MOVIE_KINDS", "MovieWidget", "export_movie"]

#: What a movie shows: the volume turning about the y axis in 3D, or the frames of a series.
MOVIE_KINDS = ("turn in 3D", "time series")


def export_movie(viewer, layer, path, kind: str = "turn in 3D", seconds: float = 4.0, fps: int = 20) -> Path:
    """Render a movie of ``layer`` from the viewer's canvas.

    Parameters
    ----------
    viewer : napari.Viewer
    layer : napari Image layer
        A result volume (z, y, x) or series (t, z, y, x).
    path : str or Path
        Output file: ``.mp4`` or ``.gif``.
    kind : {'turn in 3D', 'time series'}
        A full turn of the volume (3D view), or every time point of a series.
    seconds : float
        Length of a turn, s (a series takes one movie frame per time point).
    fps : int
        Frames per second.

    Returns
    -------
    Path
        The movie written.
    """
    from napari_animation import Animation

    path = Path(path)
    if path.suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"{path.name}: give a movie file name ending in .mp4 or .gif")
    for other in viewer.layers:
        other.visible = other is layer
    viewer.fit_to_view(layers=[layer])
    animation = Animation(viewer)
    if kind == "time series":
        if layer.ndim < 4:
            raise ValueError(f"'{layer.name}' has no time axis; choose a (t, z, y, x) result or 'turn in 3D'")
        n = layer.data.shape[0]
        viewer.dims.set_current_step(0, 0)
        animation.capture_keyframe()
        viewer.dims.set_current_step(0, n - 1)
        animation.capture_keyframe(steps=max(n - 1, 1))
    else:
        viewer.dims.ndisplay = 3
        steps = max(int(round(seconds * fps / 4)), 1)
        elevation, _, roll = viewer.camera.angles
        for azimuth in (0.0, 90.0, 180.0, 270.0, 360.0):  # a quarter turn per key frame
            viewer.camera.angles = (elevation, azimuth, roll)
            animation.capture_keyframe(steps=steps)
    animation.animate(str(path), fps=int(fps), canvas_only=True)
    return path


class MovieWidget(StepWidget):
    """Export a movie of a reconstruction: a turn in 3D, or a time series played through.

    Parameters
    ----------
    napari_viewer : napari.Viewer
    """

    def __init__(self, napari_viewer):
        super().__init__(napari_viewer)
        self.layer = LayerChoice(
            label="volume",
            choices=result_layer_choices(napari_viewer),
            tooltip="the reconstruction layer to film (default: the newest RI)",
        )
        self.kind = ComboBox(
            label="movie",
            choices=list(MOVIE_KINDS),
            value=MOVIE_KINDS[0],
            tooltip="a turn of the volume in 3D, or every frame of a (t, z, y, x) series",
        )
        self.seconds = SpinBox(label="turn (s)", min=1, max=60, value=4, tooltip="length of one full turn, s")
        self.fps = SpinBox(label="frames/s", min=1, max=60, value=20, tooltip="movie frames per second")
        self.path = FileEdit(mode="w", filter="*.mp4 *.gif")
        self.path.label = "file"
        self.path.tooltip = "movie file to write (.mp4 or .gif)"
        self.run_button, _, self.status = run_buttons("Export movie", "render the movie from the canvas")
        self.extend([self.layer, self.kind, self.seconds, self.fps, self.path, self.run_button, self.status])
        self.run_button.changed.connect(lambda *_: self.export())
        follow_layers(napari_viewer, self)

    def export(self) -> Path | None:
        """Write the movie to the chosen file (the message says why not, if it cannot).

        Returns
        -------
        Path or None
        """
        layer, path = self.layer.value, self.path.value
        if layer is None:
            notify.error("no reconstruction to film: reconstruct a frame first")
            return None
        if not path or Path(path).is_dir():
            notify.error("choose a movie file name (.mp4 or .gif) first")
            return None
        try:
            out = export_movie(self.viewer, layer, path, self.kind.value, self.seconds.value, self.fps.value)
        except ImportError:
            notify.error("movies need napari-animation: pip install napari-animation")
            return None
        except (ValueError, OSError) as e:
            notify.error(e)
            return None
        self.status.value = f"wrote {out.name}"
        return out
