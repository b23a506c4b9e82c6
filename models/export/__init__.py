"""Avatars written for other tools (docs/export.md): one module per concern.

- chart.py: the texture chart (the head model's own UVs, else an xatlas atlas), vertices split along its seams;
- skeleton.py: the head model's joints as a glTF skin (rest joints, inverse bind matrices, four weights a vertex);
- keys.py: keyframed channels as glTF samplers (linear, or smooth as a cubic spline), poses as quaternions;
- bake.py: a colour texture baked from renders of the avatar through the avatar interface;
- gltf.py: plain arrays to a glTF 2.0 binary (pygltflib), knowing nothing of avatars;
- avatar_gltf.py: an avatar to a .glb, the pieces above put together.
"""
