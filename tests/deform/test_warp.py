"""Tests of voxwarp.deform.warp: CPU references, chains, GLSL composition and CPU/GPU agreement.

The CPU tests use geometric oracles (inverse maps, fixed points, finite differences);
the ``gl`` tests compile the GLSL of :func:`compose_glsl` into a tiny program that writes
``warp_chain(p)`` and ``warp_chain_jacobian(p)`` of a uniform ``p`` into a float
framebuffer and compare it with :func:`chain_apply` and the product of the matrices.
"""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pytest

from voxwarp.deform.warp import (
    AffineWarp,
    IdentityWarp,
    Warp,
    WarpError,
    box_corners,
    chain_apply,
    chain_deformed_bounds,
    compose_glsl,
    fold_affine,
    known_warps,
    warp_from_dict,
)


class SwirlWarp(Warp):
    """A non-affine test warp (not registered): x += a * sin(y), y += a * z**2."""

    kind = "test-swirl"
    glsl_file = "warp_identity.glsl"

    def __init__(self, a: float = 0.3) -> None:
        self.a = a

    def apply(self, points: np.ndarray) -> np.ndarray:
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        q = p.copy()
        q[:, 0] += self.a * np.sin(p[:, 1])
        q[:, 1] += self.a * p[:, 2] ** 2
        return q

    def analytic_jacobian(self, points: np.ndarray) -> np.ndarray:
        p = np.atleast_2d(points)
        j = np.broadcast_to(np.eye(3), (len(p), 3, 3)).copy()
        j[:, 0, 1] = self.a * np.cos(p[:, 1])
        j[:, 1, 2] = 2 * self.a * p[:, 2]
        return j

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.kind, "a": self.a}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SwirlWarp:
        return cls(d["a"])


def rng_points(n: int = 200, seed: int = 0, scale: float = 50.0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-scale, scale, (n, 3))


def forward(w: AffineWarp, p: np.ndarray) -> np.ndarray:
    """Original -> deformed, from the documented forward matrix."""
    return p @ w.forward_matrix[:3, :3].T + w.forward_matrix[:3, 3]


def finite_difference_jacobian(w: Warp, p: np.ndarray, eps: float = 1e-5) -> np.ndarray:
    out = np.empty((len(p), 3, 3))
    for a in range(3):
        e = np.zeros(3)
        e[a] = eps
        out[:, :, a] = (w.apply(p + e) - w.apply(p - e)) / (2 * eps)
    return out


AFFINES = [
    AffineWarp.translation((3.0, -4.0, 12.5)),
    AffineWarp.scaling((2.0, 0.5, 1.25), center=(10, 20, 30)),
    AffineWarp.scaling(3.0),
    AffineWarp.rotation((0.3, -1.0, 2.0), 47.0, center=(-5, 6, 7)),
    AffineWarp(
        [[1.0, 0.4, 0.0, 1.0], [0.0, 1.0, -0.3, 2.0], [0.2, 0.0, 0.9, 3.0], [0.0, 0.0, 0.0, 1.0]]
    ),
]


# ---------------------------------------------------------------------- identity / affine
def test_identity_warp() -> None:
    p = rng_points()
    w = IdentityWarp()
    np.testing.assert_array_equal(w.apply(p), p)
    assert w.apply(p) is not p
    np.testing.assert_array_equal(w.jacobian(p), np.broadcast_to(np.eye(3), (len(p), 3, 3)))
    assert w.is_affine
    np.testing.assert_array_equal(w.affine_matrix(), np.eye(4))
    lo, hi = w.deformed_bounds(np.array([0, 1, 2]), np.array([3, 4, 5]))
    np.testing.assert_array_equal(lo, [0, 1, 2])
    np.testing.assert_array_equal(hi, [3, 4, 5])
    assert w.apply([1, 2, 3]).shape == (1, 3)


@pytest.mark.parametrize("w", AFFINES, ids=lambda w: str(np.round(w.forward_matrix[:3, 3], 2)))
def test_apply_inverts_forward(w: AffineWarp) -> None:
    p = rng_points()
    np.testing.assert_allclose(w.apply(forward(w, p)), p, atol=1e-10)
    np.testing.assert_allclose(forward(w, w.apply(p)), p, atol=1e-10)


def test_translation_moves_the_object() -> None:
    w = AffineWarp.translation((1, 2, 3))
    # the object appears moved by +offset: what is seen at p comes from p - offset
    np.testing.assert_allclose(w.apply([[1, 2, 3]]), [[0, 0, 0]])
    np.testing.assert_allclose(w.apply([[0, 0, 0]]), [[-1, -2, -3]])


def test_scaling_about_a_centre() -> None:
    w = AffineWarp.scaling(2.0, center=(10, 10, 10))
    np.testing.assert_allclose(w.apply([[10, 10, 10]]), [[10, 10, 10]])
    np.testing.assert_allclose(w.apply([[14, 10, 6]]), [[12, 10, 8]])  # distances halve


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 2, -3)])
@pytest.mark.parametrize("degrees", [30.0, 90.0, 181.0, -73.0])
def test_rotation_keeps_its_centre_and_axis_fixed(axis: Sequence[float], degrees: float) -> None:
    c = np.array([4.0, -2.0, 9.0])
    w = AffineWarp.rotation(axis, degrees, center=c)
    np.testing.assert_allclose(w.apply(c), [c], atol=1e-12)
    on_axis = c + 7.5 * np.asarray(axis, float)
    np.testing.assert_allclose(w.apply(on_axis), [on_axis], atol=1e-12)
    # rigid: distances are kept, orientation too
    p = rng_points(50)
    q = w.apply(p)
    np.testing.assert_allclose(
        np.linalg.norm(q[1:] - q[:-1], axis=1), np.linalg.norm(p[1:] - p[:-1], axis=1)
    )
    assert np.linalg.det(w.forward_matrix[:3, :3]) == pytest.approx(1.0)


def test_rotation_90_about_z_maps_x_to_y_forward() -> None:
    w = AffineWarp.rotation((0, 0, 1), 90.0)
    np.testing.assert_allclose(forward(w, np.array([[1.0, 0, 0]])), [[0, 1, 0]], atol=1e-15)
    np.testing.assert_allclose(forward(w, np.array([[0, 1.0, 0]])), [[-1, 0, 0]], atol=1e-15)
    # so the point seen at +y comes from +x
    np.testing.assert_allclose(w.apply([[0, 1.0, 0]]), [[1, 0, 0]], atol=1e-15)


def test_rotation_about_a_zero_axis_is_an_error() -> None:
    with pytest.raises(WarpError, match="axis"):
        AffineWarp.rotation((0, 0, 0), 10)


@pytest.mark.parametrize("w", AFFINES, ids=lambda w: str(np.round(w.forward_matrix[:3, 3], 2)))
def test_affine_jacobian_equals_finite_differences(w: AffineWarp) -> None:
    p = rng_points(30)
    np.testing.assert_allclose(w.jacobian(p), finite_difference_jacobian(w, p), atol=1e-7)
    np.testing.assert_allclose(w.affine_matrix() @ w.forward_matrix, np.eye(4), atol=1e-12)


def test_default_jacobian_of_a_non_affine_warp() -> None:
    w = SwirlWarp(0.7)
    p = rng_points(40, scale=3.0)
    np.testing.assert_allclose(w.jacobian(p), w.analytic_jacobian(p), atol=1e-5)
    assert not w.is_affine
    with pytest.raises(WarpError, match="not affine"):
        w.affine_matrix()


@pytest.mark.parametrize("w", AFFINES, ids=lambda w: str(np.round(w.forward_matrix[:3, 3], 2)))
def test_deformed_bounds_contain_the_forward_image_of_the_box(w: AffineWarp) -> None:
    lo, hi = np.array([-10.0, 0.0, 5.0]), np.array([20.0, 8.0, 40.0])
    dlo, dhi = w.deformed_bounds(lo, hi)
    p = np.random.default_rng(2).uniform(lo, hi, (2000, 3))
    f = forward(w, np.vstack([p, box_corners(lo, hi)]))
    assert np.all(f >= dlo - 1e-9)
    assert np.all(f <= dhi + 1e-9)
    # and it is the tightest box: the corners reach every face
    np.testing.assert_allclose(f.min(axis=0), dlo, atol=1e-9)
    np.testing.assert_allclose(f.max(axis=0), dhi, atol=1e-9)
    # every point of the deformed box that maps into [lo, hi] lies in it (by construction)
    inside = w.apply(np.random.default_rng(4).uniform(dlo, dhi, (2000, 3)))
    assert np.any(np.all((inside >= lo) & (inside <= hi), axis=1))


# ---------------------------------------------------------------------- chains
def test_chain_apply_order() -> None:
    w0 = AffineWarp.translation((10, 0, 0))
    w1 = AffineWarp.scaling(2.0)
    p = rng_points(20)
    np.testing.assert_allclose(chain_apply([w0, w1], p), w1.apply(w0.apply(p)))
    # not commutative: the order matters
    assert not np.allclose(chain_apply([w1, w0], p), chain_apply([w0, w1], p))
    np.testing.assert_allclose(chain_apply([w0, w1], [[10, 0, 0]]), [[0, 0, 0]])
    np.testing.assert_allclose(chain_apply([w1, w0], [[10, 0, 0]]), [[-5, 0, 0]])
    np.testing.assert_array_equal(chain_apply([], p), p)


def test_chain_with_a_non_affine_warp() -> None:
    chain = [AFFINES[3], SwirlWarp(0.2), AFFINES[1]]
    p = rng_points(30, scale=4.0)
    np.testing.assert_allclose(
        chain_apply(chain, p), AFFINES[1].apply(SwirlWarp(0.2).apply(AFFINES[3].apply(p)))
    )


def test_chain_deformed_bounds_contain_the_deformed_box() -> None:
    w0, w1 = AFFINES[3], AFFINES[4]
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([30.0, 20.0, 10.0])
    dlo, dhi = chain_deformed_bounds([w0, w1], lo, hi)
    q = np.random.default_rng(9).uniform(lo, hi, (3000, 3))
    p = forward(w0, forward(w1, q))  # chain_apply([w0, w1], p) == q
    np.testing.assert_allclose(chain_apply([w0, w1], p), q, atol=1e-9)
    assert np.all(p >= dlo - 1e-9)
    assert np.all(p <= dhi + 1e-9)


def test_fold_affine_equals_chain_apply() -> None:
    rng = np.random.default_rng(11)
    for _ in range(10):
        chain = [AFFINES[i] for i in rng.choice(len(AFFINES), 3)] + [IdentityWarp()]
        m = fold_affine(chain)
        assert m is not None
        assert m.shape == (4, 4)
        p = rng_points(50, seed=int(rng.integers(100)))
        np.testing.assert_allclose(p @ m[:3, :3].T + m[:3, 3], chain_apply(chain, p), atol=1e-9)
    np.testing.assert_array_equal(fold_affine([]), np.eye(4))


def test_fold_affine_is_none_with_a_non_affine_warp() -> None:
    assert fold_affine([AFFINES[0], SwirlWarp(), AFFINES[1]]) is None
    assert fold_affine([SwirlWarp()]) is None


# ---------------------------------------------------------------------- GLSL composition
def test_compose_glsl_renames_uniforms_and_functions_per_index() -> None:
    src = compose_glsl([AFFINES[0], AFFINES[1]])
    assert "WARP_" not in src
    assert re.search(r"uniform\s+mat4\s+w0_matrix\s*;", src)
    assert re.search(r"uniform\s+mat4\s+w1_matrix\s*;", src)
    for i in (0, 1):
        assert re.search(rf"vec3\s+w{i}_warp\s*\(", src)
        assert re.search(rf"mat3\s+w{i}_warp_jacobian\s*\(", src)
    assert "(w0_matrix * vec4(p, 1.0))" in src  # bodies use the renamed uniforms
    assert "mat3(w1_matrix)" in src
    # no un-prefixed definition of warp/warp_jacobian is left to clash
    assert not re.search(r"(?<![\w])warp(_jacobian)?\s*\(", src)
    assert re.search(r"vec3\s+warp_chain\s*\(", src)
    assert re.search(r"mat3\s+warp_chain_jacobian\s*\(", src)
    # the chain calls the warps in order
    body = src[src.index("vec3 warp_chain(") :]
    assert body.index("w0_warp(p)") < body.index("w1_warp(p)")


def test_compose_glsl_with_a_custom_loader_touches_only_warp_names() -> None:
    text = (
        "uniform float WARP_scale;\n"
        "uniform sampler3D WARP_field;\n"
        "float MY_WARP_x = 1.0;\n"
        "vec3 warp_helper_not_renamed(vec3 p) { return p * WARP_scale; }\n"
        "vec3 warp (vec3 p) { return warp_helper_not_renamed(p); }\n"
        "mat3 warp_jacobian(vec3 p) { return mat3(WARP_scale); }\n"
    )
    src = compose_glsl([SwirlWarp(), SwirlWarp()], loader=lambda name: text)
    for i in (0, 1):
        assert f"uniform float w{i}_scale;" in src
        assert f"uniform sampler3D w{i}_field;" in src
        assert f"vec3 w{i}_warp (vec3 p)" in src
        assert f"mat3 w{i}_warp_jacobian(vec3 p) {{ return mat3(w{i}_scale); }}" in src
    assert src.count("MY_WARP_x") == 2  # not a WARP_ prefix: left alone
    assert src.count("warp_helper_not_renamed(vec3 p)") == 2


def test_compose_glsl_of_an_empty_chain_is_the_identity() -> None:
    src = compose_glsl([])
    assert "vec3 warp_chain(vec3 p) {\n    return p;\n}" in src
    assert (
        "vec3 warp_chain_and_jacobian(vec3 p, out mat3 J) {\n    J = mat3(1.0);\n    return p;"
        in src
    )
    assert "warp_chain_and_jacobian(p, J);\n    return J;" in src  # warp_chain_jacobian


# ---------------------------------------------------------------------- CPU/GPU agreement
VERTEX = """#version 430
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

FRAGMENT = """#version 430
uniform vec3 u_p;
out vec4 frag;
{warps}
void main() {{
    int x = int(gl_FragCoord.x);
    if (x == 0) {{
        frag = vec4(warp_chain(u_p), 1.0);
    }} else {{
        frag = vec4(warp_chain_jacobian(u_p)[x - 1], 1.0);  // column x - 1
    }}
}}
"""


def gpu_chain(ctx: Any, warps: Sequence[Warp], points: np.ndarray) -> tuple:
    """(warp_chain(p), warp_chain_jacobian(p)) per point, evaluated on the GPU."""
    prog = ctx.program(
        vertex_shader=VERTEX, fragment_shader=FRAGMENT.format(warps=compose_glsl(warps))
    )
    # moderngl re-binds the context's last bound framebuffer after creating one; if an
    # earlier test released that one, the re-bind raises GL_INVALID_OPERATION
    ctx.detect_framebuffer(0).use()
    fbo = ctx.simple_framebuffer((4, 1), components=4, dtype="f4")
    vao = ctx.vertex_array(prog, [])
    try:
        for i, w in enumerate(warps):
            for name, value in w.uniforms().items():
                m = np.asarray(value, dtype=np.float32)
                prog[f"w{i}_{name}"].write(np.ascontiguousarray(m.T).tobytes())  # column-major
        qs, js = [], []
        for p in points:
            prog["u_p"].value = tuple(float(v) for v in p)
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            vao.render(mode=ctx.TRIANGLES, vertices=3)
            px = np.frombuffer(fbo.read(components=4, dtype="f4"), dtype=np.float32).reshape(4, 4)
            assert np.all(px[:, 3] == 1.0), "every pixel was written"
            qs.append(px[0, :3])
            js.append(px[1:, :3].T)  # columns back to a matrix
        return np.array(qs, dtype=np.float64), np.array(js, dtype=np.float64)
    finally:
        ctx.detect_framebuffer(0).use()  # leave no deleted framebuffer bound
        vao.release()
        fbo.release()
        prog.release()


GPU_CHAINS = {
    "two-affine": [AFFINES[3], AFFINES[1]],
    "affine-identity-affine": [AFFINES[4], IdentityWarp(), AffineWarp.rotation((0, 0, 1), 90.0)],
    "single-translation": [AFFINES[0]],
    "empty": [],
}


@pytest.mark.gl
@pytest.mark.parametrize("name", list(GPU_CHAINS))
def test_glsl_warp_chain_matches_the_cpu(gl_ctx: Any, name: str) -> None:
    warps = GPU_CHAINS[name]
    points = rng_points(8, seed=21, scale=20.0)
    q_gpu, j_gpu = gpu_chain(gl_ctx, warps, points)
    q_cpu = chain_apply(warps, points)
    scale = max(1.0, float(np.abs(q_cpu).max()))
    np.testing.assert_allclose(q_gpu, q_cpu, atol=1e-4 * scale, rtol=0)
    # chain rule for affine warps: J = A_{n-1} ... A_0 (linear parts of the inverses)
    j_cpu = np.eye(3)
    for w in warps:
        j_cpu = w.affine_matrix()[:3, :3] @ j_cpu
    np.testing.assert_allclose(j_gpu, np.broadcast_to(j_cpu, j_gpu.shape), atol=1e-4)
    # the CPU jacobians agree too (chain rule on the CPU reference)
    if warps:
        cpu_j = np.eye(3)
        for w in warps:
            cpu_j = w.jacobian(points[:1])[0] @ cpu_j
        np.testing.assert_allclose(cpu_j, j_cpu, atol=1e-12)


@pytest.mark.gl
def test_glsl_of_two_warps_of_one_kind_compiles_in_the_raycaster_names(gl_ctx: Any) -> None:
    """Three affine warps: uniforms w0_/w1_/w2_matrix are all active and distinct."""
    warps = [AFFINES[0], AFFINES[2], AFFINES[3]]
    prog = gl_ctx.program(
        vertex_shader=VERTEX, fragment_shader=FRAGMENT.format(warps=compose_glsl(warps))
    )
    try:
        for i in range(3):
            assert f"w{i}_matrix" in prog
    finally:
        prog.release()


# ---------------------------------------------------------------------- serialisation
def test_registry_and_round_trip() -> None:
    assert {"identity", "affine"} <= set(known_warps())
    for w in [*AFFINES, IdentityWarp()]:
        back = warp_from_dict(w.to_dict())
        assert type(back) is type(w)
        np.testing.assert_array_equal(back.affine_matrix(), w.affine_matrix())
    three_by_four = warp_from_dict(
        {"type": "affine", "matrix": AFFINES[4].forward_matrix[:3].tolist()}
    )
    np.testing.assert_array_equal(three_by_four.forward_matrix, AFFINES[4].forward_matrix)


@pytest.mark.parametrize(
    ("d", "pattern"),
    [
        ({}, "'type'"),
        ({"matrix": np.eye(4).tolist()}, "'type'"),
        ([1, 2], "'type'"),
        (None, "'type'"),
        ({"type": "twirl"}, "unknown warp type 'twirl'.*affine"),
        ({"type": ["affine"]}, "unknown warp type"),
        ({"type": None}, "unknown warp type"),
        ({"type": "affine"}, "'matrix'"),
        ({"type": "affine", "matrix": np.zeros((4, 4)).tolist()}, "last row|singular"),
        ({"type": "affine", "matrix": np.diag([1.0, 0.0, 1.0, 1.0]).tolist()}, "singular"),
        ({"type": "affine", "matrix": np.eye(3).tolist()}, "shape"),
        ({"type": "affine", "matrix": np.eye(5).tolist()}, "shape"),
        ({"type": "affine", "matrix": [1, 2, 3]}, "shape"),
        ({"type": "affine", "matrix": [[1, 2], [3]]}, "matrix"),
        ({"type": "affine", "matrix": "eye"}, "matrix"),
        ({"type": "affine", "matrix": {"a": 1}}, "matrix"),
        ({"type": "affine", "matrix": [[float("nan")] * 4] * 4}, "NaN"),
        (
            {"type": "affine", "matrix": [[1, 0, 0, float("inf")], *np.eye(4)[1:].tolist()]},
            "NaN/Inf",
        ),
        ({"type": "affine", "matrix": [*np.eye(4)[:3].tolist(), [1, 0, 0, 1]]}, "last row"),
    ],
)
def test_warp_from_dict_errors(d: Any, pattern: str) -> None:
    with pytest.raises(WarpError, match=pattern):
        warp_from_dict(d)


def test_warp_error_is_a_value_error() -> None:
    assert issubclass(WarpError, ValueError)


def test_built_in_warps_load_without_importing_their_modules() -> None:
    """Scene JSON names a warp kind; reading it must not depend on earlier imports."""
    code = (
        "import sys\n"
        "from voxwarp.deform.warp import known_warps, warp_from_dict\n"
        "assert 'voxwarp.deform.lattice.warp' not in sys.modules\n"
        "print(known_warps())\n"
        "box = [[0, 0, 0], [1, 1, 1]]\n"
        "w = warp_from_dict({'type': 'lattice', 'grid': {'nodes': %r}, 'box': box})\n"
        "print(type(w).__module__)\n"
    )
    nodes = [[[[float(i), float(j), float(k)] for k in (0, 1)] for j in (0, 1)] for i in (0, 1)]
    res = subprocess.run(
        [sys.executable, "-c", code % nodes], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr
    kinds, module = res.stdout.split("\n")[:2]
    for kind in ("affine", "identity", "lattice", "offset_field", "wires"):
        assert repr(kind) in kinds
    assert module == "voxwarp.deform.lattice.warp"
