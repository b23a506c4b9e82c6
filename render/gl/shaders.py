"""Shader sources: one file per program in shaders/, split into stages by #if guards.

Also the one table of attribute and uniform names the Python side and the GLSL share.
"""

from __future__ import annotations

import re
from pathlib import Path

SHADER_DIR = Path(__file__).resolve().parents[2] / "shaders"
GLSL_VERSION = "#version 330 core"
STAGES = ("VERTEX_SHADER", "FRAGMENT_SHADER")
OPTIONAL_STAGES = ("GEOMETRY_SHADER",)

#: program -> (attributes, uniforms) that its source must declare.
PROGRAMS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "surface": (("in_position", "in_normal", "in_canonical", "in_eye"),
                ("u_view_projection", "u_light_view_projection", "u_light_dir", "u_albedo", "u_ambient",
                 "u_light_color", "u_shadow_bias", "u_normal_offset", "u_use_shadows", "u_mode", "u_shadow_map",
                 "u_wire_color", "u_wire_width_px")),
    "depth": (("in_position",), ("u_view_projection",)),
    "raster": (("in_position",), ("u_view_projection", "u_view")),
    "capture": (("in_position", "in_normal", "in_canonical", "in_material", "in_tangent"),
                ("u_view_projection", "u_view", "u_light_view_projection", "u_normal_offset", "u_camera_position",
                 "u_sh", "u_light_dir", "u_light_color", "u_use_diffuse", "u_use_specular", "u_use_shadows",
                 "u_shininess", "u_shadow_bias", "u_shadow_map", "u_skin_color", "u_lip_color", "u_brow_color",
                 "u_iris_color", "u_hair_color", "u_cheek_center", "u_blush", "u_lip_center", "u_lip_radii",
                 "u_brow_center", "u_brow_radii", "u_nose_top", "u_nose_tip", "u_forehead_center", "u_forehead_radii",
                 "u_specular_range", "u_seed")),
    "flat": (("in_position",), ("u_view_projection", "u_point_size_px", "u_color")),
}


class ShaderSourceError(ValueError):
    pass


def read_program(name: str, directory: Path = SHADER_DIR) -> str:
    path = directory / f"{name}.glsl"
    if not path.is_file():
        raise ShaderSourceError(f"{path}: no such shader program")
    return path.read_text()


def stage_sources(source: str, name: str = "program", defines: tuple[str, ...] = ()) -> dict[str, str]:
    """The source of each stage: the version line, the stage's define, then the shared file.

    Vertex and fragment stages must be guarded in the file, a geometry stage may be (and is compiled
    when its guard's other conditions, such as `&& defined WIREFRAME`, hold for `defines`); the line
    numbers GLSL reports stay those of the file.
    """
    header = "".join(f"#define {d} 1\n" for d in defines)
    if "#version" in source:
        raise ShaderSourceError(f"{name}: the version line is added by the loader; remove it from the file")
    out = {}
    for stage in STAGES:
        if not re.search(rf"#\s*(el)?if\s+defined\s+{stage}\b", source):
            raise ShaderSourceError(f"{name}: no '#if defined {stage}' section")
        out[stage] = f"{GLSL_VERSION}\n#define {stage} 1\n{header}#line 1\n{source}"
    for stage in OPTIONAL_STAGES:
        guard = re.search(rf"#\s*(?:el)?if\s+defined\s+{stage}\b(.*)", source)
        if guard and all(d in defines for d in re.findall(r"defined\s+(\w+)", guard.group(1))):
            out[stage] = f"{GLSL_VERSION}\n#define {stage} 1\n{header}#line 1\n{source}"
    return out


def declared_names(source: str) -> set[str]:
    """Names of `in` attributes (of the vertex stage) and uniforms declared in a source."""
    vertex = re.split(r"#\s*(?:el)?if\s+defined\s+(?:GEOMETRY|FRAGMENT)_SHADER", source)[0]
    names = set(re.findall(r"^\s*in\s+\w+\s+(\w+)\s*;", vertex, re.M))
    names |= set(re.findall(r"^\s*uniform\s+\w+\s+(\w+)\s*(?:\[\d+\])?\s*;", source, re.M))
    return names
