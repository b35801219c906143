"""Body-body contact's narrow phase: the segment (2D) and triangle (3D) kernels, and the
feature (face, edge, vertex) a particle touches.

References are independent of the generated code: hand geometry, central finite
differences, the SymPy expressions evaluated directly, the ground kernel, Newton's third
law with moments, and a polygon's offset curve walked at a constant gap.
"""

from __future__ import annotations

import ctypes
import json

import numpy as np
import pytest

from flexbody.assembly import _kernels_module
from flexbody.cbuild import kernels_dir
from flexbody.surface_contact import EDGE, FACE, VERTEX, closest_features, point_edge, triangle_normals

from .conftest import HAS_CC

K = _kernels_module()


def segment(x, a, b):
    """The segment kernel on one element: gap, s, normal (2,), jacobian (6,)."""
    gap, s, normal, jac = K.segment_2d(*(np.asarray(z, float) for z in (x, a, b)))
    return gap[0], s[0], normal, jac[0]


def triangle(x, a, b, c):
    """The triangle kernel on one element: gap, barycentrics (3,), normal (3,), jacobian (12,)."""
    gap, bary, normal, jac = K.triangle_3d(*(np.asarray(z, float) for z in (x, a, b, c)))
    return gap[0], bary, normal, jac[0]


def random_triangle(rng):
    """A random, not too thin triangle and a particle near it (projection inside or out)."""
    while True:
        a, b, c = rng.normal(size=(3, 3))
        if np.linalg.norm(np.cross(b - a, c - a)) > 0.5:
            return rng.normal(size=3), a, b, c


def test_segment_gap_normal_and_s_match_hand_geometry():
    # a -> b along +x: a counter-clockwise boundary has its body above, so the outward normal is -y.
    gap, s, normal, _ = segment([0.5, -0.3], [0.0, 0.0], [2.0, 0.0])
    assert (gap, s) == pytest.approx((0.3, 0.25), abs=1e-15)
    np.testing.assert_allclose(normal, [0.0, -1.0], atol=1e-15)
    gap, s, _, _ = segment([0.5, 0.1], [0.0, 0.0], [2.0, 0.0])
    assert (gap, s) == pytest.approx((-0.1, 0.25), abs=1e-15)  # inside: negative
    # a -> b along +y: outward is +x; beyond b, s > 1 (the contact is not this segment's).
    gap, s, normal, _ = segment([1.5, 4.0], [1.0, 1.0], [1.0, 3.0])
    assert (gap, s) == pytest.approx((0.5, 1.5), abs=1e-15)
    np.testing.assert_allclose(normal, [1.0, 0.0], atol=1e-15)
    # A 3-4-5 segment: the distance of a point at known offsets along and across it.
    a, b = np.array([1.0, 2.0]), np.array([4.0, 6.0])
    along, across = np.array([0.6, 0.8]), np.array([0.8, -0.6])  # unit; across = right-hand perpendicular
    gap, s, normal, _ = segment(a + 2.0 * along + 0.7 * across, a, b)
    assert (gap, s) == pytest.approx((0.7, 0.4), abs=1e-14)
    np.testing.assert_allclose(normal, across, atol=1e-15)


def test_triangle_gap_normal_and_barycentrics_match_hand_geometry():
    gap, bary, normal, _ = triangle([0.2, 0.3, 0.7], [0, 0, 0], [1, 0, 0], [0, 1, 0])
    assert gap == pytest.approx(0.7, abs=1e-15)
    np.testing.assert_allclose(bary, [0.5, 0.2, 0.3], atol=1e-15)
    np.testing.assert_allclose(normal, [0, 0, 1], atol=1e-15)
    # Clockwise from above means the outside is below: the same point is 0.7 inside.
    gap, bary, normal, _ = triangle([0.2, 0.3, 0.7], [0, 0, 0], [0, 1, 0], [1, 0, 0])
    assert gap == pytest.approx(-0.7, abs=1e-15)
    np.testing.assert_allclose(bary, [0.5, 0.3, 0.2], atol=1e-15)
    # Projection outside the triangle: a barycentric below zero.
    _, bary, _, _ = triangle([2.0, 0.5, 0.1], [0, 0, 0], [1, 0, 0], [0, 1, 0])
    np.testing.assert_allclose(bary, [-1.5, 2.0, 0.5], atol=1e-15)


def test_triangle_in_the_ground_plane_gives_the_grounds_gap(rng):
    """A triangle lying in z = 0 (counter-clockwise from above, moved and turned in the plane)
    gives the ground's gap, normal and d gap / dx for any particle."""
    for _ in range(20):
        turn = rng.uniform(0, 2 * np.pi)
        R = np.array([[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 1]])
        shift = np.r_[rng.normal(size=2), 0.0]
        a, b, c = (R @ p + shift for p in np.array([[0, 0, 0], [1.3, 0, 0], [0.2, 0.9, 0]]))
        x = rng.normal(size=3)
        gap, _, normal, jac = triangle(x, a, b, c)
        g_gap, g_jac, g_normal, _ = K.ground_3d(x, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        assert gap == pytest.approx(g_gap[0], abs=1e-14)
        np.testing.assert_allclose(normal, g_normal, atol=1e-15)
        np.testing.assert_allclose(jac[:3], g_jac[0], atol=1e-15)


def _central_difference(f, z, h=1e-6):
    z = np.asarray(z, float)
    grad = np.empty_like(z)
    for k in range(len(z)):
        up, down = z.copy(), z.copy()
        up[k] += h
        down[k] -= h
        grad[k] = (f(up) - f(down)) / (2 * h)
    return grad


def test_gap_jacobians_equal_central_differences_and_the_closed_form(rng):
    """d gap / d[x, vertices] is [n, -w_1 n, -w_2 n, ...] (w: the projection's weights) and
    matches central differences of the gap."""
    for _ in range(20):
        x, a, b = rng.normal(size=(3, 2))
        _, s, n, jac = segment(x, a, b)
        np.testing.assert_allclose(jac, np.concatenate([n, -(1 - s) * n, -s * n]), atol=1e-12)
        fd = _central_difference(lambda z: segment(z[:2], z[2:4], z[4:])[0], np.concatenate([x, a, b]))
        np.testing.assert_allclose(jac, fd, atol=1e-8)
        x, a, b, c = random_triangle(rng)
        _, bary, n, jac = triangle(x, a, b, c)
        np.testing.assert_allclose(jac, np.concatenate([n, *(-w * n for w in bary)]), atol=1e-12)
        fd = _central_difference(lambda z: triangle(z[:3], z[3:6], z[6:9], z[9:])[0], np.concatenate([x, a, b, c]))
        np.testing.assert_allclose(jac, fd, atol=1e-8)


def test_kernels_equal_their_sympy_expressions(rng):
    """The generated NumPy kernels evaluate the SymPy outputs of derivation.elements."""
    pytest.importorskip("sympy")
    from derivation.elements import _surface_kernels

    kernels = {k.name: k for d in (2, 3) for k in _surface_kernels(d)}
    assert set(kernels) == {"segment_2d", "segment_2d_velocity", "triangle_3d", "triangle_3d_velocity",
                            "triangle_3d_slip"}
    for name, kernel in kernels.items():
        values = {arg: rng.normal(size=len(symbols)) for arg, symbols in kernel.inputs}
        if name.startswith("triangle"):
            values["x"], values["a"], values["b"], values["c"] = random_triangle(rng)
        outputs = getattr(K, name)(*values.values())
        subs = {s: values[arg][i] for arg, symbols in kernel.inputs for i, s in enumerate(symbols)}
        for (out, matrix), got in zip(kernel.outputs.items(), outputs):
            expected = np.array(matrix.xreplace(subs).evalf(20), dtype=float).ravel()
            np.testing.assert_allclose(np.ravel(got), expected, rtol=1e-12, atol=1e-13, err_msg=f"{name}.{out}")


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_c_kernels_equal_numpy_kernels(rng):
    """The batched C surface kernels and their NumPy twins agree on random elements."""
    from flexbody import runtime

    lib, m = runtime.library(), 9
    manifest = {"segment_2d": [("x", 2), ("a", 2), ("b", 2)],
                "triangle_3d": [("x", 3), ("a", 3), ("b", 3), ("c", 3)]}
    kernels = json.loads((kernels_dir() / "manifest.json").read_text())["kernels"]
    outputs = {name: [int(np.prod(shape)) for shape in kernels[name]["outputs"].values()]
               for name in ("segment_2d", "segment_2d_velocity", "triangle_3d", "triangle_3d_velocity")}
    assert outputs["segment_2d_velocity"] == [1, 2, 1, 1, 1] and outputs["triangle_3d"] == [1, 3, 3, 12]
    for base, positions in manifest.items():
        d = positions[0][1]
        for name, inputs in ((base, positions),
                             (f"{base}_velocity", positions + [(f"v{p}", d) for p, _ in positions])):
            args = [rng.normal(size=(m, size)) for _, size in inputs]
            outs = [np.empty((m, size)) for size in outputs[name]]
            fn = getattr(lib, f"fb_kb_{name}")
            fn.argtypes = [ctypes.c_long] + [ctypes.c_void_p] * (len(args) + len(outs))
            fn(m, *(z.ctypes.data for z in args + outs))
            expected = getattr(K, name)(*(z.T for z in args))
            for got, want in zip(outs, expected):
                np.testing.assert_allclose(got, np.reshape(want, (len(got[0]), m)).T, rtol=1e-13, atol=1e-14)


def test_gap_rate_is_the_time_derivative_of_the_gap(rng):
    """Along a random motion of the particle and the element's vertices, the gap rate equals
    the central difference of the gap, and ``J a + gap_bias`` its second difference; the tangential velocity is the relative velocity of x
    and the material point under it, less its normal part (which is the gap rate); the slip
    rates are its components along the tangents (2D: t = (-n_y, n_x); 3D: t1 along a -> b,
    t2 = n x t1), and ``J_t a + slip_bias`` the slip rates' derivatives."""
    for _ in range(20):
        for d, corners in ((2, 2), (3, 3)):
            if d == 2:
                q0 = rng.normal(size=(3, 2))
            else:
                q0 = np.array(random_triangle(rng))
            v = rng.normal(size=q0.shape)
            acc = rng.normal(size=q0.shape)  # curved paths: the rate is not a secant by accident

            def gap(t, q0=q0, v=v, acc=acc, d=d):
                q = q0 + v * t + acc * t**2 / 2
                return (segment(*q) if d == 2 else triangle(*q))[0]

            kernel = K.segment_2d_velocity if d == 2 else K.triangle_3d_velocity
            rate, tangential, bias, *slip = kernel(*q0, *v)
            h = 1e-5
            assert rate[0] == pytest.approx((gap(h) - gap(-h)) / (2 * h), rel=1e-7, abs=1e-9)
            # The gap's acceleration is J a + bias (what a held contact between bodies keeps at 0).
            jacobian = (segment(*q0) if d == 2 else triangle(*q0))[3]
            h = 1e-4
            second = (gap(h) - 2 * gap(0.0) + gap(-h)) / h**2
            assert jacobian @ acc.ravel() + bias[0] == pytest.approx(second, rel=1e-6, abs=1e-6)
            _, w, n, _ = segment(*q0) if d == 2 else triangle(*q0)
            weights = [1 - w, w] if d == 2 else w
            relative = v[0] - sum(wk * vk for wk, vk in zip(weights, v[1:]))
            assert rate[0] == pytest.approx(relative @ n, rel=1e-12, abs=1e-12)
            np.testing.assert_allclose(tangential, relative - (relative @ n) * n, atol=1e-12)
            assert abs(tangential @ n) < 1e-12
            # the slip rates along the element's tangents, and their accelerations J_t a + slip_bias
            if d == 2:
                axes = [np.array([-n[1], n[0]])]
                slip_kernel, first = K.segment_2d_velocity, 3
            else:
                t1 = (q0[2] - q0[1]) / np.linalg.norm(q0[2] - q0[1])
                axes = [t1, np.cross(n, t1)]
                slip_kernel, first = K.triangle_3d_slip, 0
                slip = K.triangle_3d_slip(*q0, *v)
            rate_t, bias_t = slip[:2]
            if d == 3:  # the tangents the kernel gives the rows are these
                np.testing.assert_allclose(np.reshape(slip[2], (2, 3)), axes, rtol=0, atol=1e-14)
            for i, t_axis in enumerate(axes):
                assert abs(t_axis @ n) < 1e-12 and t_axis @ t_axis == pytest.approx(1.0, rel=1e-14)
                assert rate_t[i] == pytest.approx(relative @ t_axis, rel=1e-12, abs=1e-12)

                def slip_rate(t, q0=q0, v=v, acc=acc, i=i, slip_kernel=slip_kernel, first=first):
                    q, qd = q0 + v * t + acc * t**2 / 2, v + acc * t
                    return slip_kernel(*q, *qd)[first][i]

                jacobian_t = np.concatenate([t_axis] + [-wk * t_axis for wk in weights])
                h = 1e-5
                derivative = (slip_rate(h) - slip_rate(-h)) / (2 * h)
                assert jacobian_t @ acc.ravel() + bias_t[i] == pytest.approx(derivative, rel=1e-6, abs=1e-6)


def _moment(r, f):
    return r[0] * f[1] - r[1] * f[0] if len(r) == 2 else np.cross(r, f)


def test_element_contact_forces_balance(rng):
    """A contact force lam J^T (on x: lam n; on each vertex: -w lam n) with the projection
    inside the element has zero resultant and zero moment about any point."""
    checked = 0
    while checked < 40:
        d = 2 if checked % 2 == 0 else 3
        q = rng.normal(size=(3, 2)) if d == 2 else np.array(random_triangle(rng))
        _, w, _, jac = segment(*q) if d == 2 else triangle(*q)
        weights = np.atleast_1d(w) if d == 3 else np.array([1 - w, w])
        if not np.all((weights > 0) & (weights < 1)):
            continue
        checked += 1
        lam = rng.uniform(0.1, 10.0)
        forces = lam * jac.reshape(-1, d)  # one row per point: x, then the vertices
        np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-12)
        pivot = rng.normal(size=d)
        total = sum(_moment(p - pivot, f) for p, f in zip(q, forces))
        np.testing.assert_allclose(total, 0.0, atol=1e-12)


def regular_polygon(count: int, radius: float = 1.0):
    """A counter-clockwise regular polygon: vertices (count, 2) and segments (count, 2)."""
    angle = 2 * np.pi * np.arange(count) / count + 0.1
    vertices = radius * np.column_stack([np.cos(angle), np.sin(angle)])
    return vertices, np.column_stack([np.arange(count), (np.arange(count) + 1) % count])


def offset_path(vertices: np.ndarray, gap: float, per_side: int):
    """Points at distance ``gap`` outside a convex counter-clockwise polygon: along each side,
    then around its end vertex on an arc.  Returns the points and the expected feature
    (FACE, segment k) or (VERTEX, vertex k) of each."""
    points, truth = [], []
    count = len(vertices)
    for k in range(count):
        a, b = vertices[k], vertices[(k + 1) % count]
        t = (b - a) / np.linalg.norm(b - a)
        n = np.array([t[1], -t[0]])
        for u in np.linspace(0, 1, per_side, endpoint=False)[1:]:
            points.append(a + u * (b - a) + gap * n)
            truth.append((FACE, k))
        c = vertices[(k + 2) % count]
        t2 = (c - b) / np.linalg.norm(c - b)
        n2 = np.array([t2[1], -t2[0]])
        start, stop = np.arctan2(n[1], n[0]), np.arctan2(n2[1], n2[0])
        stop += 2 * np.pi if stop < start else 0.0
        for phi in np.linspace(start, stop, per_side // 4 + 2)[1:-1]:
            points.append(b + gap * np.array([np.cos(phi), np.sin(phi)]))
            truth.append((VERTEX, (k + 1) % count))
    return np.array(points), truth


def test_a_particle_going_around_a_convex_polygon_is_handed_over_from_side_to_vertex_to_side():
    """At a constant small gap around a hexagon, each point has exactly one feature, the
    expected one (a side while its projection is on it, else the vertex), at the same gap,
    and the features follow each other around the polygon without a gap or a repeat."""
    vertices, segments = regular_polygon(6)
    gap = 1e-3
    points, truth = offset_path(vertices, gap, per_side=200)
    found = closest_features(points, vertices, segments)
    np.testing.assert_array_equal(found.particle, np.arange(len(points)))  # one answer per point
    np.testing.assert_allclose(found.gap, gap, rtol=1e-9)
    for k, (kind, index) in enumerate(truth):
        assert found.kind[k] == kind
        assert (found.element[k] if kind == FACE else found.feature[k, 0]) == index
    # The kernels agree: on a face, s is in [0, 1]; at a vertex both of its sides have s outside.
    faces = found.kind == FACE
    _, s, _, _ = K.segment_2d(points[faces].T, *(vertices[segments[found.element[faces], k]].T for k in range(2)))
    assert np.all((s >= 0) & (s <= 1))
    at = found.kind == VERTEX
    v = found.feature[at, 0]
    _, s_before, _, _ = K.segment_2d(points[at].T, vertices[(v - 1) % 6].T, vertices[v].T)
    _, s_after, _, _ = K.segment_2d(points[at].T, vertices[v].T, vertices[(v + 1) % 6].T)
    assert np.all(s_before > 1) and np.all(s_after < 0)
    # Handed over in order: face 0, vertex 1, face 1, vertex 2, ... each feature one run.
    keys = [(int(kd), int(found.element[i] if kd == FACE else found.feature[i, 0])) for i, kd in enumerate(found.kind)]
    runs = [key for i, key in enumerate(keys) if i == 0 or key != keys[i - 1]]
    assert runs == [(FACE, k // 2) if k % 2 == 0 else (VERTEX, (k // 2 + 1) % 6) for k in range(12)]
    # The normal is continuous too: consecutive points' normals turn by little.
    assert np.min(np.einsum("ij,ij->i", found.normal[1:], found.normal[:-1])) > np.cos(0.1)


def _inside_polygon(points, vertices):
    """Even-odd ray casting (the test's own point-in-polygon)."""
    inside = np.zeros(len(points), bool)
    for a, b in zip(vertices, np.roll(vertices, -1, axis=0)):
        crosses = (a[1] > points[:, 1]) != (b[1] > points[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            x_at = a[0] + (points[:, 1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
        inside ^= crosses & (points[:, 0] < x_at)
    return inside


def test_signed_gap_to_a_concave_polygon_matches_an_independent_reference(rng):
    """Near a concave (star) polygon, the gap's sign is point-in-polygon's and its size the
    distance to a fine sampling of the boundary, also at reflex vertices."""
    vertices, segments = star()
    points = rng.uniform(-1.2, 1.2, size=(400, 2))
    found = closest_features(points, vertices, segments)
    inside = _inside_polygon(points, vertices)
    np.testing.assert_array_equal(found.gap < 0, inside)
    u = np.linspace(0, 1, 2001)
    boundary = np.concatenate([a + u[:, None] * (b - a) for a, b in zip(vertices, np.roll(vertices, -1, axis=0))])
    reference = np.array([np.min(np.linalg.norm(boundary - p, axis=1)) for p in points])
    spacing = np.max(np.linalg.norm(np.roll(vertices, -1, axis=0) - vertices, axis=1)) / 2000
    assert np.all(np.abs(np.abs(found.gap) - reference) <= spacing)
    assert np.all(np.abs(found.gap) <= reference + 1e-15)  # never farther than a boundary point
    # The gap's gradient is its normal: central differences of the surface gap.
    for k in range(0, 400, 40):
        fd = _central_difference(lambda z: closest_features(z[None], vertices, segments).gap[0], points[k])
        np.testing.assert_allclose(found.normal[k], fd, atol=1e-6)


def cube():
    """The unit cube's 12 triangles, counter-clockwise seen from outside."""
    from scipy.spatial import ConvexHull

    vertices = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    triangles = ConvexHull(vertices).simplices.copy()
    inward = np.einsum("ij,ij->i", triangle_normals(vertices, triangles), vertices[triangles].mean(1) - 0.5) < 0
    triangles[inward] = triangles[inward][:, ::-1]
    return vertices, triangles


def test_a_particle_going_over_a_cubes_edge_is_handed_over_face_edge_face():
    """Over the edge x = 1, z = 1 of the unit cube at a constant gap: the top face, then the
    edge (on the arc), then the side face; one feature each, the same gap throughout."""
    vertices, triangles = cube()
    gap = 1e-3
    phi = np.linspace(0, np.pi / 2, 101)
    arc = np.column_stack([1 + gap * np.sin(phi), np.full_like(phi, 0.37), 1 + gap * np.cos(phi)])
    top = np.column_stack([np.linspace(0.5, 1, 50, endpoint=False), np.full(50, 0.37), np.full(50, 1 + gap)])
    side = np.column_stack([np.full(50, 1 + gap), np.full(50, 0.37), np.linspace(1, 0.5, 51)[1:]])
    points = np.vstack([top, arc[1:-1], side])
    found = closest_features(points, vertices, triangles)
    np.testing.assert_array_equal(found.particle, np.arange(len(points)))
    np.testing.assert_allclose(found.gap, gap, rtol=1e-9)
    np.testing.assert_array_equal(found.kind, [FACE] * 50 + [EDGE] * 99 + [FACE] * 50)
    edge = found.feature[found.kind == EDGE]
    np.testing.assert_array_equal(edge[:, :2], [[5, 7]] * 99)  # vertices (1, 0, 1) and (1, 1, 1)
    np.testing.assert_allclose(found.weights[found.kind == EDGE][:, 1], 0.37, atol=1e-12)
    np.testing.assert_allclose(found.normal[:50], [[0, 0, 1]] * 50, atol=1e-15)
    np.testing.assert_allclose(found.normal[-50:], [[1, 0, 0]] * 50, atol=1e-15)


def test_signed_gap_to_a_cube_matches_its_closed_form(rng):
    """Inside the cube the gap is minus the distance to the nearest face; outside it is the
    distance to the clamped point; features: faces, edges and vertices as the regions say."""
    vertices, triangles = cube()
    points = rng.uniform(-0.5, 1.5, size=(500, 3))
    found = closest_features(points, vertices, triangles)
    clamped = np.clip(points, 0, 1)
    outside = np.any(points != clamped, axis=1)
    expected = np.where(outside, np.linalg.norm(points - clamped, axis=1),
                        -np.min(np.minimum(points, 1 - points), axis=1))
    np.testing.assert_allclose(found.gap, expected, atol=1e-14)
    out_axes = np.sum(points != clamped, axis=1)  # 1: a face's region, 2: an edge's, 3: a vertex's
    np.testing.assert_array_equal(found.kind[outside], np.array([FACE, EDGE, VERTEX])[out_axes[outside] - 1])


def test_point_edge_distance_and_gradient(rng):
    for _ in range(10):
        x, a, b = rng.normal(size=(3, 1, 3))
        dist, _, direction = point_edge(x, a, b)
        samples = a + np.linspace(0, 1, 100001)[:, None] * (b - a)
        assert dist[0] == pytest.approx(np.min(np.linalg.norm(samples - x, axis=1)), abs=1e-4)
        fd = _central_difference(lambda z, a=a, b=b: point_edge(z[None], a, b)[0][0], x[0])
        np.testing.assert_allclose(direction[0], fd, atol=1e-7)


def star():
    """A concave, counter-clockwise 10-pointed star: vertices (10, 2) and segments (10, 2)."""
    angle = 2 * np.pi * np.arange(10) / 10
    radius = np.where(np.arange(10) % 2 == 0, 1.0, 0.45)
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)]), \
        np.column_stack([np.arange(10), (np.arange(10) + 1) % 10])


@pytest.mark.parametrize("dim", [2, 3])
def test_feature_gaps_jacobian_is_their_derivative_in_every_coordinate_and_balances(rng, dim):
    """Two bodies' particles in one array: a star (2D) or a cube (3D) whose corners are the
    surface vertices, and particles near it.  The sparse gap Jacobian (normal on x,
    -w normal on the feature's vertices) equals central differences of the surface gap in
    every coordinate, for faces, edges and vertices; its forces sum to zero with zero moment."""
    from flexbody.surface_contact import jacobian_entries

    corners, elements = star() if dim == 2 else cube()
    near = rng.uniform(-1.2, 1.2, size=(60, 2)) if dim == 2 else rng.uniform(-0.4, 1.4, size=(60, 3))
    x = np.vstack([corners, near])  # the first particles are the surface's, then the other body's
    pairs = np.indices((60, len(elements))).reshape(2, -1).T + [len(corners), 0]
    found = closest_features(x, x, elements, pairs)
    assert set(found.kind) == ({FACE, VERTEX} if dim == 2 else {FACE, EDGE, VERTEX})
    rows, cols, vals = jacobian_entries(found, dim)
    J = np.zeros((len(found.gap), x.size))
    np.add.at(J, (rows, cols), vals)

    def gaps(z):
        return closest_features(z.reshape(-1, dim), z.reshape(-1, dim), elements, pairs).gap

    h = 1e-7
    fd = np.empty_like(J)
    for c in range(x.size):
        up, down = x.ravel().copy(), x.ravel().copy()
        up[c] += h
        down[c] -= h
        fd[:, c] = (gaps(up) - gaps(down)) / (2 * h)
    np.testing.assert_allclose(J, fd, atol=1e-6)
    for r in range(len(found.gap)):
        forces = J[r].reshape(-1, dim)  # lam = 1
        np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-14)
        arm = x - rng.normal(size=dim)
        moment = arm[:, 0] * forces[:, 1] - arm[:, 1] * forces[:, 0] if dim == 2 else np.cross(arm, forces)
        np.testing.assert_allclose(moment.sum(axis=0), 0.0, atol=1e-12)


def square():
    """The unit square, counter-clockwise."""
    vertices = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return vertices, np.array([[0, 1], [1, 2], [2, 3], [3, 0]])


def test_passing_beside_a_segments_end_is_no_contact():
    """A particle falling past the square's right side, 1 mm outside it: the top segment's
    line gap changes sign (its line reaches beyond its end), the surface gap never does: it
    goes from the corner (vertex) to the right side (face) at 1 mm."""
    vertices, segments = square()
    heights = np.linspace(1.5, 0.5, 201)
    points = np.column_stack([np.full_like(heights, 1.001), heights])
    line_gap, s, _, _ = K.segment_2d(points.T, vertices[2].T[:, None], vertices[3].T[:, None])
    assert line_gap[0].min() < 0 < line_gap[0].max() and np.all(s[0] < 0)  # beside the top side's end
    found = closest_features(points, vertices, segments)
    assert np.all(found.gap > 0)
    np.testing.assert_allclose(found.gap[heights <= 1.0], 0.001, rtol=1e-9)
    kinds = found.kind[heights > 1.0]
    assert set(kinds) == {VERTEX} and np.all(found.kind[heights <= 1.0] == FACE)


@pytest.mark.parametrize("target", ["vertex", "face"])
def test_contact_onset_is_a_sign_change_of_the_surface_gap_located_exactly(target):
    """The signed surface gap is continuous through hand-overs and changes sign where a
    particle reaches the surface, at a vertex too (the pseudo-normal signs it): root finding
    on it gives the hit time of the closed form.  The square moves and turns meanwhile."""
    from scipy.optimize import brentq

    vertices, segments = square()
    omega, drift = 0.7, np.array([0.3, -0.2])

    def square_at(t):
        c, s = np.cos(omega * t), np.sin(omega * t)
        return (vertices - 0.5) @ np.array([[c, s], [-s, c]]) + 0.5 + drift * t

    # The particle moves with the square's motion plus a closing speed toward the point it hits,
    # so in the square's frame it travels straight in; the hit is at t = 1.
    aim = np.array([1.0, 1.0]) if target == "vertex" else np.array([1.0, 0.4])
    start = aim + (np.array([0.6, 0.8]) if target == "vertex" else np.array([0.5, 0.0]))

    def particle_at(t):
        in_frame = start + (aim - start) * t
        c, s = np.cos(omega * t), np.sin(omega * t)
        return (in_frame - 0.5) @ np.array([[c, s], [-s, c]]) + 0.5 + drift * t

    def gap(t):
        return closest_features(particle_at(t)[None], square_at(t), segments).gap[0]

    assert gap(0.0) > 0 > gap(1.2)
    hit = brentq(gap, 0.0, 1.2, xtol=1e-14)
    assert hit == pytest.approx(1.0, abs=1e-12)
    before = closest_features(particle_at(hit - 1e-6)[None], square_at(hit - 1e-6), segments)
    assert before.kind[0] == (VERTEX if target == "vertex" else FACE)


def test_a_particle_wedged_between_two_bodies_gets_one_contact_on_each():
    """Two unit squares side by side 2 mm apart and a particle between them: with the bodies
    named, one feature on each (the facing sides, 1 mm); without, the nearer one only."""
    vertices, segments = square()
    both = np.vstack([vertices, vertices + [1.002, 0.0]])
    elements = np.vstack([segments, segments + 4])
    body = np.repeat([0, 1], 4)
    x = np.array([[1.001, 0.5], [1.0015, 0.5]])
    found = closest_features(x, both, elements, element_body=body)
    np.testing.assert_array_equal(found.particle, [0, 0, 1, 1])
    np.testing.assert_array_equal(found.element, [1, 7, 1, 7])  # the right side of 0, the left side of 1
    np.testing.assert_allclose(found.gap, [0.001, 0.001, 0.0015, 0.0005], rtol=1e-9)
    np.testing.assert_allclose(found.normal, [[1, 0], [-1, 0], [1, 0], [-1, 0]], atol=1e-15)
    one = closest_features(x, both, elements)
    np.testing.assert_array_equal(one.particle, [0, 1])
    np.testing.assert_allclose(one.gap, [0.001, 0.0005], rtol=1e-9)
    assert len(closest_features(x, both, elements, pairs=np.zeros((0, 2), int)).gap) == 0


def _sphere_hull(rng, count=40):
    """A random convex polyhedron: its vertices (count, 3) and outward triangles."""
    from scipy.spatial import ConvexHull

    vertices = rng.normal(size=(count, 3))
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    triangles = ConvexHull(vertices).simplices.copy()
    inward = np.einsum("ij,ij->i", triangle_normals(vertices, triangles), vertices[triangles].mean(1)) < 0
    triangles[inward] = triangles[inward][:, ::-1]
    return vertices, triangles


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
@pytest.mark.parametrize("surface", ["star", "cube", "hull", "two squares"])
def test_compiled_closest_features_equal_the_numpy_twin(rng, surface):
    """fb_closest_features (C) gives closest_features' answer: the same particles, feature
    kinds and features (faces, edges and vertices all occur), the same element where the
    feature is a face (an edge or vertex is shared: either element is right), and gaps,
    weights and normals to rounding; over all pairs, a random subset of them, and none
    (grouped by particle, as the broad phase hands them, each group put in order alone), and
    all of them shuffled (sorted whole)."""
    from flexbody.surface_contact import CompiledClosestFeatures

    body = None
    if surface == "star":
        vertices, elements = star()
    elif surface == "cube":
        vertices, elements = cube()
    elif surface == "hull":
        vertices, elements = _sphere_hull(rng)
    else:
        square_vertices, segments = square()
        vertices = np.vstack([square_vertices, square_vertices + [1.002, 0.0]])
        elements, body = np.vstack([segments, segments + 4]), np.repeat([0, 1], 4)
    dim = vertices.shape[1]
    points = vertices.mean(axis=0) + rng.uniform(-1.3, 1.3, size=(300, dim))
    compiled = CompiledClosestFeatures(elements, len(vertices), body)
    every = np.indices((len(points), len(elements))).reshape(2, -1).T
    some = every[rng.random(len(every)) < 0.3]
    for pairs in (every, some, every[:0], every[rng.permutation(len(every))]):
        reference = closest_features(points, vertices, elements, pairs, body)
        found = compiled(points, vertices, pairs)
        for field in ("particle", "kind", "feature"):
            np.testing.assert_array_equal(getattr(found, field), getattr(reference, field), err_msg=field)
        face = reference.kind == FACE
        np.testing.assert_array_equal(found.element[face], reference.element[face])
        for field in ("gap", "weights", "normal"):
            np.testing.assert_allclose(getattr(found, field), getattr(reference, field), rtol=0, atol=1e-14,
                                       err_msg=field)
    kinds = set(closest_features(points, vertices, elements, every, body).kind.tolist())
    assert kinds == ({FACE, VERTEX} if dim == 2 else {FACE, EDGE, VERTEX})


@pytest.mark.skipif(not HAS_CC, reason="needs a C compiler")
@pytest.mark.parametrize("dim", [2, 3])
def test_the_c_narrow_phase_boxes_kept_pairs_as_the_broad_phase_does(dim):
    """fb_closest_features over every kept pair with ``reach`` = the margin answers as over
    the broad phase's filtered pairs (CandidateList.pairs), along a motion that rebuilds."""
    from flexbody.broadphase import CandidateList
    from flexbody.surface_contact import CompiledClosestFeatures

    from .test_broadphase import random_bodies

    rng = np.random.default_rng(11 + dim)
    x, elements, body = random_bodies(rng, dim, bodies=5)
    element_body = body[elements[:, 0]]
    narrow = CompiledClosestFeatures(elements, len(x), element_body)
    kept = CandidateList(elements, body, margin=0.05, skin=0.05, element_body=element_body)
    drift = -0.5 * (x - x.mean(axis=0))
    checked = boxed_out = 0
    for k in range(60):
        now = x + drift * k * 5e-3
        everything, filtered = kept.all_kept(now), kept.pairs(now)
        boxed_out += len(everything) - len(filtered)
        boxed, reference = narrow(now, now, everything, reach=kept.margin), narrow(now, now, filtered)
        for name in ("particle", "kind", "element", "feature", "weights", "gap", "normal"):
            np.testing.assert_array_equal(getattr(boxed, name), getattr(reference, name), err_msg=f"{name}, step {k}")
        checked += len(reference.particle)
    assert checked > 0 and boxed_out > 0 and kept.rebuilds >= 2


def test_the_fast_cross_product_is_numpys_bit_for_bit():
    """``flexbody.surface.cross``, which event location calls instead of ``np.cross`` (its
    set-up costs more than the product on a few rows), gives the same bits: rows, stacks
    and broadcasting, with values whose products round (so another order would differ)."""
    from flexbody.surface import cross

    rng = np.random.default_rng(5)
    for a_shape, b_shape in (((1, 3), (1, 3)), ((7, 3), (7, 3)), ((4, 2, 3), (4, 2, 3)), ((5, 6, 3), (5, 1, 3))):
        a, b = rng.normal(size=a_shape) * 1e3, rng.normal(size=b_shape) * 1e-3
        got, expected = cross(a, b), np.cross(a, b)
        assert got.shape == expected.shape
        np.testing.assert_array_equal(got, expected)
    # each component is one product less the other (not a fused or reordered sum)
    a, b = np.array([[1.0 + 2**-52, 3.0, 1e16]]), np.array([[1e16, 1.0 - 2**-53, 7.0]])
    np.testing.assert_array_equal(cross(a, b), [[3.0 * 7.0 - 1e16 * (1.0 - 2**-53), 1e16 * 1e16 - (1.0 + 2**-52) * 7.0,
                                                (1.0 + 2**-52) * (1.0 - 2**-53) - 3.0 * 1e16]])
