"""One moderngl context type: headless (EGL, no display) or the current window's."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import moderngl

from render.gl.shaders import PROGRAMS, read_program, stage_sources


class GLError(RuntimeError):
    """No usable OpenGL 3.3 context, or a shader that does not compile."""


class GLContext:
    """A moderngl context with the project's programs compiled once, on first use.

    Nothing global: whoever needs GL is handed a GLContext.
    """

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self._depth = 0
        self._programs: dict[tuple[str, tuple[str, ...]], moderngl.Program] = {}

    @classmethod
    def headless(cls) -> GLContext:
        """An offscreen context through EGL (Mesa llvmpipe on a machine without a GPU)."""
        try:
            return cls(moderngl.create_context(standalone=True, backend="egl", require=330))
        except Exception as e:  # moderngl raises plain Exception when EGL is missing
            raise GLError(f"no headless OpenGL 3.3 context through EGL ({e}); "
                          "install libegl1 libegl-mesa0 libgl1-mesa-dri") from None

    @classmethod
    def from_current_window(cls) -> GLContext:
        """Wrap the context a window made current (glfw)."""
        return cls(moderngl.create_context(require=330))

    @contextlib.contextmanager
    def current(self) -> Iterator[moderngl.Context]:
        """Make this context current for the block (re-entrant). Every GL call goes through one: a process
        may hold several contexts (a studio's window and a headless one, or one per command in tests), and
        a GL object made or used while another context is current is silently wrong."""
        if self._depth == 0:
            self.ctx.__enter__()
        self._depth += 1
        try:
            yield self.ctx
        finally:
            self._depth -= 1
            if self._depth == 0:
                self.ctx.__exit__(None, None, None)

    @property
    def renderer(self) -> str:
        return self.ctx.info.get("GL_RENDERER", "?")

    def program(self, name: str, defines: tuple[str, ...] = ()) -> moderngl.Program:
        """The compiled program of shaders/NAME.glsl with the given preprocessor defines (one variant each)."""
        key = (name, tuple(sorted(defines)))
        if key not in self._programs:
            if name not in PROGRAMS:
                raise GLError(f"unknown program '{name}'")
            stages = stage_sources(read_program(name), name, key[1])
            try:
                self._programs[key] = self.ctx.program(vertex_shader=stages["VERTEX_SHADER"],
                                                        geometry_shader=stages.get("GEOMETRY_SHADER"),
                                                        fragment_shader=stages["FRAGMENT_SHADER"])
            except moderngl.Error as e:
                raise GLError(f"shaders/{name}.glsl {' '.join(defines)}: {e}") from None
        return self._programs[key]

    def release(self) -> None:
        with self.current():
            for p in self._programs.values():
                p.release()
            self._programs.clear()
        self.ctx.release()
