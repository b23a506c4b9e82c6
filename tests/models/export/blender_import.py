"""Run inside Blender (`blender -b --factory-startup --python blender_import.py -- GLB OUT.json KEY`): import a .glb
with Blender's own glTF importer and write what Blender made of it: its shape keys, bones and actions, and the
evaluated mesh's vertices (in glTF's axes) with the shape key KEY set to 1 (the rest pose, no animation) and at the
first frame of the file's animation. (Importable outside Blender, as the test collection imports every module:
Blender's own module is imported in main.)"""

import json
import sys


def main() -> None:
    import numpy

    if not hasattr(numpy, "bool"):  # Debian's Blender 3.4 importer still names numpy.bool, gone since numpy 1.24
        numpy.bool = bool
    import bpy  # Blender's own module: only inside Blender

    glb, out, key = sys.argv[sys.argv.index("--") + 1:]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=glb)
    mesh = next(o for o in bpy.data.objects if o.type == "MESH")
    armature = next((o for o in bpy.data.objects if o.type == "ARMATURE"), None)

    def vertices() -> list:
        """The evaluated mesh's vertices in world space, as glTF's axes have them (Blender's z up is glTF's y)."""
        evaluated = mesh.evaluated_get(bpy.context.evaluated_depsgraph_get())
        world = evaluated.matrix_world
        return [[p.x, p.z, -p.y] for p in (world @ v.co for v in evaluated.data.vertices)]

    report = {"shape_keys": [k.name for k in mesh.data.shape_keys.key_blocks],
              "bones": [b.name for b in armature.data.bones] if armature else [],
              "actions": [a.name for a in bpy.data.actions]}
    action = None
    if armature is not None and armature.animation_data is not None:  # the rest pose first: no action
        action = armature.animation_data.action
        armature.animation_data.action = None
        for bone in armature.pose.bones:
            bone.rotation_quaternion = (1, 0, 0, 0)
    if mesh.data.shape_keys.animation_data is not None:
        mesh.data.shape_keys.animation_data.action = None
    mesh.data.shape_keys.key_blocks[key].value = 1.0
    bpy.context.view_layer.update()
    report["with_key"] = vertices()
    mesh.data.shape_keys.key_blocks[key].value = 0.0
    if action is not None:
        armature.animation_data.action = action
        bpy.context.scene.frame_set(int(action.frame_range[0]))
        bpy.context.view_layer.update()
        report["animated"] = vertices()
    with open(out, "w") as f:
        json.dump(report, f)


if __name__ == "__main__":
    main()
