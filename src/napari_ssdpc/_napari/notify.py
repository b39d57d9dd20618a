"""The plugin's notifications, in one place: napari's toasts (tests replace these functions)."""

from __future__ import annotations

from napari.utils import notifications

__all__ = ["error", "info", "warning"]


def error(message) -> None:
    """Show ``message`` (a string or an exception's one-line text) as a napari error.

    Parameters
    ----------
    message : str or Exception
    """
    notifications.show_error(str(message))


def warning(message) -> None:
    """Show ``message`` as a napari warning.

    Parameters
    ----------
    message : str or Exception
    """
    notifications.show_warning(str(message))


def info(message) -> None:
    """Show ``message`` as a napari information toast.

    Parameters
    ----------
    message : str or Exception
    """
    notifications.show_info(str(message))
