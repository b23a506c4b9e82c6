"""The .glb in Blender (its own glTF importer, run headless): the expressions arrive as shape keys named as the
sliders, a shape key at 1 is the head model with that expression, and the animation's jaw turns the mesh as the
head model's skinning does. Skipped where Blender is not installed (`apt-get install blender python3-numpy`)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from models.export.gltf import glb_bytes
from models.export.keys import Clip, pose_frames
from models.head.controls import Controls
from models.head.head import Head

BLENDER = shutil.which("blender")
SCRIPT = Path(__file__).with_name("blender_import.py")
pytestmark = pytest.mark.skipif(BLENDER is None, reason="Blender is not installed (apt-get install blender "
                                                         "python3-numpy)")


def farthest_m(got: np.ndarray, want: np.ndarray) -> float:
    """The largest distance from a wanted vertex to the nearest of Blender's (its importer may split or order the
    vertices its own way)."""
    return float(cKDTree(got).query(want)[0].max())


def test_blender_imports_the_expressions_and_the_jaw(demo_export, demo_avatar, tmp_path):
    head = demo_avatar.head_model
    jaw = np.zeros((2, len(head.joint_names), 3))
    jaw[:, head.joint_names.index("jaw"), 0] = 0.3
    path = tmp_path / "talk.glb"
    path.write_bytes(glb_bytes(demo_export[0].mesh, (Clip("talk", None, pose_frames(np.array([0.0, 1.0]), jaw)),)))
    out = tmp_path / "blender.json"
    run = subprocess.run([BLENDER, "-b", "--factory-startup", "--python", str(SCRIPT), "--", str(path), str(out),
                          "smile_L"], capture_output=True, text=True, timeout=300)
    assert out.is_file(), run.stdout[-2000:] + run.stderr[-2000:]
    report = json.loads(out.read_text())
    assert report["shape_keys"] == ["Basis", *head.expr_names]
    assert "jaw" in report["bones"] and report["actions"]
    expr = np.zeros(head.num_expression, np.float32)
    expr[head.expression_index("smile_L")] = 1.0
    smile = Head(head).pose(Controls(expression=expr))[0][0].numpy()
    assert farthest_m(np.asarray(report["with_key"]), smile) < 1e-5
    rest = Head(head).pose(Controls())[0][0].numpy()
    assert farthest_m(np.asarray(report["with_key"]), rest) > 1e-3  # (the smile moved the mouth: the key is read)
    open_jaw = Head(head).pose(Controls(jaw=np.array([0.3, 0.0, 0.0], np.float32)))[0][0].numpy()
    assert farthest_m(np.asarray(report["animated"]), open_jaw) < 1e-4
    assert farthest_m(np.asarray(report["animated"]), rest) > 5e-3  # (the jaw turned: 0.3 rad moves the chin cm)
