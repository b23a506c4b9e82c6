"""The demo avatar exported once for the export tests: small texture, few and small renders (seconds)."""

from __future__ import annotations

import pytest

from tests.conftest import BUILTIN_AVATAR as DEMO  # the built-in head: a skeleton with jaw and neck

SMALL = dict(texture_px=256, render_px=128, yaws=3)
"""The bake's settings in these tests: 6 renders of 128 px onto a 256 px texture."""


@pytest.fixture(scope="session")
def demo_avatar():
    from models.avatars.registry import load_avatar

    return load_avatar(DEMO)[0]


@pytest.fixture(scope="session")
def raster(gl):
    from render.gl.raster import Rasterizer

    return Rasterizer(gl)


@pytest.fixture(scope="session")
def demo_export(demo_avatar, raster, tmp_path_factory):
    """(Export, path): the demo avatar as a .glb, written."""
    from models.export.avatar_gltf import BakeSettings, export_glb

    done = export_glb(demo_avatar, raster, BakeSettings(**SMALL))
    path = tmp_path_factory.mktemp("export") / "demo.glb"
    path.write_bytes(done.data)
    return done, path
