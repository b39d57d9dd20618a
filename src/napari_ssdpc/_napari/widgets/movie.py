"""The Movie widget: a turn around a reconstructed volume, or a series played in time, to a file.

Built on napari-animation: key frames are captured from the viewer and interpolated. The export is
a job of the plugin's job runner (progress, Cancel): a helper thread asks the GUI thread to render
one frame at a time (rendering needs it; the event loop runs between frames) and encodes the frames
into an MP4 (or a GIF) itself. The view (camera, 2D/3D, sliders, which layers are visible) is
restored when the export ends, also after Cancel or an error; a cancelled or failed export leaves
no partial file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from magicgui.widgets import ComboBox, FileEdit, SpinBox

from napari_ssdpc._napari import notify
from napari_ssdpc._napari.placement import fit_view
from napari_ssdpc._napari.widgets.choices import LayerChoice, result_layer_choices
from napari_ssdpc._napari.widgets.common import StepWidget, follow_layers, run_buttons
from napari_ssdpc._napari.widgets.jobs import JobRunner
from napari_ssdpc.errors import SsdpcError

__all__ = ["MOVIE_KINDS", "MovieWidget", "camera_of", "export_movie", "keep_view", "plan_movie", "write_movie"]

#: What a movie shows: the volume turning about the y axis in 3D, or the frames of a series.
MOVIE_KINDS = ("turn in 3D", "time series")
#: Longest wait for the GUI thread to render one frame, ms.
RENDER_TIMEOUT_MS = 60_000


def camera_of(viewer):
    """The viewer's camera (``viewer.scene.camera`` since napari 0.9, ``viewer.camera`` before).

    Parameters
    ----------
    viewer : napari.Viewer

    Returns
    -------
    napari camera model
    """
    scene = getattr(viewer, "scene", None)
    return scene.camera if scene is not None else viewer.camera


def keep_view(viewer):
    """Remember the view: camera, 2D/3D, slider positions and each layer's visibility.

    Parameters
    ----------
    viewer : napari.Viewer

    Returns
    -------
    callable
        ``restore()`` puts the view back (layers removed since are skipped).
    """
    camera, ndisplay, step = camera_of(viewer).dict(), viewer.dims.ndisplay, viewer.dims.current_step
    visible = [(layer, layer.visible) for layer in viewer.layers]

    def restore():
        viewer.dims.ndisplay = ndisplay
        camera_of(viewer).update(camera)
        if len(viewer.dims.current_step) == len(step):
            viewer.dims.current_step = step
        for layer, shown in visible:
            if layer in viewer.layers:
                layer.visible = shown

    return restore


def _capture(animation, steps: int = 15) -> None:
    """Add the current view as a key frame: ``Animation.capture_keyframe`` without the thumbnail,
    which costs a full render of the canvas on the GUI thread (the widget shows no key frames)."""
    from napari_animation import KeyFrame, ViewerState

    thumbnail = np.zeros((32, 32, 4), np.uint8)
    animation.key_frames.append(KeyFrame(ViewerState.from_viewer(animation.viewer), thumbnail, steps=steps))


def plan_movie(viewer, layer, kind: str = "turn in 3D", seconds: float = 4.0, fps: int = 20):
    """Capture the key frames of a movie of ``layer`` (only it shown, the view fitted to it).

    Parameters
    ----------
    viewer : napari.Viewer
    layer : napari Image layer
        A result volume (z, y, x) or series (t, z, y, x).
    kind : {'turn in 3D', 'time series'}
        A full turn of the volume (3D view), or every time point of a series.
    seconds : float
        Length of a turn, s (a series takes one movie frame per time point).
    fps : int
        Frames per second.

    Returns
    -------
    napari_animation.Animation
    """
    from napari_animation import Animation

    for other in viewer.layers:
        other.visible = other is layer
    fit_view(viewer, layer)
    animation = Animation(viewer)
    if kind == "time series":
        if layer.ndim < 4:
            raise ValueError(f"'{layer.name}' has no time axis; choose a (t, z, y, x) result or 'turn in 3D'")
        n = layer.data.shape[0]
        viewer.dims.set_current_step(0, 0)
        _capture(animation)
        viewer.dims.set_current_step(0, n - 1)
        _capture(animation, steps=max(n - 1, 1))
    else:
        viewer.dims.ndisplay = 3
        steps = max(int(round(seconds * fps / 4)), 1)
        camera = camera_of(viewer)
        elevation, _, roll = camera.angles
        for azimuth in (0.0, 90.0, 180.0, 270.0, 360.0):  # a quarter turn per key frame
            camera.angles = (elevation, azimuth, roll)
            _capture(animation, steps=steps)
    return animation


def movie_frames(animation) -> int:
    """Images in the movie: one per interpolation step, and the first key frame.

    Parameters
    ----------
    animation : napari_animation.Animation

    Returns
    -------
    int
    """
    return int(sum(kf.steps for kf in animation.key_frames[1:])) + 1


def render_frame(animation, index: int):
    """The canvas at movie frame ``index`` (on the GUI thread).

    Parameters
    ----------
    animation : napari_animation.Animation
    index : int
        Movie frame.

    Returns
    -------
    ndarray, uint8, (h, w, 4)
        RGBA.
    """
    animation.set_movie_frame_index(index)
    return animation.viewer.screenshot(canvas_only=True, flash=False)


def write_movie(animation, path, fps: int, render=None, progress=None) -> Path:
    """Render every movie frame and encode it to ``path`` (a partial file is removed).

    Parameters
    ----------
    animation : napari_animation.Animation
        Key frames from :func:`plan_movie`.
    path : str or Path
        ``.mp4`` or ``.gif``.
    fps : int
        Frames per second.
    render : callable, optional
        ``render(index)`` gives movie frame ``index`` as an RGBA image (default :func:`render_frame`,
        which must run on the GUI thread).
    progress : callable, optional
        ``progress(done, total, label)`` after each frame.

    Returns
    -------
    Path
    """
    import imageio

    path = Path(path)
    render = render or (lambda i: render_frame(animation, i))
    n = movie_frames(animation)
    try:  # as napari-animation writes them
        if path.suffix.lower() == ".gif":
            writer = imageio.get_writer(path, duration=1000 / fps)
        else:
            writer = imageio.get_writer(path, fps=fps, quality=5)
    except (OSError, ValueError) as e:
        raise SsdpcError(f"{path}: the movie cannot be written ({e}); choose another file") from None
    finished = False
    try:
        for i in range(n):
            writer.append_data(render(i))
            if progress is not None:
                progress(i + 1, n, "movie frames")
        finished = True
    finally:
        writer.close()
        if not finished:
            path.unlink(missing_ok=True)
    return path


def _checked(path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"{path.name}: give a movie file name ending in .mp4 or .gif")
    return path


def export_movie(viewer, layer, path, kind: str = "turn in 3D", seconds: float = 4.0, fps: int = 20) -> Path:
    """Render a movie of ``layer`` from the viewer's canvas, on the calling (GUI) thread; the view is
    restored afterwards. The Movie widget does the same as a job with progress and Cancel.

    Parameters
    ----------
    viewer : napari.Viewer
    layer : napari Image layer
        A result volume (z, y, x) or series (t, z, y, x).
    path : str or Path
        Output file: ``.mp4`` or ``.gif``.
    kind : {'turn in 3D', 'time series'}
    seconds : float
        Length of a turn, s.
    fps : int
        Frames per second.

    Returns
    -------
    Path
        The movie written.
    """
    path = _checked(path)
    restore = keep_view(viewer)
    try:
        return write_movie(plan_movie(viewer, layer, kind, seconds, fps), path, int(fps))
    finally:
        restore()


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
        self.run_button, self.cancel_button, self.status = run_buttons(
            "Export movie", "render the movie from the canvas"
        )
        self.extend(
            [
                self.layer,
                self.kind,
                self.seconds,
                self.fps,
                self.path,
                self.run_button,
                self.cancel_button,
                self.status,
            ]
        )
        self.runner = JobRunner("Movie", self.run_button, self.cancel_button, self.status)
        self.run_button.changed.connect(lambda *_: self.export())
        follow_layers(napari_viewer, self)

    def export(self):
        """Write the movie to the chosen file as a job (the message says why not, if it cannot).

        Returns
        -------
        worker or None
            The job's worker; its file is written when it finishes (the status names it).
        """
        from superqt.utils import ensure_main_thread

        layer, path = self.layer.value, self.path.value
        if layer is None:
            notify.error("no reconstruction to film: reconstruct a frame first")
            return None
        if not path or Path(path).is_dir():
            notify.error("choose a movie file name (.mp4 or .gif) first")
            return None
        if self.runner.running:
            notify.info("a movie is being written; cancel it first")
            return None
        restore = keep_view(self.viewer)
        try:
            path = _checked(path)
            animation = plan_movie(self.viewer, layer, self.kind.value, self.seconds.value, self.fps.value)
        except ImportError:
            restore()
            notify.error("movies need napari-animation: pip install napari-animation")
            return None
        except ValueError as e:
            restore()
            notify.error(e)
            return None

        def on_gui(i):
            try:
                return render_frame(animation, i)
            except Exception as e:  # handed back to the helper thread, which names it
                return e

        on_gui_thread = ensure_main_thread(on_gui, await_return=True, timeout=RENDER_TIMEOUT_MS)

        def render(i):
            image = on_gui_thread(i)
            if isinstance(image, Exception):
                raise SsdpcError(
                    f"movie frame {i + 1} could not be rendered ({type(image).__name__}: {image}); export again"
                )
            return image

        fps = int(self.fps.value)

        def work(progress, should_stop):
            return write_movie(animation, path, fps, render, progress)

        worker = self.runner.start(work, lambda out: f"wrote {out.name}", "Movie")
        if worker is None:
            restore()
            return None
        worker.finished.connect(restore)
        return worker
