from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def shared_optics_path():
    """The paper's optics as shipped in shared/ (falls back to the copy in the package's docs)."""
    for p in (ROOT.parent / "shared" / "paper-optics.yaml", ROOT / "docs" / "paper-optics.yaml"):
        if p.is_file():
            return p
    pytest.skip("paper-optics.yaml not found")
