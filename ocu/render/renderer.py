"""OpenGL 3.3 core renderer of a robot model: one vertex buffer per link, uploaded once.

A joint change only changes the model matrices passed as uniforms; the vertex buffers are
written in initialize() and never again. The same code draws into a QOpenGLWidget and into
an OSMesa buffer: the caller makes a context current and binds the framebuffer.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ocu.model.mesh import MeshData
from ocu.model.urdf import RobotModel
from ocu.render.gl import GL
from ocu.render.scene import LinkDraw, OverlayDraw, RenderFrame

VERTEX_SHADER = """
#version 330 core
layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec4 a_color;
uniform mat4 u_model;
uniform mat4 u_view_projection;
out vec3 v_world;
out vec3 v_normal;
out vec4 v_color;
void main() {
    vec4 world = u_model * vec4(a_position, 1.0);
    v_world = world.xyz;
    v_normal = mat3(u_model) * a_normal;  // rigid transforms: no inverse-transpose needed
    v_color = a_color;
    gl_Position = u_view_projection * world;
}
"""

FRAGMENT_SHADER = """
#version 330 core
in vec3 v_world;
in vec3 v_normal;
in vec4 v_color;
uniform vec3 u_eye;
uniform vec4 u_tint;
uniform float u_alpha;
uniform int u_lit;
out vec4 frag_color;
void main() {
    vec3 base = mix(v_color.rgb, u_tint.rgb, u_tint.a);
    if (u_lit == 0) {
        frag_color = vec4(base, v_color.a * u_alpha);
        return;
    }
    vec3 n = normalize(v_normal);
    vec3 to_eye = normalize(u_eye - v_world);
    if (dot(n, to_eye) < 0.0) n = -n;  // two-sided: imported meshes may be wound either way
    vec3 sun = normalize(vec3(0.45, 0.35, 0.82));
    float diffuse = max(dot(n, sun), 0.0);
    float facing = max(dot(n, to_eye), 0.0);
    float specular = pow(max(dot(n, normalize(sun + to_eye)), 0.0), 40.0) * 0.22;
    vec3 color = base * (0.28 + 0.47 * diffuse + 0.30 * facing) + vec3(specular);
    frag_color = vec4(color, v_color.a * u_alpha);
}
"""

VERTEX_DTYPE = np.dtype(
    [("position", "<f4", 3), ("normal", "<f4", 3), ("color", "u1", 4)], align=False
)
NO_TINT = (0.0, 0.0, 0.0, 0.0)
GRID_HALF_SIZE_M = 1.5
GRID_STEP_M = 0.25
AXIS_LENGTH_M = 0.5


OVERLAY_MODES = ("lines", "triangles")


class RenderError(RuntimeError):
    """The GL context cannot run the renderer (shader compile or link failure)."""


@dataclass
class _Buffer:
    vao: int
    vbo: int
    count: int
    mode: int


def interleave(mesh: MeshData) -> npt.NDArray[np.void]:
    """The vertex array uploaded to the GPU: position, normal, RGBA per vertex."""
    data = np.empty(mesh.vertex_count, dtype=VERTEX_DTYPE)
    data["position"] = mesh.positions
    data["normal"] = mesh.normals
    data["color"] = mesh.colors
    return data


def grid_lines() -> MeshData:
    """Ground grid and the world axes as line vertices (normals unused)."""
    ticks = np.arange(-GRID_HALF_SIZE_M, GRID_HALF_SIZE_M + 1e-9, GRID_STEP_M)
    points: list[tuple[float, float, float]] = []
    colors: list[tuple[int, int, int, int]] = []
    grid = (92, 96, 104, 255)
    major = (120, 126, 136, 255)
    for t in ticks:
        color = major if abs(t) < 1e-9 or abs(abs(t) - 1.0) < 1e-9 else grid
        points += [(t, -GRID_HALF_SIZE_M, 0.0), (t, GRID_HALF_SIZE_M, 0.0)]
        points += [(-GRID_HALF_SIZE_M, t, 0.0), (GRID_HALF_SIZE_M, t, 0.0)]
        colors += [color] * 4
    lift = 0.002  # above the grid lines, so the axes win the depth test
    axes = (
        ((AXIS_LENGTH_M, 0.0, lift), (230, 60, 50, 255)),
        ((0.0, AXIS_LENGTH_M, lift), (70, 200, 80, 255)),
        ((0.0, 0.0, AXIS_LENGTH_M), (70, 120, 240, 255)),
    )
    for end, color in axes:
        points += [(0.0, 0.0, lift), end]
        colors += [color, color]
    positions = np.asarray(points, dtype=np.float32)
    return MeshData(
        positions=positions,
        normals=np.zeros_like(positions),
        colors=np.asarray(colors, dtype=np.uint8),
    )


def _compile(kind: int, source: str) -> int:
    shader = int(GL.glCreateShader(kind))
    GL.glShaderSource(shader, source)
    GL.glCompileShader(shader)
    if not GL.glGetShaderiv(shader, GL.GL_COMPILE_STATUS):
        log = GL.glGetShaderInfoLog(shader)
        GL.glDeleteShader(shader)
        raise RenderError(f"shader compile failed: {_text(log)}")
    return shader


def _text(log: object) -> str:
    return log.decode(errors="replace") if isinstance(log, bytes) else str(log)


def _matrix(matrix: npt.NDArray[np.float64]) -> npt.NDArray[np.float32]:
    # OpenGL reads column-major: send the transpose of our row-major matrices.
    return np.ascontiguousarray(matrix.T, dtype=np.float32)


class ModelRenderer:
    """Draws a RobotModel's link meshes with a simple lit shader, plus grid, axes and ghost."""

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self._program = 0
        self._buffers: dict[str, _Buffer] = {}
        self._grid: _Buffer | None = None
        self._uniforms: dict[str, int] = {}
        self.buffer_uploads = 0  # glBufferData calls: stays put after initialize()
        self.initialized = False
        # Helpers drawn over the robot, by name: uploaded once, at the first frame after
        # they are given (the GL context is current only while drawing).
        self._overlay_meshes: dict[str, tuple[MeshData, str]] = {}
        self._pending: set[str] = set()
        self._overlays: dict[str, _Buffer] = {}

    def set_overlay_mesh(self, name: str, mesh: MeshData, mode: str = "lines") -> None:
        """A helper mesh (lines or triangles) that frames may draw by name."""
        if mode not in OVERLAY_MODES:
            raise ValueError(f"overlay mode must be one of {OVERLAY_MODES}, got {mode!r}")
        self._overlay_meshes[name] = (mesh, mode)
        self._pending.add(name)

    def initialize(self) -> None:
        """Compile the shaders and upload every mesh once; needs a current GL 3.3 context."""
        vertex = _compile(GL.GL_VERTEX_SHADER, VERTEX_SHADER)
        fragment = _compile(GL.GL_FRAGMENT_SHADER, FRAGMENT_SHADER)
        program = int(GL.glCreateProgram())
        GL.glAttachShader(program, vertex)
        GL.glAttachShader(program, fragment)
        GL.glLinkProgram(program)
        GL.glDeleteShader(vertex)
        GL.glDeleteShader(fragment)
        if not GL.glGetProgramiv(program, GL.GL_LINK_STATUS):
            log = GL.glGetProgramInfoLog(program)
            GL.glDeleteProgram(program)
            raise RenderError(f"shader link failed: {_text(log)}")
        self._program = program
        for name in ("u_model", "u_view_projection", "u_eye", "u_tint", "u_alpha", "u_lit"):
            self._uniforms[name] = int(GL.glGetUniformLocation(program, name))
        for link, mesh in self.model.meshes.items():
            if mesh.vertex_count:
                self._buffers[link] = self._upload(mesh, GL.GL_TRIANGLES)
        self._grid = self._upload(grid_lines(), GL.GL_LINES)
        self.initialized = True
        self._pending = set(self._overlay_meshes)
        self._upload_overlays()

    def _upload_overlays(self) -> None:
        for name in sorted(self._pending):
            mesh, mode = self._overlay_meshes[name]
            old = self._overlays.pop(name, None)
            if old is not None:
                GL.glDeleteVertexArrays(1, [old.vao])
                GL.glDeleteBuffers(1, [old.vbo])
            if mesh.vertex_count:
                kind = GL.GL_LINES if mode == "lines" else GL.GL_TRIANGLES
                self._overlays[name] = self._upload(mesh, kind)
        self._pending.clear()

    def _upload(self, mesh: MeshData, mode: int) -> _Buffer:
        data = interleave(mesh)
        vao = int(GL.glGenVertexArrays(1))
        vbo = int(GL.glGenBuffers(1))
        GL.glBindVertexArray(vao)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, vbo)
        GL.glBufferData(GL.GL_ARRAY_BUFFER, data.nbytes, data, GL.GL_STATIC_DRAW)
        self.buffer_uploads += 1
        stride = VERTEX_DTYPE.itemsize
        layout = (
            (0, 3, GL.GL_FLOAT, False, "position"),
            (1, 3, GL.GL_FLOAT, False, "normal"),
            (2, 4, GL.GL_UNSIGNED_BYTE, True, "color"),
        )
        for location, size, kind, normalized, field in layout:
            offset = VERTEX_DTYPE.fields[field][1] if VERTEX_DTYPE.fields else 0
            GL.glEnableVertexAttribArray(location)
            GL.glVertexAttribPointer(
                location, size, kind, normalized, stride, ctypes.c_void_p(offset)
            )
        GL.glBindVertexArray(0)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)
        return _Buffer(vao=vao, vbo=vbo, count=mesh.vertex_count, mode=mode)

    def render(self, frame: RenderFrame, width_px: int, height_px: int) -> None:
        """Draw one frame into the bound framebuffer (initialize() first)."""
        if not self.initialized:
            self.initialize()
        if self._pending:
            self._upload_overlays()
        GL.glViewport(0, 0, width_px, height_px)
        GL.glClearColor(*frame.background)
        GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDepthFunc(GL.GL_LESS)
        GL.glDepthMask(GL.GL_TRUE)
        GL.glDisable(GL.GL_CULL_FACE)
        GL.glDisable(GL.GL_BLEND)
        GL.glUseProgram(self._program)
        u = self._uniforms
        GL.glUniformMatrix4fv(
            u["u_view_projection"], 1, GL.GL_FALSE, _matrix(frame.projection @ frame.view)
        )
        GL.glUniform3f(u["u_eye"], *frame.eye)
        GL.glUniform1i(u["u_lit"], 1 if frame.lit else 0)
        GL.glUniform1f(u["u_alpha"], 1.0)
        self._draw_links(frame.links)
        if frame.show_grid and self._grid is not None:
            GL.glUniform1i(u["u_lit"], 0)
            GL.glUniform4f(u["u_tint"], *NO_TINT)
            GL.glUniformMatrix4fv(u["u_model"], 1, GL.GL_FALSE, _matrix(np.eye(4)))
            GL.glBindVertexArray(self._grid.vao)
            GL.glDrawArrays(self._grid.mode, 0, self._grid.count)
            GL.glUniform1i(u["u_lit"], 1 if frame.lit else 0)
        for overlay, alpha in (
            (frame.readings, frame.reading_alpha),
            (frame.ghosts, frame.ghost_alpha),
        ):
            if not overlay:
                continue
            GL.glEnable(GL.GL_BLEND)
            # Blend colour only: the target's alpha stays opaque, or Qt's compositor (and a
            # PNG) would show the window behind the ghost.
            GL.glBlendFuncSeparate(
                GL.GL_SRC_ALPHA, GL.GL_ONE_MINUS_SRC_ALPHA, GL.GL_ZERO, GL.GL_ONE
            )
            GL.glDepthMask(GL.GL_FALSE)
            GL.glUniform1f(u["u_alpha"], alpha)
            self._draw_links(overlay)
            GL.glDepthMask(GL.GL_TRUE)
            GL.glDisable(GL.GL_BLEND)
        if frame.overlays:
            self._draw_overlays(frame.overlays)
        GL.glBindVertexArray(0)
        GL.glUseProgram(0)

    def _draw_overlays(self, overlays: Sequence[OverlayDraw]) -> None:
        u = self._uniforms
        GL.glUniform1i(u["u_lit"], 0)
        GL.glUniform4f(u["u_tint"], *NO_TINT)
        GL.glEnable(GL.GL_BLEND)
        GL.glBlendFuncSeparate(GL.GL_SRC_ALPHA, GL.GL_ONE_MINUS_SRC_ALPHA, GL.GL_ZERO, GL.GL_ONE)
        GL.glDepthMask(GL.GL_FALSE)
        for item in overlays:
            buffer = self._overlays.get(item.mesh)
            if buffer is None:
                continue
            if item.on_top:
                GL.glDisable(GL.GL_DEPTH_TEST)
            GL.glUniform1f(u["u_alpha"], item.alpha)
            GL.glUniformMatrix4fv(u["u_model"], 1, GL.GL_FALSE, _matrix(item.world))
            GL.glBindVertexArray(buffer.vao)
            GL.glDrawArrays(buffer.mode, 0, buffer.count)
            if item.on_top:
                GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDepthMask(GL.GL_TRUE)
        GL.glDisable(GL.GL_BLEND)

    def _draw_links(self, links: Sequence[LinkDraw]) -> None:
        u = self._uniforms
        for item in links:
            buffer = self._buffers.get(item.link)
            if buffer is None:
                continue
            GL.glUniformMatrix4fv(u["u_model"], 1, GL.GL_FALSE, _matrix(item.world))
            GL.glUniform4f(u["u_tint"], *(item.tint or NO_TINT))
            GL.glBindVertexArray(buffer.vao)
            GL.glDrawArrays(buffer.mode, 0, buffer.count)

    def vertex_buffer(self, link: str) -> int:
        """The GL name of a link's vertex buffer."""
        return self._buffers[link].vbo

    def read_buffer(self, link: str) -> bytes:
        """The bytes of a link's vertex buffer as the GPU holds them (for checks)."""
        buffer = self._buffers[link]
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, buffer.vbo)
        size = buffer.count * VERTEX_DTYPE.itemsize
        data = GL.glGetBufferSubData(GL.GL_ARRAY_BUFFER, 0, size)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)
        return bytes(np.asarray(data, dtype=np.uint8).tobytes())

    def release(self) -> None:
        """Delete the GL objects; needs the same context current."""
        buffers = list(self._buffers.values()) + list(self._overlays.values())
        if self._grid is not None:
            buffers.append(self._grid)
        for buffer in buffers:
            GL.glDeleteVertexArrays(1, [buffer.vao])
            GL.glDeleteBuffers(1, [buffer.vbo])
        if self._program:
            GL.glDeleteProgram(self._program)
        self._buffers.clear()
        self._overlays.clear()
        self._grid = None
        self._program = 0
        self.initialized = False
