"""Equations of motion of a particle-spring-damper system by Kane's method.

Build time only (SymPy).  :func:`derive` turns a :class:`~flexbody.topology.Topology` and a
formulation into a :class:`SymbolicModel`: the mass matrix ``M(q, p)`` and forcing
``F(q, u, p)`` of ``M u' = F``, ``q' = u``, plus energies, particle positions and
velocities in N, ground gaps with their Jacobian and bias, and the forcing Jacobians an
implicit integrator needs.  Parameters (masses, stiffness, damping, rest lengths,
gravity, ground placement) stay symbols, so changing their values needs no regeneration.

Formulations
------------
``particles``
    q are the particle coordinates in N; M is constant and diagonal.
``floating`` (the thesis's)
    Per body, q1, q2 place T's origin in N, q3 is T's angle about N3, and the remaining
    coordinates are particle positions in T.  Gauge: the anchor particle is pinned at
    T's origin and the reference particle lies on T's x-axis (its y in T is not a
    coordinate), see :func:`flexbody.topology.gauge_particles`.  This removes the three
    rigid-motion redundancies, so M is nonsingular.

    In 3D, q1..q3 place T's origin and q4..q6 are body-fixed X-Y-Z angles (alpha about N1,
    beta about the turned 2-axis, gamma about T3), with their rates as the speeds, so
    ``q' = u`` holds as in every other model (the generated C copies u into q').  The
    gauge also puts a third particle in T's x-y plane (its z in T is not a coordinate):
    six coordinates removed, one per rigid motion.  Bodies of one particle have no
    angles; bodies whose particles are all on one line (two particles, a straight chain)
    have no third particle and are refused (the rotation about the line is not fixed).

    A ``rigid`` body is its frame T alone (the thesis's future work, "a flexible as well as a
    rigid body"): q1, q2, q3 in 2D (six in 3D), and its particles fixed in T at coordinates
    that are parameters (``rx<i>``, ``ry<i>``, ``rz<i>``: the particle's initial position in
    T), so its links carry no load and store no energy (they are not elastic; their k, c, L
    stay in p, unused).  Rigid and flexible bodies mix in one scene.

    Gimbal lock: at beta = +-90 deg (T's z-axis along N's x-axis) the angles' rates no
    longer span every spin and M is singular.  A quaternion has no such point, but needs
    ``q' = G(q) u != u`` and a norm constraint that drifts; the angles keep the runtime's
    kinematics the identity.  T is only a gauge (the particles' motion does not depend on
    it), so the lock is a property of the coordinates, not of the physics: a body must
    start at least 10 deg from it (:func:`flexbody.state.initial_coordinates` refuses
    otherwise, naming the body), and a body that tumbles close to it makes M
    ill-conditioned; on M singular the runtime stops with status ``blow_up``.  The
    particles formulation (the default) has no such point.

Never inverts M symbolically: the runtime solves ``M u' = F`` numerically.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from sympy.physics.mechanics import KanesMethod, Particle, Point, ReferenceFrame, dynamicsymbols

from flexbody.topology import Topology

#: Energies, in this order, returned by the generated ``energies`` function.
ENERGY_NAMES = ("kinetic", "spring", "gravity", "damping_power")


@dataclass
class SymbolicModel:
    """Everything the code generator prints, in plain symbols (no functions of time)."""

    formulation: str
    topology: Topology
    q: list[sp.Symbol]
    u: list[sp.Symbol]
    p: list[sp.Symbol]
    a: list[sp.Symbol]  # accelerations, inputs of the forcing Jacobian
    outputs: dict[str, sp.Matrix]  # name -> matrix, see OUTPUTS in codegen
    descriptions: dict[str, str]  # symbol name -> meaning, for eom.md

    @property
    def mass_matrix_is_diagonal(self) -> bool:
        M = self.outputs["mass_matrix"]
        return all(M[i, j] == 0 for i in range(M.rows) for j in range(M.cols) if i != j)


def _parameters(top: Topology) -> tuple[list[sp.Symbol], dict[str, str]]:
    n, nl = top.n_particles, top.n_links
    p: list[sp.Symbol] = []
    text: dict[str, str] = {}
    for i in range(n):
        p.append(sp.Symbol(f"m{i}", positive=True))
        text[f"m{i}"] = f"mass of particle {i} (kg)"
    drawn = {l_ for l_, rigid in enumerate(b.rigid for b in top.bodies for _ in b.links) if rigid}
    for prefix, meaning in (("k", "stiffness (N/m)"), ("c", "damping (N s/m)"), ("L", "rest length (m)")):
        for l_ in range(nl):
            p.append(sp.Symbol(f"{prefix}{l_}", real=True))
            text[f"{prefix}{l_}"] = f"{meaning} of link {l_}" + (", unused (a rigid body's link: it only draws the body)"
                                                                 if l_ in drawn else "")
    for axis in "xyz"[: top.dim]:
        p.append(sp.Symbol(f"g_{axis}", real=True))
        text[f"g_{axis}"] = f"gravity, {axis} component (m/s^2)"
    for j in range(top.n_grounds):
        for prefix, meaning in (("P", "a point of"), ("n", "unit normal of")):
            for axis in "xyz"[: top.dim]:
                p.append(sp.Symbol(f"{prefix}{j}_{axis}", real=True))
                text[f"{prefix}{j}_{axis}"] = f"{meaning} ground {j}, {axis} component"
    first = 0
    for b, body in enumerate(top.bodies):  # after everything else: flexible scenes keep their p
        if body.rigid:
            for i in range(body.n_particles):
                if i != body.gauge[0]:
                    for axis in "xyz"[: top.dim]:
                        p.append(rigid_symbol(axis, first + i))
                        text[f"r{axis}{first + i}"] = f"{axis} of particle {first + i} in T{b}, fixed (rigid body, m)"
        first += body.n_particles
    return p, text


def rigid_symbol(axis: str, particle: int) -> sp.Symbol:
    """The parameter of a rigid body's particle coordinate in T (``rx3`` ...)."""
    return sp.Symbol(f"r{axis}{particle}", real=True)


class _Builder:
    """Collects coordinates, speeds, points and particles for one formulation."""

    def __init__(self) -> None:
        self.N = ReferenceFrame("N")
        self.origin = Point("O")
        self.origin.set_vel(self.N, 0)
        self.q: list = []
        self.u: list = []
        self.text: dict[str, str] = {}
        self.frames: list[dict] = []  # per 3D floating body: what _equations_in_t needs

    def coordinate(self, name: str, speed: str, meaning: str):
        q, u = dynamicsymbols(f"{name} {speed}")
        self.q.append(q)
        self.u.append(u)
        self.text[name] = meaning
        self.text[speed] = f"time derivative of {name}"
        return q, u

    def particles_in_n(self, top: Topology) -> list[Point]:
        N, points = self.N, []
        for i in range(top.n_particles):
            position = velocity = 0 * N.x
            for axis, unit in zip("xyz"[: top.dim], (N.x, N.y, N.z)):
                c, v = self.coordinate(f"{axis}{i}", f"v{axis}{i}", f"{axis} of particle {i} in N (m)")
                position, velocity = position + c * unit, velocity + v * unit
            P = self.origin.locatenew(f"P{i}", position)
            P.set_vel(N, velocity)
            points.append(P)
        return points

    def particles_floating(self, top: Topology) -> list[Point]:
        N, points = self.N, []
        first = 0
        for b, body in enumerate(top.bodies):
            axes = list(zip("XYZ"[: top.dim], (N.x, N.y, N.z)))
            origin = velocity = 0 * N.x
            for q_name, (axis, unit) in enumerate(axes, start=1):
                c, v = self.coordinate(f"{axis}{b}", f"v{axis}{b}", f"{axis.lower()} of T{b}'s origin in N (q{q_name}, m)")
                origin, velocity = origin + c * unit, velocity + v * unit
            O = self.origin.locatenew(f"O{b}", origin)
            O.set_vel(N, velocity)
            T = ReferenceFrame(f"T{b}")
            frame = {"first": first, "n": body.n_particles, "T": T, "origin_speeds": list(self.u[-top.dim:]),
                     "angles": [], "rates": [], "rho": {}, "vrel": {}, "speeds": {}}
            if body.n_particles == 1:
                T.orient_axis(N, N.z, 0)
            elif top.dim == 2 and body.rigid:
                th, w = self.coordinate(f"theta{b}", f"omega{b}", f"angle of rigid body T{b} about N3 (q3, rad)")
                T.orient_axis(N, N.z, th)
                T.set_ang_vel(N, w * N.z)
            elif top.dim == 2:
                th, w = self.coordinate(f"theta{b}", f"omega{b}", f"angle of T{b} about N3 (q3, rad)")
                T.orient_axis(N, N.z, th)
                T.set_ang_vel(N, w * N.z)
            else:
                frame["angles"], frame["rates"] = self._orient_3d(T, b)
            for i in range(body.n_particles):
                if body.rigid:
                    points.append(self._particle_fixed_in_t(O, T, body.gauge, i, first + i, top.dim, frame))
                else:
                    points.append(self._particle_in_t(O, T, body.gauge, i, first + i, b, top.dim, frame))
            if top.dim == 3:
                self.frames.append(frame)
            first += body.n_particles
        return points

    def _orient_3d(self, T: ReferenceFrame, b: int) -> tuple[list, list]:
        """T's orientation in N by body-fixed X-Y-Z angles; the speeds are their rates (q' = u).

        Singular (gimbal lock) where beta = +-90 deg, i.e. T's z-axis along N's x-axis: see
        the module docstring.
        """
        meaning = ("first, about N1. In 3D the rows below are not regrouped by cause: F_<speed> is "
                   "the forcing as derived, printed in the raw equations",
                   "second, about the rotated 2-axis (+-90 deg: gimbal lock)",
                   "third, about T3")
        angles, rates = [], []
        for k, (name, text) in enumerate(zip(("alpha", "beta", "gamma"), meaning), start=4):
            a, w = self.coordinate(f"{name}{b}", f"v{name}{b}",
                                   f"body-fixed X-Y-Z angle of T{b} in N, {text} (q{k}, rad)")
            angles.append(a)
            rates.append(w)
        T.orient_body_fixed(self.N, angles, "XYZ")
        # The angular velocity in the speeds (the angles' rates), in T's components.
        omega = T.ang_vel_in(self.N).express(T).xreplace({a.diff(): w for a, w in zip(angles, rates)})
        T.set_ang_vel(self.N, omega)
        return angles, rates

    def _particle_fixed_in_t(self, O: Point, T: ReferenceFrame, gauge: tuple[int, ...], i: int, g: int,
                             dim: int, frame: dict) -> Point:
        """Particle g (index i of a rigid body) fixed in T: the anchor at T's origin, the others
        at the parameters ``rx<g>, ry<g>[, rz<g>]``; no coordinates."""
        rho = sp.zeros(3, 1)
        if i != gauge[0]:
            for k, axis in enumerate("xyz"[:dim]):
                rho[k] = rigid_symbol(axis, g)
        frame["rho"][i], frame["vrel"][i], frame["speeds"][i] = rho, sp.zeros(3, 1), []
        P = O.locatenew(f"P{g}", rho[0] * T.x + rho[1] * T.y + rho[2] * T.z)
        P.v2pt_theory(O, self.N, T)
        return P

    def _particle_in_t(self, O: Point, T: ReferenceFrame, gauge: tuple[int, ...], i: int, g: int, b: int,
                       dim: int, frame: dict) -> Point:
        """Particle g (index i in body b) at coordinates in T, less those the gauge removes.

        The anchor is at T's origin (no coordinate), the reference on T's x-axis (x only),
        and in 3D the third particle in T's x-y plane (x and y only).
        """
        frame["rho"][i], frame["vrel"][i], frame["speeds"][i] = sp.zeros(3, 1), sp.zeros(3, 1), []
        if i == gauge[0]:
            P = O.locatenew(f"P{g}", 0 * T.x)
            P.set_vel(self.N, O.vel(self.N))
            return P
        kept = 1 if i == gauge[1] else 2 if dim == 2 or i == gauge[2] else 3
        position = velocity = 0 * T.x
        for k, (name, axis, unit) in enumerate(list(zip(("xi", "eta", "zeta"), "xyz", (T.x, T.y, T.z)))[:kept]):
            c, v = self.coordinate(f"{name}{g}", f"v{name}{g}", f"{axis} of particle {g} in T{b} (m)")
            position, velocity = position + c * unit, velocity + v * unit
            frame["rho"][i][k], frame["vrel"][i][k] = c, v
            frame["speeds"][i].append((k, v))
        P = O.locatenew(f"P{g}", position)
        P.set_vel(T, velocity)
        P.v1pt_theory(O, self.N, T)
        return P


def _cross(a: sp.Matrix, b: sp.Matrix) -> sp.Matrix:
    return sp.Matrix([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _equations_in_t(build: _Builder, top: Topology, sym: dict[str, sp.Symbol]) -> tuple[sp.Matrix, sp.Matrix]:
    """``M`` and ``F`` of the 3D floating formulation, assembled from Kane's terms in T's components.

    Kane's ``F_r = sum_i (f_i - m_i a_i|u'=0) . dv_i/du_r`` and ``M_rs = sum_i m_i
    dv_i/du_r . dv_i/du_s``, with ``v_i = v_O + v_i/T + w x rho_i``, written so that what
    cancels does so before it is printed: the internal forces in the translation rows
    (they sum to zero) and, for springs and axial dampers, in the rotation rows (a force
    along the link has no moment about it); ``a_O|u'=0 = 0`` (O's speeds are its velocity
    components in N); ``R^T R = 1``.  What SymPy's KanesMethod returns is the same
    up to trigonometric identities, but about 10x longer in 3D, and the forcing Jacobians
    grew with it (minutes for eight particles).

    Returns
    -------
    M : Matrix, shape (nu, nu)
    F : Matrix, shape (nu, 1)
    """
    N, nu = build.N, len(build.u)
    index = {u: r for r, u in enumerate(build.u)}
    M, F = sp.zeros(nu, nu), sp.zeros(nu, 1)
    g_n = sp.Matrix([sym[f"g_{a}"] for a in "xyz"])
    link = 0
    for body, frame in zip(top.bodies, build.frames):
        T, first, n = frame["T"], frame["first"], frame["n"]
        R = N.dcm(T)  # columns: T's axes in N
        g_t = R.T * g_n
        omega = sp.Matrix([T.ang_vel_in(N).dot(e) for e in (T.x, T.y, T.z)])  # (3,) in T, linear in the rates
        rates, angles = frame["rates"], frame["angles"]
        B = omega.jacobian(rates) if rates else sp.zeros(3, 0)
        omega_dot = omega.jacobian(angles) * sp.Matrix(rates) if rates else sp.zeros(3, 1)  # q' = u
        m = [sym[f"m{first + i}"] for i in range(n)]
        rho, vrel = frame["rho"], frame["vrel"]
        # Forces on each particle in T: gravity, then the links.
        force = [m[i] * g_t for i in range(n)]
        torque = sp.zeros(3, 1)  # sum_i rho_i x (internal force on i): the relative dampers only
        for i, j in body.links if not body.rigid else ():
            k, c, rest = sym[f"k{link}"], sym[f"c{link}"], sym[f"L{link}"]
            d = rho[i] - rho[j]
            length = sp.sqrt(d.dot(d))
            dv = vrel[j] - vrel[i] + _cross(omega, rho[j] - rho[i])
            if body.damper == "relative":
                f_damp = c * dv
                torque += _cross(d, f_damp)
            else:
                f_damp = c * dv.dot(d) * d / length**2
            f = k * (rest - length) * d / length + f_damp
            force[i], force[j] = force[i] + f, force[j] - f
            link += 1
        link += len(body.links) if body.rigid else 0
        # Inertia: a_i|u'=0 in T = w' x rho_i + w x (w x rho_i) + 2 w x v_i/T (a_O|u'=0 = 0).
        inertia = [m[i] * (_cross(omega_dot, rho[i]) + _cross(omega, _cross(omega, rho[i]))
                           + 2 * _cross(omega, vrel[i])) for i in range(n)]
        mass, moment = sum(m, sp.S.Zero), sum((m[i] * rho[i] for i in range(n)), sp.zeros(3, 1))
        momentum_t = sum((m[i] * vrel[i] for i in range(n)), sp.zeros(3, 1))
        # sum_i of the inertia terms, linear in rho_i and v_i/T: written with their sums, once
        total_inertia = _cross(omega_dot, moment) + _cross(omega, _cross(omega, moment)) + 2 * _cross(omega, momentum_t)
        rows = [index[s] for s in frame["origin_speeds"]]
        for a, r in enumerate(rows):  # translation: internal forces cancel
            F[r] = mass * g_n[a] - (R[a, :] * total_inertia)[0]
            M[r, r] = mass
        # sum_i rho_i x inertia_i = J w' + w x (J w) + 2 (w h - H w): the inertia tensor J about O,
        # h = sum_i m_i rho_i . v_i/T and H = sum_i m_i v_i/T rho_i^T; no angle in J, h, H.
        J = sum((m[i] * (rho[i].dot(rho[i]) * sp.eye(3) - rho[i] * rho[i].T) for i in range(n)), sp.zeros(3, 3))
        h = sum((m[i] * rho[i].dot(vrel[i]) for i in range(n)), sp.S.Zero)
        H = sum((m[i] * vrel[i] * rho[i].T for i in range(n)), sp.zeros(3, 3))
        spin_inertia = J * omega_dot + _cross(omega, J * omega) + 2 * (omega * h - H * omega)
        net_moment = _cross(moment, g_t) + torque - spin_inertia
        spins = [index[s] for s in rates]
        for a, r in enumerate(spins):
            F[r] = B[:, a].dot(net_moment)
            for c_, s in enumerate(rows):
                M[r, s] = M[s, r] = (R[c_, :] * _cross(B[:, a], moment))[0]
            for b_, s in enumerate(spins):
                M[r, s] = sum((m[i] * _cross(B[:, a], rho[i]).dot(_cross(B[:, b_], rho[i])) for i in range(n)),
                              sp.S.Zero)
        for i in range(n):
            for axis, speed in frame["speeds"][i]:
                r = index[speed]
                F[r] = force[i][axis] - inertia[i][axis]
                M[r, r] = m[i]
                for c_, s in enumerate(rows):
                    M[r, s] = M[s, r] = m[i] * R[c_, axis]
                for a, s in enumerate(spins):
                    M[r, s] = M[s, r] = m[i] * _cross(B[:, a], rho[i])[axis]
    return M, F


def _kinematics_solver(A: sp.Matrix, b: sp.Matrix) -> sp.Matrix:
    """Solve A x = b for the kinematic equations q' = u, where A is diagonal (the identity).

    SymPy's default is a dense symbolic LU, which dominated the derivation time
    (87 of 158 s at 100 degrees of freedom); a diagonal system needs none.
    """
    if A.is_diagonal():
        return sp.Matrix(b.rows, b.cols, lambda i, j: b[i, j] / A[i, i])
    return A.LUsolve(b)


def jacobian(exprs: sp.Matrix, symbols: list[sp.Symbol]) -> sp.Matrix:
    """``exprs.jacobian(symbols)``, differentiating only where a symbol occurs.

    Each force involves few coordinates, so most entries are zero; skipping them made the
    Jacobians ~10x cheaper to derive for large bodies.
    """
    index = {s: j for j, s in enumerate(symbols)}
    entries = {}
    for i, expr in enumerate(exprs):
        for s in expr.free_symbols & index.keys():
            d = expr.diff(s)
            if d != 0:
                entries[i, index[s]] = d
    return sp.Matrix(sp.SparseMatrix(len(exprs), len(symbols), entries))


def derive(top: Topology, formulation: str) -> SymbolicModel:
    """Derive the equations of motion and every generated output for one topology.

    Parameters
    ----------
    top : Topology
    formulation : {"particles", "floating"}

    Returns
    -------
    SymbolicModel
    """
    if formulation not in ("particles", "floating"):
        raise ValueError(f"`formulation` = {formulation!r}: must be 'particles' or 'floating'")
    if formulation == "particles" and top.has_rigid:
        raise ValueError("rigid bodies are frames T without particle coordinates: they need the floating formulation")
    if formulation == "floating" and top.dim == 3:
        unfixed = [b for b, body in enumerate(top.bodies) if body.n_particles > 1 and body.gauge[2] < 0]
        if unfixed:
            raise ValueError(f"bodies {unfixed}: all particles on one line, so no third particle fixes the rotation "
                             "about it; the floating formulation needs one in 3D")
    p, text = _parameters(top)
    sym = {s.name: s for s in p}
    build = _Builder()
    N = build.N
    points = build.particles_in_n(top) if formulation == "particles" else build.particles_floating(top)
    masses = [sym[f"m{i}"] for i in range(top.n_particles)]
    axes = list(zip("xyz"[: top.dim], (N.x, N.y, N.z)))
    gravity = sum((sym[f"g_{a}"] * unit for a, unit in axes), 0 * N.x)

    loads = [(P, m * gravity) for P, m in zip(points, masses)]
    spring_energy = damping_power = sp.S.Zero
    link, first = 0, 0
    for body in top.bodies:
        if body.rigid:  # fixed in T: its links are not elastic, no load, no energy
            link += len(body.links)
            first += body.n_particles
            continue
        for i, j in body.links:
            Pi, Pj = points[first + i], points[first + j]
            k, c, rest = sym[f"k{link}"], sym[f"c{link}"], sym[f"L{link}"]
            d = Pi.pos_from(Pj)  # P_ij = x_i - x_j, thesis eq. 3.7
            length = sp.sqrt(d.dot(d))
            e = d / length
            dv = Pj.vel(N) - Pi.vel(N)  # V_j - V_i
            if body.damper == "relative":  # thesis eq. 3.8
                f_damp = c * dv
                damping_power += c * dv.dot(dv)
            else:
                f_damp = c * dv.dot(e) * e
                damping_power += c * dv.dot(e) ** 2
            f = k * (rest - length) * e + f_damp  # force on i; j gets -f
            loads += [(Pi, f), (Pj, -f)]
            spring_energy += k * (length - rest) ** 2 / 2
            link += 1
        first += body.n_particles

    q, u = build.q, build.u
    if formulation == "floating" and top.dim == 3:
        M, F = _equations_in_t(build, top, sym)
    else:
        kane = KanesMethod(N, q_ind=q, u_ind=u, kd_eqs=[qi.diff() - ui for qi, ui in zip(q, u)],
                           kd_eqs_solver=_kinematics_solver)
        kane.kanes_equations([Particle(f"pa{i}", P, m) for i, (P, m) in enumerate(zip(points, masses))], loads)
        M, F = kane.mass_matrix, kane.forcing

    positions = [P.pos_from(build.origin).express(N) for P in points]
    velocities = [P.vel(N).express(N) for P in points]
    kinetic = sum((m * v.dot(v) for m, v in zip(masses, velocities)), sp.S.Zero) / 2
    gravity_energy = -sum((m * r.dot(gravity) for m, r in zip(masses, positions)), sp.S.Zero)
    gaps = []
    for r in positions:  # contact c = particle * n_grounds + ground
        for g in range(top.n_grounds):
            point = sum((sym[f"P{g}_{a}"] * unit for a, unit in axes), 0 * N.x)
            normal = sum((sym[f"n{g}_{a}"] * unit for a, unit in axes), 0 * N.x)
            gaps.append((r - point).dot(normal))

    # Replace functions of time by plain symbols: q(t) -> q, u(t) -> u.
    qs = [sp.Symbol(s.name, real=True) for s in (qi.func for qi in q)]
    us = [sp.Symbol(s.name, real=True) for s in (ui.func for ui in u)]
    plain = dict(zip(q, qs)) | dict(zip(u, us))
    plain |= {qi.diff(): ui for qi, ui in zip(q, us)}

    def to_plain(expr):
        return sp.sympify(expr).xreplace(plain)

    M = M.xreplace(plain)
    F = F.xreplace(plain)
    a = [sp.Symbol(f"a{r}", real=True) for r in range(len(us))]
    gap_vec = sp.Matrix([to_plain(g) for g in gaps])
    Jg = jacobian(gap_vec, qs) if gaps else sp.zeros(0, len(qs))
    bias = jacobian(Jg * sp.Matrix(us), qs) * sp.Matrix(us) if gaps else sp.zeros(0, 1)
    # Particle velocities are linear in u: v = P(q) u, and their accelerations P u' + P' u.
    # Contacts between bodies need both to constrain a particle against another's surface.
    V = sp.Matrix([to_plain(v.dot(unit)) for v in velocities for _, unit in axes])
    P = jacobian(V, us)
    particle_bias = (jacobian(V, qs) * sp.Matrix(us)).reshape(len(velocities), top.dim)
    outputs = {
        "mass_matrix": M,
        "forcing": F,
        "energies": sp.Matrix([to_plain(e) for e in (kinetic, spring_energy, gravity_energy, damping_power)]),
        "damping_power": sp.Matrix([to_plain(damping_power)]),
        "positions": sp.Matrix([[to_plain(r.dot(unit)) for _, unit in axes] for r in positions]),
        "velocities": sp.Matrix([[to_plain(v.dot(unit)) for _, unit in axes] for v in velocities]),
        "gaps": gap_vec,
        "gap_jacobian": Jg,
        "gap_bias": bias,
        "particle_jacobian": P,
        "particle_bias": particle_bias,
        # d(F - M a)/dq and dF/du: with q' = u these give the Jacobian of the first-order RHS.
        "jacobian_q": jacobian(F - M * sp.Matrix(a), qs),
        "jacobian_u": jacobian(F, us),
    }
    text |= build.text | {f"a{r}": f"acceleration input {r} of the forcing Jacobian" for r in range(len(a))}
    return SymbolicModel(formulation, top, qs, us, p, a, outputs, text)
