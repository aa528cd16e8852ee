"""Where the real measured records live (../shared/data/real, never copied into the repo) and how their tests
skip when they are absent."""

from __future__ import annotations

from pathlib import Path

import pytest

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def real_dataset(name: str, probe: str | None, reason: str) -> tuple[Path, list]:
    """(the dataset's folder, the test module's `pytestmark`): marked realdata, skipped with `reason` when the file
    `probe` (None: the folder itself) is absent."""
    folder = REAL / name
    present = (folder / probe).exists() if probe else folder.is_dir()
    return folder, [pytest.mark.realdata, pytest.mark.skipif(not present, reason=reason)]
