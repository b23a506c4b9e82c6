"""Reading a .glb back as a viewer would, independently of the writer: accessors (dense, sparse, or no data at all),
the embedded texture, glTF's own skinning and CUBICSPLINE sampling (glTF 2.0, "Skins" and Appendix C), and the
Khronos glTF validator (npm's gltf-validator, installed into .node/ by the set-up)."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[3]
VALIDATOR = REPO / ".node" / "node_modules" / "gltf-validator"
COMPONENTS = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def accessor(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    """(count, width) values of an accessor: its buffer view's (zeros without one), sparse values put in."""
    a = gltf.accessors[index]
    blob = gltf.binary_blob()
    width = WIDTHS[a.type]

    def view(bv: int, dtype, count: int, offset: int = 0) -> np.ndarray:
        return np.frombuffer(blob, dtype, count, gltf.bufferViews[bv].byteOffset + offset)

    if a.bufferView is None:
        out = np.zeros((a.count, width), COMPONENTS[a.componentType])
    else:
        out = view(a.bufferView, COMPONENTS[a.componentType], a.count * width, a.byteOffset or 0).reshape(-1, width)
        out = out.copy()
    if a.sparse is not None:
        rows = view(a.sparse.indices.bufferView, COMPONENTS[a.sparse.indices.componentType], a.sparse.count)
        out[rows] = view(a.sparse.values.bufferView, COMPONENTS[a.componentType], a.sparse.count * width
                         ).reshape(-1, width)
    return out


def texture(gltf: pygltflib.GLTF2) -> np.ndarray:
    """(H,W,3) uint8: the base-colour texture's image."""
    bv = gltf.bufferViews[gltf.images[0].bufferView]
    png = gltf.binary_blob()[bv.byteOffset:bv.byteOffset + bv.byteLength]
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def skinned(gltf: pygltflib.GLTF2, positions: np.ndarray, rotations: dict[int, np.ndarray]) -> np.ndarray:
    """(N,3) the mesh's vertices skinned as glTF does: v' = sum_j w_j (G_j IBM_j) v, G_j the joint node's world
    matrix (its parent's times its own translation and rotation), rotations: node index -> quaternion (x,y,z,w)."""
    prim = gltf.meshes[0].primitives[0]
    skin = gltf.skins[gltf.nodes[0].skin]
    ibm = accessor(gltf, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)  # column-major in the file
    parent = {c: n for n, node in enumerate(gltf.nodes) for c in node.children or []}
    world: dict[int, np.ndarray] = {}

    def matrix(n: int) -> np.ndarray:
        if n not in world:
            local = np.eye(4)
            local[:3, :3] = Rotation.from_quat(rotations.get(n, [0, 0, 0, 1])).as_matrix()
            local[:3, 3] = gltf.nodes[n].translation or [0, 0, 0]
            world[n] = (matrix(parent[n]) if n in parent else np.eye(4)) @ local
        return world[n]

    joint_mats = np.stack([matrix(n) @ ibm[j] for j, n in enumerate(skin.joints)])  # (J,4,4)
    joints = accessor(gltf, prim.attributes.JOINTS_0).astype(np.int64)
    weights = accessor(gltf, prim.attributes.WEIGHTS_0).astype(np.float64)
    per_vertex = (joint_mats[joints] * weights[..., None, None]).sum(1)  # (N,4,4)
    homogeneous = np.concatenate([positions, np.ones((len(positions), 1))], 1)
    return np.einsum("nij,nj->ni", per_vertex, homogeneous)[:, :3]


def cubic_spline(times: np.ndarray, out: np.ndarray, t: float) -> np.ndarray:
    """A CUBICSPLINE sampler's value at t: out is (K,3,E) in-tangent, value, out-tangent per key; held outside the
    keys. p(s) = (2s^3 - 3s^2 + 1) v_k + dt (s^3 - 2s^2 + s) b_k + (-2s^3 + 3s^2) v_k+1 + dt (s^3 - s^2) a_k+1."""
    if t <= times[0]:
        return out[0, 1]
    if t >= times[-1]:
        return out[-1, 1]
    k = int(np.searchsorted(times, t, "right")) - 1
    dt = float(times[k + 1] - times[k])
    s = (t - times[k]) / dt
    return ((2 * s**3 - 3 * s**2 + 1) * out[k, 1] + dt * (s**3 - 2 * s**2 + s) * out[k, 2]
            + (-2 * s**3 + 3 * s**2) * out[k + 1, 1] + dt * (s**3 - s**2) * out[k + 1, 0])


def validator_report(path: Path) -> dict:
    """The Khronos glTF validator's report on a file (its "issues": numErrors, numWarnings, messages); skips where
    Node.js or the validator is not installed."""
    node = shutil.which("node")
    if node is None or not (VALIDATOR / "package.json").is_file():
        pytest.skip(f"the Khronos glTF validator is not installed (needs Node.js and `npm install --prefix .node "
                    f"gltf-validator`, which the set-up runs); looked for {VALIDATOR}")
    script = ("const v = require(process.argv[1]); const fs = require('fs');"
              "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])), {maxIssues: 50})"
              ".then(r => console.log(JSON.stringify(r))).catch(e => { console.error(e); process.exit(1); });")
    done = subprocess.run([node, "-e", script, str(VALIDATOR), str(path)], capture_output=True, text=True, timeout=120,
                          check=True)
    return json.loads(done.stdout)["issues"]
