"""napari tests keep napari's settings in memory: the plugin records reader preferences in napari's
settings (``_napari/preferences.py``), never in the settings file of the person running the tests."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _napari_settings_in_memory(monkeypatch):
    try:
        from napari import settings
        from napari.settings import NapariSettings
    except ImportError:  # napari absent: those tests are skipped
        yield
        return
    monkeypatch.setattr(settings, "_SETTINGS", NapariSettings(config_path=None))
    yield
