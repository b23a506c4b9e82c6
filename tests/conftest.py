"""Shared fixtures: the real data in ../shared (skipped clearly when absent) and a headless GL context."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"
ICT_NPZ = SHARED_DATA / "ict_facekit" / "ict_head.npz"


@pytest.fixture(scope="session")
def ict_npz() -> Path:
    if not ICT_NPZ.is_file():
        pytest.skip(f"ICT-FaceKit data not found at {ICT_NPZ} (../shared is absent)")
    return ICT_NPZ


@pytest.fixture(scope="session")
def ict_model(ict_npz):
    from models.head.ict import load_ict_npz

    return load_ict_npz(ict_npz)


@pytest.fixture(scope="session")
def builtin_model():
    from models.head.sources import load_builtin

    return load_builtin()


@pytest.fixture(scope="session")
def gl():
    from render.gl.context import GLContext

    ctx = GLContext.headless()
    yield ctx
    ctx.release()
