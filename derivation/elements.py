"""Equations of one element, in frame N, for d = 2 and 3 (build time only, SymPy).

A scene's particles formulation is a sum over elements with a diagonal mass matrix, so
its equations never need to be derived whole: each element is derived once here, the
code generator turns it into a C kernel and a vectorised NumPy twin, and the runtime
assembles them over the scene's index arrays (:mod:`flexbody.assembly`).

Elements
--------
``link`` (one per damper law and dimension)
    A Hooke spring (thesis eq. 3.7) and a damper (``relative``: eq. 3.8; ``axial``: the
    relative velocity's component along the link) between particles i and j.  Its
    generalised forces come from Kane's method on the two particles with the link as
    the only load; the force on j is minus the force on i (checked here).  Also its
    spring energy, damping power and the Jacobian of the force on i with respect to
    ``[x_i, x_j, v_i, v_j]``.
``particle``
    Gravity's force and potential, and the kinetic energy, of a point mass.
``ground``
    A plane ground through ``P`` with unit normal ``n``: the gap ``(x - P) . n``, its
    Jacobian with respect to x, the normal, and an orthonormal tangent basis (in 3D the
    branch-free basis of Duff et al., "Building an orthonormal basis, revisited", 2017).
``split``
    A contact vector w (a velocity, or a force) against a ground's unit normal n: its
    normal component ``w . n``, its tangential part ``w - (w . n) n`` and that part's
    length.  Coulomb friction (DESIGN §6) acts on the tangential part: the impulse at an
    impact, the sticking force and the slip direction.
``segment`` (2D) and ``triangle`` (3D)
    A particle x against a surface element of another body whose vertices move (DESIGN
    §6, several bodies).  Orientation: a 2D body's boundary runs counter-clockwise, so a
    segment a -> b has the outward normal ``n = (b - a) x z / |b - a|``, the right-hand
    perpendicular of b - a; a 3D body's triangles a, b, c run counter-clockwise seen from
    outside, ``n = (b - a) x (c - a) / |(b - a) x (c - a)|``.  The signed gap is
    ``(x - a) . n`` (< 0 inside); the projection's weights are ``[1 - s, s]`` with
    ``s = (x - a) . (b - a) / |b - a|^2`` (segment) or the barycentric coordinates
    (triangle), unclamped: a weight outside [0, 1] means the contact belongs to a
    neighbour or a vertex (:mod:`flexbody.surface_contact`).  The gap's Jacobian with
    respect to every coordinate is ``[n, -w_1 n, -w_2 n, ...]``, so with the weights in
    [0, 1] a contact force ``lam n`` on x comes with ``-w_i lam n`` on the vertices: zero
    net force and moment.  Their ``_velocity`` twins give the gap rate (the Jacobian times
    the velocities), the tangential part of the velocity of x relative to the material
    point of the element under it (for friction), and the gap acceleration's velocity
    term ``d(J v)/dq . v`` that a held contact between bodies needs (:mod:`flexbody.body_contact`);
    and for friction between bodies the slip rates along the element's unit tangents (2D:
    ``t = (-n_y, n_x)``, in ``segment_2d_velocity``; 3D: ``t1 = (b - a) / |b - a|``,
    ``t2 = n x t1``, in ``triangle_3d_slip``) with their accelerations' velocity terms.
``edge`` (3D)
    An edge a -> b of one body against an edge c -> d of another (two meshes crossed edge
    to edge, no vertex on a face): the signed distance ``n . (a - c)`` of their lines along
    their common unit normal ``n = side (b - a) x (d - c) / |...|``, the closest points'
    parameters s, t, and the Jacobian ``[(1 - s) n, s n, -(1 - t) n, -t n]``; its
    ``_velocity`` twin as the surface kernels' (see :func:`edge_kernels`), and its ``_slip``
    twin for friction between the edges, as the triangle's.

Every kernel is a :class:`Kernel`: named inputs (flat arrays of given sizes) and named
outputs (SymPy matrices of those inputs only).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp
from sympy.physics.mechanics import KanesMethod, Particle, Point, ReferenceFrame, dynamicsymbols

DIMENSIONS = (2, 3)
DAMPERS = ("relative", "axial")
AXES = "xyz"


class CopySign1(sp.Function):
    """``copysign(1, x)``: +1 or -1, never 0 (sympy's sign(0) is 0); its derivative is 0."""

    nargs = 1

    def fdiff(self, argindex: int = 1) -> sp.Expr:
        return sp.S.Zero


@dataclass
class Kernel:
    """One generated element function.

    Attributes
    ----------
    name : str
        C name ``fb_k_<name>``, NumPy name ``<name>``.
    doc : str
    inputs : list of (name, symbols)
        Each input is a flat array; ``symbols[i]`` is its entry i.
    outputs : dict of name -> sympy.Matrix
        Each output is written as a flat row-major array.
    """

    name: str
    doc: str
    inputs: list[tuple[str, list[sp.Symbol]]]
    outputs: dict[str, sp.Matrix] = field(default_factory=dict)


def _vector_symbols(name: str, d: int) -> list[sp.Symbol]:
    return [sp.Symbol(f"{name}_{AXES[a]}", real=True) for a in range(d)]


def _frame_vector(N: ReferenceFrame, components) -> object:
    return sum((c * axis for c, axis in zip(components, (N.x, N.y, N.z))), sp.S.Zero * N.x)


def link_kernels(d: int, damper: str) -> list[Kernel]:
    """The link element of dimension ``d`` with the ``damper`` law: force, energy, Jacobian."""
    N = ReferenceFrame("N")
    O = Point("O")
    O.set_vel(N, 0)
    coords = [dynamicsymbols(f"x{p}_{AXES[a]}") for p in "ij" for a in range(d)]
    speeds = [dynamicsymbols(f"v{p}_{AXES[a]}") for p in "ij" for a in range(d)]
    Pi = O.locatenew("Pi", _frame_vector(N, coords[:d]))
    Pj = O.locatenew("Pj", _frame_vector(N, coords[d:]))
    Pi.set_vel(N, _frame_vector(N, speeds[:d]))
    Pj.set_vel(N, _frame_vector(N, speeds[d:]))
    k, c, rest = sp.symbols("k c L", real=True)
    P_ij = Pi.pos_from(Pj)  # thesis eq. 3.7: P_ij = x_i - x_j
    length = sp.sqrt(P_ij.dot(P_ij))
    e = P_ij / length
    dv = Pj.vel(N) - Pi.vel(N)  # V_j - V_i
    if damper == "relative":  # thesis eq. 3.8
        f_damp, power = c * dv, c * dv.dot(dv)
    else:
        f_damp, power = c * dv.dot(e) * e, c * dv.dot(e) ** 2
    f = k * (rest - length) * e + f_damp  # on i; j gets -f
    mass_i, mass_j = sp.symbols("m_i m_j", positive=True)
    kane = KanesMethod(N, q_ind=coords, u_ind=speeds, kd_eqs=[q.diff() - u for q, u in zip(coords, speeds)])
    kane.kanes_equations([Particle("pi", Pi, mass_i), Particle("pj", Pj, mass_j)], [(Pi, f), (Pj, -f)])
    plain = {q: s for q, s in zip(coords, _vector_symbols("xi", d) + _vector_symbols("xj", d))}
    plain |= {u: s for u, s in zip(speeds, _vector_symbols("vi", d) + _vector_symbols("vj", d))}
    generalized = kane.forcing.xreplace(plain)
    force_i, force_j = generalized[:d, 0], generalized[d:, 0]
    if sp.simplify(force_i + force_j) != sp.zeros(d, 1):
        raise AssertionError("the link's forces on i and j are not equal and opposite")
    xi, xj, vi, vj = (_vector_symbols(n, d) for n in ("xi", "xj", "vi", "vj"))
    spring_energy = (k * (length - rest) ** 2 / 2).xreplace(plain)
    params = [k, c, rest]
    inputs = [("xi", xi), ("xj", xj), ("vi", vi), ("vj", vj), ("par", params)]
    tag = f"link_{damper}_{d}d"
    meaning = "relative (thesis eq. 3.8)" if damper == "relative" else "axial"
    return [
        Kernel(f"{tag}_force", f"Force on particle i of a spring (eq. 3.7) and {meaning} damper, and the "
               "damping power (W, >= 0); par = [k, c, L]. The force on j is minus it.", inputs,
               {"force": sp.Matrix(force_i), "power": sp.Matrix([power.xreplace(plain)])}),
        Kernel(f"{tag}_energy", "Spring energy k (|x_i - x_j| - L)^2 / 2 (J); par = [k, c, L].", inputs,
               {"energy": sp.Matrix([spring_energy])}),
        Kernel(f"{tag}_jacobian", "d(force on i) / d[x_i, x_j, v_i, v_j], shape (d, 4d); par = [k, c, L].",
               inputs, {"jacobian": sp.Matrix(force_i).jacobian(xi + xj + vi + vj)}),
    ]


def particle_kernel(d: int) -> Kernel:
    """Gravity force and potential and kinetic energy of one particle of mass m."""
    N = ReferenceFrame("N")
    O = Point("O")
    x, v, g = _vector_symbols("x", d), _vector_symbols("v", d), _vector_symbols("g", d)
    m = sp.Symbol("m", positive=True)
    P = O.locatenew("P", _frame_vector(N, x))
    gravity = m * _frame_vector(N, g)
    velocity = _frame_vector(N, v)
    return Kernel(
        f"particle_{d}d", "Gravity force m g (N), its potential -m g . x and the kinetic energy (J).",
        [("x", x), ("v", v), ("m", [m]), ("g", g)],
        {
            "force": sp.Matrix([gravity.dot(axis) for axis in (N.x, N.y, N.z)[:d]]),
            "potential": sp.Matrix([-gravity.dot(P.pos_from(O))]),
            "kinetic": sp.Matrix([m * velocity.dot(velocity) / 2]),
        },
    )


def _tangents(n: list[sp.Symbol]) -> list[list[sp.Expr]]:
    """An orthonormal tangent basis of the unit normal n (right-handed with n in 3D)."""
    if len(n) == 2:
        return [[-n[1], n[0]]]
    s = CopySign1(n[2])
    a = -1 / (s + n[2])
    b = n[0] * n[1] * a
    return [[1 + s * n[0] ** 2 * a, s * b, -s * n[0]], [b, s + n[1] ** 2 * a, -n[1]]]


def ground_kernel(d: int) -> Kernel:
    """Gap, gap Jacobian, normal and tangent basis of a plane ground (point P, unit normal n)."""
    N = ReferenceFrame("N")
    x, point, n = _vector_symbols("x", d), _vector_symbols("P", d), _vector_symbols("n", d)
    normal = _frame_vector(N, n)
    gap = (_frame_vector(N, x) - _frame_vector(N, point)).dot(normal)
    gap_m = sp.Matrix([gap])
    return Kernel(
        f"ground_{d}d", "Gap (x - P) . n (m, < 0 inside), d gap / dx, the normal and a tangent basis "
        f"(({d - 1}, {d}), orthonormal, rows) of a plane ground with unit normal n.",
        [("x", x), ("P", point), ("n", n)],
        {
            "gap": gap_m,
            "gap_jacobian": gap_m.jacobian(x),
            "normal": sp.Matrix(n),
            "tangents": sp.Matrix(_tangents(n)),
        },
    )


def split_kernel(d: int) -> Kernel:
    """Normal component, tangential part and its length of a vector w against unit normal n."""
    N = ReferenceFrame("N")
    w, n = _vector_symbols("w", d), _vector_symbols("n", d)
    vector, normal = _frame_vector(N, w), _frame_vector(N, n)
    along = vector.dot(normal)
    tangential = vector - along * normal
    components = sp.Matrix([tangential.dot(axis) for axis in (N.x, N.y, N.z)[:d]])
    return Kernel(
        f"split_{d}d", "Normal component w . n, tangential part w - (w . n) n and its length of a vector w "
        "(a velocity or a force) at a ground with unit normal n.",
        [("w", w), ("n", n)],
        {
            "normal": sp.Matrix([along]),
            "tangential": components,
            "tangential_norm": sp.Matrix([sp.sqrt(sum(c**2 for c in components))]),
        },
    )


def _surface_kernels(d: int) -> list[Kernel]:
    """Gap, projection weights, normal and gap Jacobian of a particle against a segment (2D)
    or a triangle (3D) whose vertices move; and their gap rate and tangential velocity."""
    N = ReferenceFrame("N")
    corners = "ab" if d == 2 else "abc"
    x, v = _vector_symbols("x", d), _vector_symbols("v", d)
    X = {c: _vector_symbols(c, d) for c in corners}
    V = {c: _vector_symbols(f"v{c}", d) for c in corners}
    a, b, p = _frame_vector(N, X["a"]), _frame_vector(N, X["b"]), _frame_vector(N, x)
    if d == 2:  # counter-clockwise boundary: the outward normal is the right-hand perpendicular
        outward = (b - a).cross(N.z)
        weights = [1 - (p - a).dot(b - a) / (b - a).dot(b - a)]
        weights.append(1 - weights[0])
    else:  # counter-clockwise seen from outside; barycentrics: signed sub-areas over the whole
        c = _frame_vector(N, X["c"])
        outward = (b - a).cross(c - a)
        area2 = outward.dot(outward)
        weights = [(b - p).cross(c - p).dot(outward) / area2, (c - p).cross(a - p).dot(outward) / area2,
                   (a - p).cross(b - p).dot(outward) / area2]
    normal = outward / sp.sqrt(outward.dot(outward))
    gap = sp.Matrix([(p - a).dot(normal)])
    coordinates = x + [q for c in corners for q in X[c]]
    jacobian = gap.jacobian(coordinates)
    velocities = sp.Matrix(v + [u for c in corners for u in V[c]])
    rate = jacobian * velocities
    # d(gap)/dt = J v, so d2(gap)/dt2 = J a + gap_bias with gap_bias = (d(J v)/d coordinates) v:
    # a held contact keeps its gap's acceleration at 0 with this term (Baumgarte-free).
    material = sum((w * _frame_vector(N, V[c]) for w, c in zip(weights, corners)), 0 * N.x)
    relative = _frame_vector(N, v) - material
    tangential = relative - relative.dot(normal) * normal
    axes = (N.x, N.y, N.z)[:d]
    positions = [("x", x)] + [(c, X[c]) for c in corners]
    if d == 2:
        name, element, projection = "segment_2d", "segment a, b", {"s": sp.Matrix([weights[1]])}
        what = "the closest-point parameter s on the line (0..1 on the segment, unclamped)"
    else:
        name, element, projection = "triangle_3d", "triangle a, b, c", {"barycentric": sp.Matrix(weights)}
        what = "the barycentrics of x's projection (unclamped)"
    velocity_outputs = {"gap_rate": rate,
                        "tangential_velocity": sp.Matrix([tangential.dot(e) for e in axes]),
                        "gap_bias": rate.jacobian(coordinates) * velocities}
    # Coulomb friction between bodies: the slip rates along the element's unit tangents, linear
    # in the velocities with the Jacobian [t, -w_a t, ...], and their accelerations' velocity
    # terms.  2D: t = (-n_y, n_x), in the velocity kernel.  3D: t1 along the edge a -> b and
    # t2 = n x t1 (smooth in the vertices, unlike a basis built from n alone, so their rates
    # are defined everywhere), in a kernel of their own: only friction calls it, and with the
    # velocity kernel's outputs it would cost every frictionless held row half as much again.
    if d == 2:
        tangents = [N.z.cross(normal)]
    else:
        edge = b - a
        tangents = [edge / sp.sqrt(edge.dot(edge))]
        tangents.append(normal.cross(tangents[0]))
    slip = sp.Matrix([relative.dot(t) for t in tangents])
    slip_outputs = {"slip_rate": slip, "slip_bias": slip.jacobian(coordinates) * velocities}
    if d == 2:
        velocity_outputs |= slip_outputs
    else:  # the rows' tangent directions: the runtime takes them from here, not from a twin
        slip_outputs["tangents"] = sp.Matrix([t.dot(e) for t in tangents for e in axes])
    return [
        Kernel(name, f"Particle x against the {element} of another body: signed gap (x - a) . n (m, < 0 "
               f"inside), {what}, the outward unit normal n and d gap / d[x, {', '.join(corners)}].",
               positions,
               {"gap": gap, **projection, "normal": sp.Matrix([normal.dot(e) for e in axes]),
                "gap_jacobian": jacobian}),
        Kernel(f"{name}_velocity", f"Gap rate (m/s) of particle x against the {element}: d gap / dt, the gap "
               "Jacobian times the velocities; the tangential part (m/s) of x's velocity relative to the "
               "element's material point under x; and the gap acceleration's velocity term (m/s^2), "
               "d2 gap / dt2 - J a" + ("; in 2D also the slip rate along t = (-n_y, n_x) (m/s) and its "
                                       "acceleration's velocity term (m/s^2)." if d == 2 else "."),
               positions + [("v", v)] + [(f"v{c}", V[c]) for c in corners],
               velocity_outputs),
    ] + ([] if d == 2 else [
        Kernel(f"{name}_slip", f"Slip rates (m/s) of particle x against the {element}: its velocity relative to "
               "the element's material point under x along the unit tangents t1 = (b - a) / |b - a| and "
               "t2 = n x t1, their accelerations' velocity terms (m/s^2), d2 s / dt2 - J_t a, and t1, t2.",
               positions + [("v", v)] + [(f"v{c}", V[c]) for c in corners],
               slip_outputs),
    ])


def edge_kernels() -> list[Kernel]:
    """Gap, closest-point parameters, normal and gap Jacobian of an edge a -> b of one 3D
    body against an edge c -> d of another, both moving; and their gap rate, tangential
    relative velocity and gap acceleration's velocity term.

    Two triangle meshes also touch edge on edge, with no vertex on a face (two boxes
    crossed edge to edge).  The lines' common normal is ``(b - a) x (d - c)``, made a
    unit vector n and turned by ``side`` (+1 or -1, a constant of the contact: the
    runtime chooses it so that n points out of the second edge's body); the signed gap is
    ``n . (a - c)``, the distance between the lines, the same as ``n . (p - r)`` between
    their closest points ``p = a + s (b - a)`` and ``r = c + t (d - c)`` (s, t unclamped:
    outside [0, 1] the closest points of the edges are an end, a vertex contact's).
    Its Jacobian is ``[(1 - s) n, s n, -(1 - t) n, -t n]`` on ``[a, b, c, d]`` (the
    envelope theorem: the lines' distance is a minimum over s and t, so at its minimiser
    the points' gradients are the weights times n; checked against the gap's own
    derivative in the tests), the form of the element kernels: with s and t in [0, 1] the
    forces balance in force and moment.  Written so, not as SymPy's derivative of the
    normalised cross product, its expression is a fraction as long.
    """
    N = ReferenceFrame("N")
    X = {c: _vector_symbols(c, 3) for c in "abcd"}
    V = {c: _vector_symbols(f"v{c}", 3) for c in "abcd"}
    side = sp.Symbol("side", real=True)
    a, b, c, d = (_frame_vector(N, X[k]) for k in "abcd")
    u, w, r = b - a, d - c, a - c
    common = u.cross(w)
    normal = side * common / sp.sqrt(common.dot(common))
    uu, uw, ww, ur, wr = u.dot(u), u.dot(w), w.dot(w), u.dot(r), w.dot(r)
    den = common.dot(common)  # uu ww - uw^2 as |u x w|^2: no cancellation for nearly parallel edges
    s = (uw * wr - ww * ur) / den
    t = (uu * wr - uw * ur) / den
    gap = sp.Matrix([normal.dot(r)])
    n = [normal.dot(e) for e in (N.x, N.y, N.z)]
    weights = [1 - s, s, -(1 - t), -t]
    jacobian = sp.Matrix([[wk * nk for wk in weights for nk in n]])
    coordinates = [q for k in "abcd" for q in X[k]]
    velocities = sp.Matrix([q for k in "abcd" for q in V[k]])
    rate = jacobian * velocities
    relative = ((1 - s) * _frame_vector(N, V["a"]) + s * _frame_vector(N, V["b"])
                - (1 - t) * _frame_vector(N, V["c"]) - t * _frame_vector(N, V["d"]))
    tangential = relative - relative.dot(normal) * normal
    positions = [(k, X[k]) for k in "abcd"] + [("side", [side])]
    # Coulomb friction between the edges: the slip rates of the first edge's material point at
    # the contact relative to the second's, along t1 = (b - a) / |b - a| and t2 = n x t1 (both
    # perpendicular to n, which is perpendicular to b - a), linear in the velocities with the
    # Jacobian [(1 - s) t, s t, -(1 - t) t, -t t], and their accelerations' velocity terms, as
    # the triangle's slip kernel gives them for a particle on a face
    tangents = [u / sp.sqrt(u.dot(u))]
    tangents.append(normal.cross(tangents[0]))
    slip = sp.Matrix([relative.dot(e) for e in tangents])
    return [
        Kernel("edge_3d", "Edge a -> b of one body against edge c -> d of another: the signed distance "
               "n . (a - c) of their lines (m, < 0 crossed), n = side (b - a) x (d - c) / |(b - a) x (d - c)|, "
               "the closest points' parameters s (on a -> b) and t (on c -> d), unclamped, n, and "
               "d gap / d[a, b, c, d].",
               positions,
               {"gap": gap, "parameters": sp.Matrix([s, t]), "normal": sp.Matrix(n), "gap_jacobian": jacobian}),
        Kernel("edge_3d_velocity", "Gap rate (m/s) of edge a -> b against edge c -> d: the gap Jacobian times "
               "the velocities; the tangential part (m/s) of the velocity of the first edge's closest point "
               "relative to the second's; and the gap acceleration's velocity term (m/s^2), d2 gap / dt2 - J a.",
               positions + [(f"v{k}", V[k]) for k in "abcd"],
               {"gap_rate": rate, "tangential_velocity": sp.Matrix([tangential.dot(e) for e in (N.x, N.y, N.z)]),
                "gap_bias": rate.jacobian(coordinates) * velocities}),
        Kernel("edge_3d_slip", "Slip rates (m/s) of edge a -> b against edge c -> d: the velocity of the first "
               "edge's material point at the contact relative to the second's along the unit tangents "
               "t1 = (b - a) / |b - a| and t2 = n x t1, their accelerations' velocity terms (m/s^2), "
               "d2 s / dt2 - J_t a, and t1, t2.",
               positions + [(f"v{k}", V[k]) for k in "abcd"],
               {"slip_rate": slip, "slip_bias": slip.jacobian(coordinates) * velocities,
                "tangents": sp.Matrix([t.dot(e) for t in tangents for e in (N.x, N.y, N.z)])}),
    ]


def all_kernels() -> list[Kernel]:
    """Every element kernel, in the order they are generated."""
    kernels: list[Kernel] = []
    for d in DIMENSIONS:
        for damper in DAMPERS:
            kernels += link_kernels(d, damper)
        kernels += [particle_kernel(d), ground_kernel(d), split_kernel(d)]
    for d in DIMENSIONS:  # after the round-1 kernels: their generated text does not move
        kernels += _surface_kernels(d)
    return kernels + edge_kernels()  # last: the kernels before keep their generated text
