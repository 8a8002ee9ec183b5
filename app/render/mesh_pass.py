"""Drawing mesh instances deformed in the vertex shader (moderngl).

About this technique
--------------------
Knuth, Kohlhammer and Kuijper ("Embedding hierarchical deformation within a realtime
scene graph", GRAPP 2010, sections 4-6) deform scene-graph geometry on the GPU: each
leaf gets one composed transform, a 4x4 matrix or a grid of trilinear cells, and the
vertex shader applies it, so a vertex costs the same whatever the depth of the graph.
Here (``shaders/mesh.vert.glsl``):

* a matrix instance is drawn by the ``LINEAR`` program (one matrix product per vertex),
  and so is a lattice whose grid is one affine map
  (:meth:`voxwarp.core.mesh.MeshInstance.affine_matrix`): the paper's fast path for
  parallelepipeds (section 4.1, last paragraph), same positions and normals;
* a lattice instance uploads its grid nodes as an RGBA32F 3D texture
  (:meth:`voxwarp.deform.lattice.trilinear.TrilinearGrid.texture_data`); each vertex fetches the 8
  nodes
  of its cell and evaluates the trilinear map and its analytic Jacobian (exact float
  arithmetic). ``position="hardware"`` evaluates the position with one hardware
  trilinear fetch at node-centred coordinates instead (the paper's texture lookup;
  GPUs quantise filter weights to 8 bits, 1/256 of a cell);
* normals follow section 4.2, per instance: ``"normal"``, the direct transform ``J n``
  (smooth across cell faces), or ``"tangent"`` (two tangents through ``J``, crossed:
  orthogonal to the surface, seams at cell faces); a matrix instance's ``"normal"`` is
  its exact inverse transpose (:func:`voxwarp.deform.lattice.trilinear.carry_normals` and
  ``shaders/mesh.vert.glsl`` say more).

With a scene's warp chain (``draw(..., warps=...)``) the meshes move with the volume:
an all-affine chain joins the instance matrix; any other chain is baked per vertex on the
CPU through its forward map (:mod:`voxwarp.core.mesh_warp`) and drawn by the ``LINEAR``
program with an identity model matrix, its buffers cached per mesh, transform and warp
revisions.

Fragments get Blinn-Phong shading with a headlight, lit from both sides, and are written
premultiplied with depth. Opaque instances are drawn first with depth writes; translucent
ones (alpha < 1) after them, blended (premultiplied "over") without depth writes and
unsorted, so overlapping translucent instances depend on their order.

:class:`MeshRenderer` draws into a framebuffer it is given;
:class:`voxwarp.render.raycaster.Renderer`
uses it for mixed scenes (meshes depth-composited with the volume).
"""

from __future__ import annotations

import weakref
from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np

from voxwarp import shaders
from voxwarp.core.camera import Camera
from voxwarp.core.mesh import Mesh, MeshInstance
from voxwarp.core.mesh_warp import affine_forward, moves_meshes, warped_geometry
from voxwarp.deform import gl_programs
from voxwarp.deform.lattice.trilinear import TrilinearGrid, cofactor_matrix
from voxwarp.deform.warp import Warp, WarpError
from voxwarp.errors import RenderError
from voxwarp.render.gl_uniforms import set_uniform

#: Blinn-Phong ambient, diffuse, specular, shininess (as the raycaster's
#: voxwarp.render.raycaster.LIGHT).
MESH_LIGHT = (0.25, 0.7, 0.3, 32.0)
#: Vertex position evaluation of lattice instances.
POSITIONS = ("exact", "hardware")


class _MeshGPU:
    """Interleaved position + normal buffer and index buffer of one mesh (its own
    vertices, or ``vertices``/``normals`` baked through a warp chain)."""

    def __init__(
        self,
        ctx: Any,
        mesh: Mesh,
        vertices: np.ndarray | None = None,
        normals: np.ndarray | None = None,
    ) -> None:
        v = mesh.vertices if vertices is None else vertices
        n = mesh.normals if normals is None else normals
        data = np.concatenate([v, n], axis=1).astype(np.float32)
        self.vbo = ctx.buffer(np.ascontiguousarray(data).tobytes())
        self.ibo = ctx.buffer(np.ascontiguousarray(mesh.faces, dtype=np.uint32).tobytes())
        self.count = mesh.n_faces * 3
        self.vaos: dict[int, Any] = {}

    def vao(self, ctx: Any, prog: Any) -> Any:
        vao = self.vaos.get(id(prog))
        if vao is None:
            vao = ctx.vertex_array(
                prog,
                [(self.vbo, "3f 3f", "in_position", "in_normal")],
                index_buffer=self.ibo,
                index_element_size=4,
            )
            self.vaos[id(prog)] = vao
        return vao

    def release(self) -> None:
        for vao in self.vaos.values():
            vao.release()
        self.vaos.clear()
        self.vbo.release()
        self.ibo.release()


class MeshRenderer:
    """Draws :class:`~voxwarp.core.mesh.MeshInstance` lists on a given moderngl context.

    Parameters
    ----------
    ctx
        A ``moderngl.Context`` (OpenGL 4.3+); the caller owns it.
    position
        ``"exact"`` (default): lattice positions from the 8 fetched corner nodes;
        ``"hardware"``: one hardware-trilinear texture fetch (see the module docstring).
    linear_fast_path
        Draw lattices whose grid is one affine map with the ``LINEAR`` program (default
        True; False keeps them on the trilinear program, for benchmarks).

    GPU buffers are cached per mesh object and node textures per grid object (both are
    immutable), programs per variant; :meth:`release` frees everything (idempotent).
    """

    def __init__(self, ctx: Any, *, position: str = "exact", linear_fast_path: bool = True) -> None:
        if position not in POSITIONS:
            raise RenderError(f"position must be one of {', '.join(POSITIONS)}; got {position!r}")
        self.ctx = ctx
        self.position = position
        self.linear_fast_path = bool(linear_fast_path)
        #: instances drawn or read back by each program ("linear", "trilinear")
        self.program_uses: dict[str, int] = {"linear": 0, "trilinear": 0}
        self._programs: dict[tuple, Any] = {}
        self._meshes: dict[int, tuple[weakref.ref, _MeshGPU]] = {}
        #: buffers of instances baked through a warp chain, by mesh_warp.geometry_key
        self._baked: dict[Hashable, tuple[weakref.ref, _MeshGPU]] = {}
        self._grids: dict[int, tuple[weakref.ref, Any]] = {}
        #: 1x1 framebuffer bound during transform feedback (drivers such as Mesa check
        #: the bound framebuffer's completeness even with rasterisation discarded)
        self._feedback_fbo: tuple[Any, Any] | None = None
        self._released = False

    # ------------------------------------------------------------------ resources
    def _program(self, linear: bool, feedback: bool = False) -> Any:
        key = (linear, self.position, feedback)
        hold = self._programs.get(key)
        if hold is not None:
            return hold.program
        defines = []
        if linear:
            defines.append("#define LINEAR")
        elif self.position == "hardware":
            defines.append("#define HW_TRILINEAR")
        vert = shaders.with_defines(shaders.source("mesh.vert.glsl"), defines)
        try:  # compiled once per context, shared by its mesh renderers (gl_programs)
            if feedback:  # vertex stage only, its outputs captured (deformed_vertices)
                hold = gl_programs.program(
                    self.ctx, vertex_shader=vert, varyings=["v_world", "v_normal"]
                )
            else:
                hold = gl_programs.program(
                    self.ctx, vertex_shader=vert, fragment_shader=shaders.source("mesh.frag.glsl")
                )
        except Exception as exc:
            raise RenderError(f"mesh shader failed to compile/link for {key}: {exc}") from exc
        self._programs[key] = hold
        return hold.program

    def _mesh_gpu(self, mesh: Mesh) -> _MeshGPU:
        hit = self._meshes.get(id(mesh))
        if hit is not None and hit[0]() is mesh:
            return hit[1]
        if hit is not None:  # a dead mesh reused the id
            hit[1].release()
        gpu = _MeshGPU(self.ctx, mesh)
        self._meshes[id(mesh)] = (weakref.ref(mesh), gpu)
        return gpu

    def _grid_texture(self, grid: TrilinearGrid) -> Any:
        hit = self._grids.get(id(grid))
        if hit is not None and hit[0]() is grid:
            return hit[1]
        if hit is not None:
            hit[1].release()
        data = np.ascontiguousarray(grid.texture_data(), dtype=np.float32)
        nz, ny, nx = data.shape[:3]
        tex = self.ctx.texture3d((nx, ny, nz), 4, data.tobytes(), dtype="f4")
        tex.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        self._grids[id(grid)] = (weakref.ref(grid), tex)
        return tex

    def _baked_gpu(self, inst: MeshInstance, warps: Sequence[Warp]) -> _MeshGPU:
        """Buffers of ``inst`` moved by the chain (baked on the CPU once per mesh,
        transform and warp revisions; the previous revision's buffers are freed)."""
        try:
            positions, normals, key = warped_geometry(inst, warps)
        except WarpError as exc:
            raise RenderError(f"mesh {inst.name!r} cannot follow the warps: {exc}") from exc
        hit = self._baked.get(key)
        if hit is not None and hit[0]() is inst.mesh:
            return hit[1]
        for old in [k for k in self._baked if k[:2] == key[:2]]:  # type: ignore[index]
            self._baked.pop(old)[1].release()
        gpu = _MeshGPU(self.ctx, inst.mesh, positions, normals)
        self._baked[key] = (weakref.ref(inst.mesh), gpu)
        return gpu

    def _evict_dead(self) -> None:
        for cache in (self._meshes, self._grids, self._baked):
            for key in [k for k, (ref, _) in cache.items() if ref() is None]:
                cache.pop(key)[1].release()

    # ------------------------------------------------------------------ drawing
    def draw(
        self,
        instances: Sequence[MeshInstance],
        framebuffer: Any,
        camera: Camera,
        viewport: tuple[int, int, int, int] | None = None,
        *,
        clear: Sequence[float] | None = (0.0, 0.0, 0.0, 0.0),
        warps: Sequence[Warp] = (),
    ) -> None:
        """Draw ``instances`` seen by ``camera`` into ``framebuffer`` within ``viewport``.

        Writes premultiplied colour and depth (the framebuffer needs a depth attachment
        for occlusion). ``clear``: premultiplied RGBA the viewport's colour is cleared to
        (depth to 1) first; ``None`` draws over what is there. ``warps``: the scene's
        warp chain; the meshes move with the volume through its forward map (an
        all-affine chain joins the instance matrix; any other is baked per vertex on the
        CPU, see :mod:`voxwarp.core.mesh_warp`). A fold on a mesh raises
        :class:`RenderError`.
        """
        if self._released:
            raise RenderError("this MeshRenderer was released")
        instances = list(instances)
        for inst in instances:
            if not isinstance(inst, MeshInstance):
                raise RenderError(
                    f"MeshRenderer.draw takes MeshInstance objects; got {type(inst).__name__}"
                )
        self._evict_dead()
        if viewport is None:
            viewport = (0, 0, *framebuffer.size)
        x, y, w, h = (int(v) for v in viewport)
        if w <= 0 or h <= 0:
            raise RenderError(f"viewport must have a positive size; got {viewport}")
        ctx = self.ctx
        framebuffer.use()
        framebuffer.viewport = (x, y, w, h)
        if clear is not None:
            framebuffer.clear(*clear, depth=1.0, viewport=(x, y, w, h))
        if not instances:
            return
        view_proj = camera.view_projection(w / h)
        if camera.projection == "perspective":
            eye = (*camera.eye, 1.0)
        else:
            eye = (*camera.rotation[:, 2], 0.0)
        warps = list(warps) if moves_meshes(warps) else []
        drawn = [self._prepared(inst, warps) for inst in instances]
        opaque = [d for d in drawn if d[0].color[3] >= 1.0]
        translucent = [d for d in drawn if d[0].color[3] < 1.0]
        ctx.enable(ctx.DEPTH_TEST)
        ctx.disable(ctx.CULL_FACE)
        try:
            ctx.disable(ctx.BLEND)
            for inst, gpu in opaque:
                self._draw_instance(inst, gpu, view_proj, eye)
            if translucent:
                ctx.enable(ctx.BLEND)
                ctx.blend_func = (ctx.ONE, ctx.ONE_MINUS_SRC_ALPHA)
                framebuffer.depth_mask = False
                for inst, gpu in translucent:
                    self._draw_instance(inst, gpu, view_proj, eye)
        finally:
            framebuffer.depth_mask = True
            ctx.blend_func = ctx.DEFAULT_BLENDING
            ctx.disable(ctx.DEPTH_TEST | ctx.BLEND)

    def deformed_vertices(self, instance: MeshInstance) -> tuple[np.ndarray, np.ndarray]:
        """Run the vertex stage alone (transform feedback) and read its results back.

        Returns the (N, 3) world positions and (N, 3) unit normals the shader gives the
        mesh's vertices: what is drawn, for picking on deformed meshes and for tests
        against the CPU reference :meth:`voxwarp.core.mesh.MeshInstance.local_to_world`.
        """
        if self._released:
            raise RenderError("this MeshRenderer was released")
        if not isinstance(instance, MeshInstance):
            raise RenderError(f"deformed_vertices takes a MeshInstance; got {type(instance)}")
        self._evict_dead()
        prog = self._instance_program(instance, np.eye(4), (0.0, 0.0, 1.0, 0.0), feedback=True)
        gpu = self._mesh_gpu(instance.mesh)
        n = instance.mesh.n_vertices
        if self._feedback_fbo is None:
            rb = self.ctx.renderbuffer((1, 1), 4, dtype="f1")
            self._feedback_fbo = (self.ctx.framebuffer(color_attachments=[rb]), rb)
        previous = self.ctx.fbo
        out = self.ctx.buffer(reserve=n * 6 * 4)
        vao = self.ctx.vertex_array(prog, [(gpu.vbo, "3f 3f", "in_position", "in_normal")])
        try:
            self._feedback_fbo[0].use()
            vao.transform(out, mode=self.ctx.POINTS, vertices=n)
            data = np.frombuffer(out.read(), dtype=np.float32).reshape(n, 6).astype(np.float64)
        finally:
            vao.release()
            out.release()
            if previous is not None:
                previous.use()
        normals = data[:, 3:]
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            normals = normals / length
        return data[:, :3], normals

    def _prepared(self, inst: MeshInstance, warps: Sequence[Warp]) -> tuple[MeshInstance, _MeshGPU]:
        """The instance to set uniforms from and the buffers to draw for ``inst`` under
        the chain: itself; its matrix times the chain's forward matrix; or an identity
        instance over buffers baked through the chain."""
        if not warps:
            return inst, self._mesh_gpu(inst.mesh)
        forward = affine_forward(warps)
        if forward is None or inst.is_lattice:
            gpu = self._baked_gpu(inst, warps)
            forward, inst_matrix = np.eye(4), None
        else:
            gpu, inst_matrix = self._mesh_gpu(inst.mesh), inst.matrix()
        moved = MeshInstance(
            inst.mesh,
            forward if inst_matrix is None else forward @ inst_matrix,
            color=inst.color,
            normal_method=inst.normal_method,
            name=inst.name,
        )
        return moved, gpu

    def _draw_instance(
        self, inst: MeshInstance, gpu: _MeshGPU, view_proj: np.ndarray, eye: tuple
    ) -> None:
        prog = self._instance_program(inst, view_proj, eye)
        gpu.vao(self.ctx, prog).render(mode=self.ctx.TRIANGLES, vertices=gpu.count)

    def _instance_program(
        self, inst: MeshInstance, view_proj: np.ndarray, eye: tuple, feedback: bool = False
    ) -> Any:
        """The program that draws ``inst`` (counted in :attr:`program_uses`), with its
        uniforms set: ``LINEAR`` for a matrix or (with the fast path) a lattice that is one
        affine map, else the trilinear one."""
        m = inst.affine_matrix() if not inst.is_lattice or self.linear_fast_path else None
        self.program_uses["linear" if m is not None else "trilinear"] += 1
        prog = self._program(m is not None, feedback=feedback)
        self._set_instance_uniforms(prog, inst, m, view_proj, eye)
        return prog

    def _set_instance_uniforms(
        self,
        prog: Any,
        inst: MeshInstance,
        m: np.ndarray | None,
        view_proj: np.ndarray,
        eye: tuple,
    ) -> None:
        """``m``: the instance's affine matrix when the ``LINEAR`` program draws it."""
        method = 0 if inst.normal_method == "normal" else 1
        values: dict[str, Any] = {
            "u_view_proj": view_proj,
            "u_color": inst.color,
            "u_eye": tuple(float(v) for v in eye),
            "u_light": MESH_LIGHT,
        }
        if m is not None:
            values["u_model"] = m
            if not inst.is_lattice and method == 0:
                method = 2  # a matrix's exact normal: the inverse transpose
                a = m[:3, :3]
                # a singular matrix keeps the (defined) cofactor matrix
                singular = abs(float(np.linalg.det(a))) <= 1e-300
                values["u_normal_matrix"] = cofactor_matrix(a) if singular else np.linalg.inv(a).T
        else:
            grid = inst.transform
            assert isinstance(grid, TrilinearGrid)
            lo, hi = inst.box
            self._grid_texture(grid).use(0)
            values["u_nodes"] = 0
            values["u_cells"] = tuple(float(c) for c in grid.shape)
            values["u_box_lo"] = tuple(float(v) for v in lo)
            values["u_box_inv_size"] = tuple(float(v) for v in 1.0 / (hi - lo))
        values["u_normal_method"] = method
        for name, value in values.items():
            set_uniform(prog, name, value)

    def release(self) -> None:
        """Free every GPU resource this renderer made; idempotent."""
        if self._released:
            return
        for cache in (self._meshes, self._baked):
            for _, gpu in cache.values():
                gpu.release()
            cache.clear()
        for _, tex in self._grids.values():
            tex.release()
        self._grids.clear()
        for hold in self._programs.values():
            hold.release()  # the shared program stays for the context's other users
        self._programs.clear()
        if self._feedback_fbo is not None:
            if self.ctx.fbo is self._feedback_fbo[0]:
                # never delete the bound framebuffer (moderngl would re-bind the dead name)
                try:
                    self.ctx.detect_framebuffer(0).use()
                except Exception:
                    pass
            for obj in self._feedback_fbo:
                obj.release()
            self._feedback_fbo = None
        self._released = True
