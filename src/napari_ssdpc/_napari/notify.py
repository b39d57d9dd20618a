"""The plugin's notifications, in one place: napari's toasts (tests replace these functions).

The core's messages name the command line's flags (``--method multislice``); a toast says the
same in the dock's words (:func:`gui_words`).
"""

from __future__ import annotations

import re

from napari.utils import notifications

__all__ = ["error", "gui_words", "info", "warning"]

#: (pattern, words) for the flags the core's messages name, in the order they are applied.
_GUI_WORDS = (
    (r"with `ssdpc fit-optics --calibration CAL --flat FLAT -o FITTED\.json`", "with Fit the optics (Calibrate tab)"),
    (
        r"with `ssdpc fit-optics BEADS\.tif --calibration CAL --flat FLAT --white WHITE -o FITTED\.json`",
        "with Fit the optics (Calibrate tab: the bead frame, the flat and the white frame)",
    ),
    (
        r"\(`ssdpc fit-optics BEADS\.tif --calibration CAL --flat FLAT --medium-index ([0-9.]+) -o FITTED\.json`\)",
        r"(Fit the optics in the Calibrate tab, on a frame of beads in it, the medium's index \1 in the Optics tab)",
    ),
    (r"`ssdpc fit-optics`", "Fit the optics in the Calibrate tab"),
    (r"--calibration\b", "the calibration (Method tab)"),
    (r"--flat\b", "the flat frame (Reconstruct tab)"),
    (r"reconstruct with --method (\w+)", r"choose the phase method '\1' (Method tab)"),
    (r"--method (\w+)", r"the phase method '\1' (Method tab)"),
    (r"\(--tv-warm-iterations\)", "(in the run configuration)"),
    (r"\(`ssdpc calibrate WHITE.tif --optics ...`\)", "(Calibrate tab)"),
    (r"\(--optics\)", "(Optics tab)"),
    (r"--optics\b", "the optics (Optics tab)"),
    (r"\(--multislice-iterations, or the run configuration's multislice: iterations\)", "(in the run configuration)"),
    (r"--multislice-iterations\b", "the multislice iterations (in the run configuration)"),
    (r"\(--roi, or a Shapes layer in napari\)", "(a Shapes layer as the multislice region, Reconstruct tab)"),
    (r"\(--roi\)", "(a Shapes layer as the multislice region, Reconstruct tab)"),
    (r"--dz ([0-9.]+)", r"dz \1 µm"),
    (r"--z\b", "z min / z max (Method tab)"),
    (r"--dz\b", "dz (Method tab)"),
    (r"--alpha\b", "the Tikhonov α (Reconstruct tab)"),
    (r"--bead-ri\b", "the bead RI (Fit the optics, Calibrate tab)"),
    (r"\(set --medium-index to the beads' medium\)", "(set the medium's index in the Optics tab)"),
    (r"--medium-index\b", "the medium's index (Optics tab)"),
)


def gui_words(message) -> str:
    """A core message with the command line's flags said in the dock's words.

    Parameters
    ----------
    message : str or Exception

    Returns
    -------
    str
    """
    text = str(message)
    for pattern, words in _GUI_WORDS:
        text = re.sub(pattern, words, text)
    return text


def error(message) -> None:
    """Show ``message`` (a string or an exception's one-line text) as a napari error.

    Parameters
    ----------
    message : str or Exception
    """
    notifications.show_error(gui_words(message))


def warning(message) -> None:
    """Show ``message`` as a napari warning.

    Parameters
    ----------
    message : str or Exception
    """
    notifications.show_warning(gui_words(message))


def info(message) -> None:
    """Show ``message`` as a napari information toast.

    Parameters
    ----------
    message : str or Exception
    """
    notifications.show_info(gui_words(message))
