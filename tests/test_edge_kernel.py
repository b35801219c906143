"""The edge-against-edge kernels of 3D bodies (``edge_3d``, ``edge_3d_velocity``, ``edge_3d_slip``).

References: closed forms (two crossed edges a known distance apart, the closest points of
two lines from their own minimisation), central differences of the gap (the Jacobian and
the gap rate, its second difference for the velocity term), the SymPy expressions the
kernels are generated from, and the C kernels against their NumPy twins.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from flexbody.assembly import _kernels_module

from .conftest import HAS_CC
from .test_narrowphase import _central_difference

K = _kernels_module()


def edge(a, b, c, d, side=1.0):
    """``edge_3d`` on one pair of edges: gap, (s, t), normal (3,), Jacobian (12,)."""
    gap, parameters, normal, jacobian = K.edge_3d(a, b, c, d, np.array([side]))
    return gap[0], parameters, normal, np.ravel(jacobian)


def test_two_crossed_edges_a_height_apart_have_that_gap_at_their_crossing():
    """An edge along x at height h above an edge along y: the gap is h with n = +z (the
    side that puts the first edge outside), -h the other way, and the closest points are
    where their projections cross (s = 1/4, t = 3/5)."""
    h = 0.037
    a, b = np.array([-0.25, 0.0, h]), np.array([0.75, 0.0, h])  # crosses x = 0 at s = 1/4
    c, d = np.array([0.0, -0.6, 0.0]), np.array([0.0, 0.4, 0.0])  # crosses y = 0 at t = 3/5
    # (b - a) x (d - c) = x x y = +z
    gap, (s, t), n, _ = edge(a, b, c, d, side=1.0)
    assert gap == pytest.approx(h, rel=1e-14) and s == pytest.approx(0.25) and t == pytest.approx(0.6)
    np.testing.assert_allclose(n, [0.0, 0.0, 1.0], atol=1e-15)
    gap, _, n, _ = edge(a, b, c, d, side=-1.0)
    assert gap == pytest.approx(-h, rel=1e-14)
    np.testing.assert_allclose(n, [0.0, 0.0, -1.0], atol=1e-15)
    # moved down through the other edge, the gap changes sign: the crossing
    assert edge(a - [0, 0, 2 * h], b - [0, 0, 2 * h], c, d)[0] == pytest.approx(-h, rel=1e-13)


def test_parameters_are_the_closest_points_and_the_gap_their_signed_distance(rng):
    """s and t minimise |p(s) - r(t)| (the normal equations hold), and |gap| is that least
    distance with p - r = gap n: the gap is the lines' signed distance."""
    for _ in range(50):
        a, b, c, d = rng.normal(size=(4, 3))
        gap, (s, t), n, _ = edge(a, b, c, d)
        p, r = a + s * (b - a), c + t * (d - c)
        assert abs((p - r) @ (b - a)) < 1e-12 and abs((p - r) @ (d - c)) < 1e-12
        np.testing.assert_allclose(p - r, gap * n, atol=1e-12)
        assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-14)
        # no other pair of points of the lines is closer
        for ds, dt in rng.normal(scale=0.1, size=(5, 2)):
            assert np.linalg.norm(a + (s + ds) * (b - a) - c - (t + dt) * (d - c)) >= abs(gap) - 1e-12


def test_the_jacobian_is_the_weights_times_n_and_the_gaps_derivative(rng):
    """d gap / d[a, b, c, d] = [(1 - s) n, s n, -(1 - t) n, -t n], equal to central
    differences; its forces balance in force and moment about any point."""
    for _ in range(20):
        a, b, c, d = rng.normal(size=(4, 3))
        for side in (1.0, -1.0):
            _, (s, t), n, jac = edge(a, b, c, d, side)
            np.testing.assert_allclose(jac, np.concatenate([(1 - s) * n, s * n, -(1 - t) * n, -t * n]), atol=1e-12)
            fd = _central_difference(lambda z, side=side: edge(*z.reshape(4, 3), side)[0], np.concatenate([a, b, c, d]))
            np.testing.assert_allclose(jac, fd, atol=1e-7)
            forces = jac.reshape(4, 3)
            np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-12)
            moment = sum(np.cross(x, f) for x, f in zip((a, b, c, d), forces))
            np.testing.assert_allclose(moment, 0.0, atol=1e-11)


def test_gap_rate_and_bias_are_the_gaps_time_derivatives(rng):
    """Along a curved random motion of the four ends, the gap rate is the gap's central
    difference and ``J a + gap_bias`` its second difference; the tangential velocity is
    the closest points' relative velocity less its normal part (the gap rate)."""
    for _ in range(20):
        q0, v, acc = rng.normal(size=(3, 4, 3))
        side = np.array([1.0])

        def gap(t, q0=q0, v=v, acc=acc):
            return edge(*(q0 + v * t + acc * t**2 / 2))[0]

        rate, tangential, bias = K.edge_3d_velocity(*q0, side, *v)
        h = 1e-5
        assert rate[0] == pytest.approx((gap(h) - gap(-h)) / (2 * h), rel=1e-7, abs=1e-9)
        _, (s, t), n, jac = edge(*q0)
        h = 1e-4
        second = (gap(h) - 2 * gap(0.0) + gap(-h)) / h**2
        assert jac @ acc.ravel() + bias[0] == pytest.approx(second, rel=1e-5, abs=1e-5)
        relative = (1 - s) * v[0] + s * v[1] - (1 - t) * v[2] - t * v[3]
        assert rate[0] == pytest.approx(relative @ n, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(tangential, relative - (relative @ n) * n, atol=1e-12)


def test_slip_rates_are_the_contact_points_relative_velocity_along_the_edges_tangents(rng):
    """``edge_3d_slip``: t1 along a -> b and t2 = n x t1 are orthonormal and normal to n; the
    slip rates are the closest points' relative velocity (material points, s and t held)
    along them; and ``J_t a + slip_bias`` is the time derivative of the slip rates along a
    curved random motion of the ends (central differences)."""
    for _ in range(20):
        q0, v0, acc = rng.normal(size=(3, 4, 3))
        side = np.array([1.0 if rng.random() < 0.5 else -1.0])

        def slip_terms(q, v):  # rates (2,), bias (2,), tangents (6,)
            return tuple(np.ravel(z) for z in K.edge_3d_slip(*q, side, *v))

        def slip(t, q0=q0, v0=v0, acc=acc):
            return slip_terms(q0 + v0 * t + acc * t**2 / 2, v0 + acc * t)[0]

        rate, bias, tangents = slip_terms(q0, v0)
        t1, t2 = np.ravel(tangents)[:3], np.ravel(tangents)[3:]
        _, (s, t), n, _ = edge(*q0, side[0])
        np.testing.assert_allclose(t1, (q0[1] - q0[0]) / np.linalg.norm(q0[1] - q0[0]), atol=1e-12)
        np.testing.assert_allclose(t2, np.cross(n, t1), atol=1e-12)
        assert abs(t1 @ n) < 1e-12 and abs(t2 @ n) < 1e-12
        relative = (1 - s) * v0[0] + s * v0[1] - (1 - t) * v0[2] - t * v0[3]
        np.testing.assert_allclose(rate, [relative @ t1, relative @ t2], rtol=1e-12, atol=1e-12)
        along_acc = slip_terms(q0, acc)[0]  # J_t a: the rates are linear in the velocities
        h = 1e-5
        np.testing.assert_allclose(along_acc + bias, (slip(h) - slip(-h)) / (2 * h), rtol=1e-6, atol=1e-6)


def test_kernels_equal_their_sympy_expressions(rng):
    """The generated NumPy kernels evaluate the SymPy outputs of derivation.elements."""
    pytest.importorskip("sympy")
    from derivation.elements import edge_kernels

    for kernel in edge_kernels():
        values = {arg: rng.normal(size=len(symbols)) for arg, symbols in kernel.inputs}
        values["side"] = np.array([-1.0])
        outputs = getattr(K, kernel.name)(*values.values())
        subs = {s: values[arg][i] for arg, symbols in kernel.inputs for i, s in enumerate(symbols)}
        for (out, matrix), got in zip(kernel.outputs.items(), outputs):
            expected = np.array(matrix.xreplace(subs).evalf(20), dtype=float).ravel()
            np.testing.assert_allclose(np.ravel(got), expected, rtol=1e-12, atol=1e-13,
                                       err_msg=f"{kernel.name}.{out}")


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_c_kernels_equal_numpy_kernels(rng):
    """The batched C edge kernels and their NumPy twins agree on random edge pairs."""
    from flexbody import runtime

    lib, m = runtime.library(), 7
    for name, inputs, widths in (("edge_3d", [3] * 4 + [1], [1, 2, 3, 12]),
                                 ("edge_3d_velocity", [3] * 4 + [1] + [3] * 4, [1, 3, 1]),
                                 ("edge_3d_slip", [3] * 4 + [1] + [3] * 4, [2, 2, 6])):
        args = [rng.normal(size=(m, size)) for size in inputs]
        args[4] = np.where(rng.random((m, 1)) < 0.5, -1.0, 1.0)
        outs = [np.empty((m, w)) for w in widths]
        fn = getattr(lib, f"fb_kb_{name}")
        fn.argtypes = [ctypes.c_long] + [ctypes.c_void_p] * (len(args) + len(outs))
        fn(m, *(z.ctypes.data for z in args + outs))
        expected = getattr(K, name)(*(z.T for z in args))
        for got, want in zip(outs, expected):
            np.testing.assert_allclose(got, np.reshape(want, (got.shape[1], m)).T, rtol=1e-12, atol=1e-13)


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_the_edge_kernels_of_either_backend_give_the_same_arrays(rng):
    """EdgeKernels("c") hands the compiled kernels' outputs back in the NumPy twins' shapes
    (size, k), the Jacobian (1, 12, k), equal to rounding on random edge pairs."""
    from flexbody.edge_contact import EdgeKernels

    m = 9
    ends = [rng.normal(size=(3, m)) for _ in range(4)]
    side = np.where(rng.random((1, m)) < 0.5, -1.0, 1.0)
    rates = [rng.normal(size=(3, m)) for _ in range(4)]
    c, numpy = EdgeKernels("c"), EdgeKernels("numpy")
    for got, want in zip(c.edge_3d(*ends, side) + c.edge_3d_velocity(*ends, side, *rates)
                         + c.edge_3d_slip(*ends, side, *rates),
                         numpy.edge_3d(*ends, side) + numpy.edge_3d_velocity(*ends, side, *rates)
                         + numpy.edge_3d_slip(*ends, side, *rates)):
        assert got.shape == np.shape(want)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-13)
