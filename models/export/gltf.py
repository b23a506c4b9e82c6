"""Plain arrays to a glTF 2.0 binary (.glb) through pygltflib: one mesh with morph targets, a skin, a texture and
animations. Knows nothing of avatars or head models (avatar_gltf.py puts those into these arrays).

The file holds, in glTF 2.0's terms ("Meshes", "Skins", "Animations"):
- node 0, the mesh: POSITION, NORMAL, TEXCOORD_0 (and JOINTS_0, WEIGHTS_0 where there is a skin), triangles; one
  morph target per expression (POSITION deltas, sparse where most vertices do not move), their names in
  `mesh.extras.targetNames` (what Blender, three.js and glTFast name shape keys and morph targets by);
- nodes 1..J, the joints, each translated from its parent, and the skin (inverse bind matrices);
- one material: the texture as base colour, unlit (KHR_materials_unlit: the texture is the avatar as lit in its
  capture; viewers without the extension shade it as a rough non-metal);
- animations: morph weights (LINEAR or CUBICSPLINE) on node 0, rotations (LINEAR) on the joints.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pygltflib as g

from models.export.keys import Clip

FLOAT, UBYTE, USHORT, UINT = g.FLOAT, g.UNSIGNED_BYTE, g.UNSIGNED_SHORT, g.UNSIGNED_INT
TYPES = {1: g.SCALAR, 2: g.VEC2, 3: g.VEC3, 4: g.VEC4, 16: g.MAT4}
DTYPES = {FLOAT: np.float32, UBYTE: np.uint8, USHORT: np.uint16, UINT: np.uint32}
UNLIT = "KHR_materials_unlit"


@dataclass(frozen=True, eq=False)
class Skin:
    """Joints as nodes, and each vertex's four of them."""

    names: tuple[str, ...]
    parents: np.ndarray  # (J,) int, -1 for the root
    translations: np.ndarray  # (J,3) each joint's offset from its parent, metres
    inverse_bind: np.ndarray  # (J,4,4) row-major
    joints: np.ndarray  # (N,4) int: the joints each vertex follows
    weights: np.ndarray  # (N,4) their weights, rows summing to 1


@dataclass(frozen=True, eq=False)
class MeshAsset:
    """One textured, morphable, skinned mesh."""

    name: str
    positions: np.ndarray  # (N,3) metres, +y up
    normals: np.ndarray  # (N,3) unit
    uv: np.ndarray  # (N,2) glTF's (v down)
    triangles: np.ndarray  # (F,3) counter-clockwise seen from outside
    morph_names: tuple[str, ...] = ()
    morph_deltas: np.ndarray | None = None  # (E,N,3) metres
    texture_png: bytes | None = None
    skin: Skin | None = None
    extras: dict = field(default_factory=dict)


class BinaryChunk:
    """The .glb's one buffer, built up view by view (each 4-byte aligned), and the accessors over it."""

    def __init__(self, gltf: g.GLTF2):
        self.gltf = gltf
        self.blob = bytearray()

    def view(self, data: bytes, target: int | None = None) -> int:
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        self.gltf.bufferViews.append(g.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data),
                                                  target=target))
        self.blob.extend(data)
        return len(self.gltf.bufferViews) - 1

    def accessor(self, array: np.ndarray, component: int, target: int | None = None, bounds: bool = False) -> int:
        """An accessor of (count, k) values (k in TYPES; a flat array is SCALAR); bounds: with min and max."""
        a = np.ascontiguousarray(array, DTYPES[component])
        rows = a.reshape(len(a), -1)
        acc = g.Accessor(bufferView=self.view(a.tobytes(), target), componentType=component, count=len(a),
                         type=TYPES[rows.shape[1]])
        if bounds:
            acc.min, acc.max = _bounds(rows)
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def sparse_vec3(self, deltas: np.ndarray) -> int:
        """A VEC3 float accessor of (N,3) deltas with min and max: sparse (the rows that are not zero, over zeros)
        where that is smaller than writing them all; no data at all where every row is zero (glTF: zeros)."""
        d = np.ascontiguousarray(deltas, np.float32)
        moved = np.flatnonzero(np.any(d != 0, axis=1))
        index_type = USHORT if len(d) <= 65535 else UINT
        index_bytes = 2 if index_type == USHORT else 4
        if len(moved) * (12 + index_bytes) >= d.nbytes:
            return self.accessor(d, FLOAT, g.ARRAY_BUFFER, bounds=True)
        acc = g.Accessor(componentType=FLOAT, count=len(d), type=g.VEC3, byteOffset=None)
        acc.min, acc.max = _bounds(d)
        if len(moved):
            indices = self.view(moved.astype(DTYPES[index_type]).tobytes())
            values = self.view(d[moved].tobytes())
            acc.sparse = g.Sparse(count=len(moved), indices=g.AccessorSparseIndices(bufferView=indices,
                                                                                    componentType=index_type),
                                  values=g.AccessorSparseValues(bufferView=values))
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1


def _bounds(rows: np.ndarray) -> tuple[list[float], list[float]]:
    return [float(v) for v in rows.min(0)], [float(v) for v in rows.max(0)]


def glb_bytes(mesh: MeshAsset, clips: tuple[Clip, ...] = (), generator: str = "avatar-studio") -> bytes:
    """The mesh, its skin, texture and animations as a glTF 2.0 binary."""
    n = len(mesh.positions)
    assert mesh.normals.shape == (n, 3) and mesh.uv.shape == (n, 2), "normals (N,3) and uv (N,2) for N positions"
    gltf = g.GLTF2(asset=g.Asset(version="2.0", generator=generator))
    chunk = BinaryChunk(gltf)
    attributes = g.Attributes(POSITION=chunk.accessor(mesh.positions, FLOAT, g.ARRAY_BUFFER, bounds=True),
                              NORMAL=chunk.accessor(mesh.normals, FLOAT, g.ARRAY_BUFFER),
                              TEXCOORD_0=chunk.accessor(mesh.uv, FLOAT, g.ARRAY_BUFFER))
    if mesh.skin is not None:
        attributes.JOINTS_0 = chunk.accessor(mesh.skin.joints, UBYTE if len(mesh.skin.names) < 256 else USHORT,
                                             g.ARRAY_BUFFER)
        attributes.WEIGHTS_0 = chunk.accessor(mesh.skin.weights, FLOAT, g.ARRAY_BUFFER)
    indices = chunk.accessor(np.asarray(mesh.triangles).ravel(), USHORT if n <= 65535 else UINT,
                             g.ELEMENT_ARRAY_BUFFER)
    deltas = np.zeros((0, n, 3)) if mesh.morph_deltas is None else mesh.morph_deltas
    targets = [{"POSITION": chunk.sparse_vec3(d)} for d in deltas]
    primitive = g.Primitive(attributes=attributes, indices=indices, mode=g.TRIANGLES, targets=targets or None)
    if mesh.texture_png is not None:
        primitive.material = add_texture(gltf, chunk, mesh.texture_png)
    gltf.meshes.append(g.Mesh(name=mesh.name, primitives=[primitive], weights=[0.0] * len(targets) or None,
                              extras={"targetNames": list(mesh.morph_names), **mesh.extras}))
    gltf.nodes.append(g.Node(name=mesh.name, mesh=0))
    roots = [0]
    if mesh.skin is not None:
        roots += add_skin(gltf, chunk, mesh.skin)
    gltf.scenes.append(g.Scene(nodes=roots))
    gltf.scene = 0
    for clip in clips:
        add_clip(gltf, chunk, clip)
    gltf.buffers.append(g.Buffer(byteLength=len(chunk.blob)))
    gltf.set_binary_blob(bytes(chunk.blob))
    return b"".join(gltf.save_to_bytes())


def add_texture(gltf: g.GLTF2, chunk: BinaryChunk, png: bytes) -> int:
    """The PNG as the base colour of an unlit material; its index."""
    gltf.images.append(g.Image(bufferView=chunk.view(png), mimeType="image/png"))
    gltf.samplers.append(g.Sampler(magFilter=g.LINEAR, minFilter=g.LINEAR_MIPMAP_LINEAR, wrapS=g.CLAMP_TO_EDGE,
                                   wrapT=g.CLAMP_TO_EDGE))
    gltf.textures.append(g.Texture(source=len(gltf.images) - 1, sampler=len(gltf.samplers) - 1))
    gltf.materials.append(g.Material(
        name="avatar", doubleSided=True, extensions={UNLIT: {}},
        pbrMetallicRoughness=g.PbrMetallicRoughness(baseColorTexture=g.TextureInfo(index=len(gltf.textures) - 1),
                                                    metallicFactor=0.0, roughnessFactor=1.0)))
    gltf.extensionsUsed = [*gltf.extensionsUsed, UNLIT]
    return len(gltf.materials) - 1


def add_skin(gltf: g.GLTF2, chunk: BinaryChunk, skin: Skin) -> list[int]:
    """The joints as nodes after the mesh's (node 0, which the skin is put on); the root joints' node indices."""
    first = len(gltf.nodes)
    for j, name in enumerate(skin.names):
        children = [first + int(c) for c in np.flatnonzero(skin.parents == j)]
        gltf.nodes.append(g.Node(name=name, translation=[float(v) for v in skin.translations[j]],
                                 children=children or None))
    ibm = chunk.accessor(np.transpose(skin.inverse_bind, (0, 2, 1)).reshape(len(skin.names), 16), FLOAT)
    roots = [first + int(j) for j in np.flatnonzero(skin.parents < 0)]
    gltf.skins.append(g.Skin(joints=list(range(first, first + len(skin.names))), inverseBindMatrices=ibm,
                             skeleton=roots[0]))
    gltf.nodes[0].skin = len(gltf.skins) - 1
    return roots


def add_clip(gltf: g.GLTF2, chunk: BinaryChunk, clip: Clip) -> None:
    """One animation: the morph weights' sampler on node 0 and a rotation sampler for each posed joint (joint j is
    node j + 1)."""
    samplers, channels = [], []

    def sampler(times: np.ndarray, values: np.ndarray, interpolation: str, target: g.AnimationChannelTarget) -> None:
        samplers.append(g.AnimationSampler(input=chunk.accessor(times, FLOAT, bounds=True),
                                           output=chunk.accessor(values, FLOAT), interpolation=interpolation))
        channels.append(g.AnimationChannel(sampler=len(samplers) - 1, target=target))

    if clip.morph is not None:
        m = clip.morph
        out = m.values if m.interpolation == "LINEAR" else np.stack([m.in_tangents, m.values, m.out_tangents], 1)
        sampler(m.times, out.ravel(), m.interpolation, g.AnimationChannelTarget(node=0, path="weights"))
    if clip.pose is not None:
        for joint, q in clip.pose.rotations.items():
            sampler(clip.pose.times, q, g.ANIM_LINEAR, g.AnimationChannelTarget(node=1 + joint, path="rotation"))
    if channels:
        gltf.animations.append(g.Animation(name=clip.name, samplers=samplers, channels=channels))
