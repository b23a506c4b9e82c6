"""Shader files and their preprocessing, without GL."""

from __future__ import annotations

import pytest

from render.gl.shaders import PROGRAMS, SHADER_DIR, ShaderSourceError, declared_names, read_program, stage_sources


def test_every_program_file_declares_the_shared_names():
    for name, (attributes, uniforms) in PROGRAMS.items():
        declared = declared_names(read_program(name))
        assert set(attributes) | set(uniforms) <= declared, name
    assert {p.stem for p in SHADER_DIR.glob("*.glsl")} == set(PROGRAMS)


def test_stage_sources_add_version_and_define():
    src = "#if defined VERTEX_SHADER\nvoid main(){}\n#elif defined FRAGMENT_SHADER\nvoid main(){}\n#endif\n"
    stages = stage_sources(src, "t")
    assert stages["VERTEX_SHADER"].splitlines()[:3] == ["#version 330 core", "#define VERTEX_SHADER 1", "#line 1"]
    assert stages["FRAGMENT_SHADER"].splitlines()[1] == "#define FRAGMENT_SHADER 1"


def test_missing_stage_guard_and_version_line_are_errors():
    with pytest.raises(ShaderSourceError, match="FRAGMENT_SHADER"):
        stage_sources("#if defined VERTEX_SHADER\n#endif\n", "t")
    with pytest.raises(ShaderSourceError, match="version line"):
        stage_sources("#version 330\n#if defined VERTEX_SHADER\n#elif defined FRAGMENT_SHADER\n#endif", "t")


def test_geometry_stage_only_for_its_defines():
    src = ("#if defined VERTEX_SHADER\n#elif defined GEOMETRY_SHADER && defined WIREFRAME\n"
           "#elif defined FRAGMENT_SHADER\n#endif\n")
    assert "GEOMETRY_SHADER" not in stage_sources(src, "t")
    stages = stage_sources(src, "t", ("WIREFRAME",))
    assert "#define WIREFRAME 1" in stages["GEOMETRY_SHADER"] and "#define WIREFRAME 1" in stages["VERTEX_SHADER"]
