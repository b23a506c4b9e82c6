"""MediaPipe's canonical face mesh (468 vertices that its face landmarks index into), read from the face
landmarker bundle the user supplies (a zip holding `geometry_pipeline_metadata_landmarks.binarypb`).

The metadata is a protocol buffer (mediapipe's GeometryPipelineMetadata; its one large field is the canonical
Mesh3d, whose field 3 is the vertex buffer, five floats a vertex: x, y, z in centimetres, u, v, and field 4
the triangle indices, packed or not). A few lines of wire-format reading replace a protobuf dependency.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

METADATA = "geometry_pipeline_metadata_landmarks.binarypb"


class BundleError(ValueError):
    """A landmarker bundle that cannot be read; the message names the file and the problem."""


def _varint(buf: bytes, i: int) -> tuple[int, int]:
    value, shift = 0, 0
    while True:
        if i >= len(buf):
            raise ValueError("truncated varint")
        b = buf[i]
        i += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, i
        shift += 7


def message_fields(buf: bytes) -> list[tuple[int, int, bytes | int]]:
    """(field number, wire type, value) of one protocol-buffer message: bytes for length-delimited fields,
    ints for varints, raw bytes for fixed 32/64-bit ones."""
    out, i = [], 0
    while i < len(buf):
        key, i = _varint(buf, i)
        field, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(buf, i)
        elif wire == 2:
            n, i = _varint(buf, i)
            value, i = buf[i:i + n], i + n
        elif wire == 5:
            value, i = buf[i:i + 4], i + 4
        elif wire == 1:
            value, i = buf[i:i + 8], i + 8
        else:
            raise ValueError(f"unsupported wire type {wire}")
        out.append((field, wire, value))
    return out


def canonical_face_mesh(bundle: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(468,3) vertices in metres (+y up, +z out of the face) and (T,3) triangles of the canonical mesh."""
    bundle = Path(bundle)
    try:
        with zipfile.ZipFile(bundle) as z:
            data = z.read(METADATA)
        mesh = max((v for f, w, v in message_fields(data) if w == 2), key=len)
        fields = message_fields(mesh)
        vb = b"".join(v for f, w, v in fields if f == 3 and w in (2, 5))
        verts = np.frombuffer(vb, "<f4").reshape(-1, 5)[:, :3].astype(np.float32) / 100.0
        idx = [v for f, w, v in fields if f == 4 and w == 0]
        for packed in (v for f, w, v in fields if f == 4 and w == 2):
            i = 0
            while i < len(packed):
                v, i = _varint(packed, i)
                idx.append(v)
        tris = np.asarray(idx, np.int64).reshape(-1, 3)
    except (OSError, zipfile.BadZipFile, KeyError, IndexError, ValueError) as e:
        raise BundleError(f"{bundle}: not a MediaPipe face landmarker bundle ({type(e).__name__}: {e})") from None
    if len(verts) != 468 or tris.max(initial=0) >= len(verts):
        raise BundleError(f"{bundle}: its canonical face mesh has {len(verts)} vertices, expected 468")
    return verts, tris
