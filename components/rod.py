"""A planar Cosserat (Simo–Reissner) rod as a port-Hamiltonian component.

The rod of length ``L`` is clamped at ``s = 0`` and cut into ``n`` elements of length
``h = L/n``.  Configuration and momenta live on the nodes ``k = 1..n`` (node 0 is the
clamp), strains on the elements (a staggered grid):

* states of node ``k``: displacements ``ux{k}``, ``uy{k}`` from the straight reference
  ``X_k = k h (cos beta, sin beta)``, rotation ``theta{k}`` of the cross-section, and the
  conjugate momenta ``px{k}``, ``py{k}``, ``pth{k}`` (the zero state is the undeformed rod at rest);
* strains of element ``e`` (nodes ``a = e-1``, ``b = e``), geometrically exact:
  ``d = (r_b - r_a)/h``, ``phi = beta + (theta_a + theta_b)/2``,
  ``nu1 = cos(phi) d_x + sin(phi) d_y - 1`` (extension), ``nu2 = -sin(phi) d_x + cos(phi) d_y``
  (shear), ``kappa = (theta_b - theta_a)/h`` (curvature);
* energy ``H = sum_e h (EA nu1^2 + k_s G A nu2^2 + E I kappa^2)/2 + sum_k (|p_k|^2/(2 m_k) + pth_k^2/(2 j_k))
  + sum_k (rho - rho_w) A h_k g y_k`` with lumped ``m_k = rho A h_k``, ``j_k = rho I h_k``, ``h_k = h``
  (``h/2`` at the tip);
* structure: every nodal degree of freedom ``q`` is a 1-junction of its configuration storage,
  its momentum storage, the Kelvin–Voigt damper and the load ports, so ``q' = dH/dp`` and
  ``p' = -dH/dq - F_damp + F_ext``: J is the canonical symplectic matrix (constant, exactly skew);
* damping: Kelvin–Voigt, damping stresses ``tau`` times the elastic ones evaluated at the strain
  rates, ``R_pp = sum_e B_e^T (tau h C) B_e`` with ``B_e = d(nu1, nu2, kappa)/dq`` and
  ``C = diag(EA, k_s G A, E I)``, symmetric positive semidefinite by construction.  With
  ``damping="kelvin_voigt"`` ``B_e(q)`` is taken at the current configuration (geometrically exact,
  configuration-dependent R: costly to assemble, for small n); the default
  ``"stiffness_proportional"`` takes ``B_e`` at the reference, so ``R = tau K_0`` is constant
  (stiffness-proportional Rayleigh damping: exact for small strain rates about the straight rod, not
  frame-indifferent for large rotations).  An optional viscous drag ``c_v h_k v_k`` on each node
  (a linearised fluid drag) adds ``c_v h_k`` to the translational diagonal of R; an optional quadratic
  drag ``c_q h_k |v_k| v_k`` on each node (isotropic fluid drag, ``c_q`` in kg/m**2; the water drag
  ``R C q ⊙ |q|`` of Doroudchi et al., eq. 5, with the speed ``|q|`` in place of each component's
  magnitude: the same for motion across the rod) adds ``c_q h_k |v_k|`` to the translational diagonal of
  R, with ``|v_k| = |p_k|/m_k`` from the momenta (smoothed as ``sqrt(|v_k|^2 + v_s^2)``, ``v_s`` a
  thousandth of the typical velocity of :meth:`CosseratRod.scales`);

In the strain coordinates the same structure reads ``eps' = D(q) v``, ``p' = -D(q)^T sigma``: the
discrete differential operator ``D`` and its negative transpose, so the semi-discrete power balance
``dH/dt = -grad(H)^T R grad(H) + y^T u`` holds exactly.  Nothing is linearised: large rotations,
extension and shear are exact at the nodes; the spatial discretisation (midpoint rule on each
element, lumped inertia) is second-order accurate.

Ports (created only when asked for, each a translational or rotational effort/flow pair whose flow
is the velocity it acts on): ``tip_x``, ``tip_y``, ``tip_m`` (force/torque at the tip in the fixed
frame), ``tip_t``, ``tip_n`` (follower force along/normal to the tip cross-section), ``qx``, ``qy``
(uniform load per unit length, conjugate flow ``sum_k h_k v_k``), ``fx{k}``, ``fy{k}`` (node forces)
and ``c{e}`` (a couple bending element ``e``: ``+M`` on node ``e``, ``-M`` on node ``e-1``,
conjugate flow ``omega_e - omega_{e-1}``; ``c{a}_{b}`` the same over the nodes ``a < b``).
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy as sp

from components._base import require_positive
from phs.component import Component, Dissipator, Piece, Port, Relation
from phs.errors import ModelError
from phs.params import EnergyTerm, Measured

TIP_LOADS = ("free", "force", "follower")
"""Tip load options of :class:`CosseratRod`."""

DAMPING = ("stiffness_proportional", "kelvin_voigt")
"""Damping laws of :class:`CosseratRod`: Kelvin–Voigt with the strain rates linearised at the reference
configuration (a constant ``R = tau K_0``), or geometrically exact (``R(q)``)."""


def element_strains(xa, ya, ta, xb, yb, tb, h, beta=0) -> tuple[sp.Expr, sp.Expr, sp.Expr | float]:
    """Extension, shear and curvature ``(nu1, nu2, kappa)`` of one element from its end nodes.

    ``xa, ya, ta`` are the position and cross-section rotation of the first node, ``xb, yb, tb``
    those of the second, ``h`` the reference length and ``beta`` the reference direction.

    Examples
    --------
    A rigid rotation by 0.3 rad leaves the strains at zero:

    >>> import sympy as sp
    >>> nu1, nu2, kappa = element_strains(0, 0, 0.3, sp.cos(0.3), sp.sin(0.3), 0.3, 1)
    >>> [abs(round(float(v), 12)) for v in (nu1, nu2, kappa)]
    [0.0, 0.0, 0.0]
    """
    dx, dy = (xb - xa) / h, (yb - ya) / h
    phi = beta + (ta + tb) / 2
    c, s = sp.cos(phi), sp.sin(phi)
    return c * dx + s * dy - 1, -s * dx + c * dy, (tb - ta) / h


class CosseratRod(Component):
    """Planar geometrically exact Cosserat rod, clamped at the base, as a port-Hamiltonian piece.

    Parameters
    ----------
    name : str
        Component name; states are ``{name}.ux{k}``, ``{name}.uy{k}``, ``{name}.theta{k}``,
        ``{name}.px{k}``, ``{name}.py{k}``, ``{name}.pth{k}`` for nodes ``k = 1..n``.
    n : int
        Number of elements (at least 1).
    L, rho, A, I, E, G, k_s, tau : float, Param or expression
        Length [m], density [kg/m**3], cross-section area [m**2], second moment of area [m**4],
        Young's and shear moduli [Pa], shear correction factor [-] and Kelvin–Voigt retardation
        time [s] (damping stresses ``tau`` times the elastic stresses of the strain rates; 0: none).
    damping : {"stiffness_proportional", "kelvin_voigt"}
        Strain rates linearised at the reference (constant R, default) or geometrically exact.
    c_v : float, Param or expression
        Viscous drag per unit length [N*s/m**2] on the nodal velocities (0: none).
    c_q : float, Param or expression
        Quadratic drag per unit length [kg/m**2] on the nodal velocities, ``c_q |v| v`` (0: none).
    gravity : bool
        Include the weight ``(rho - rho_w) A g`` per unit length along ``-y``.
    g, rho_w : float, Param or expression
        Gravitational acceleration [m/s**2] and density of a surrounding fluid [kg/m**3]
        (buoyancy); used only with ``gravity``.
    beta : float
        Direction of the clamped reference configuration [rad] (0: along +x).
    tip : {"free", "force", "follower"}
        ``"force"`` adds ports ``tip_x``, ``tip_y``, ``tip_m`` (fixed frame); ``"follower"`` adds
        ``tip_t``, ``tip_n`` (along and normal to the tip cross-section) and ``tip_m``.
    distributed : sequence of {"x", "y"}
        Uniform load ports ``qx``/``qy`` [N/m].
    node_forces : sequence of int
        Nodes ``k`` (1..n) with force ports ``fx{k}``, ``fy{k}``.
    couples : sequence of int or (int, int)
        Elements ``e`` (1..n) with bending couple ports ``c{e}`` (``+M`` on node ``e``, ``-M`` on node
        ``e-1``), or node pairs ``(a, b)`` with a couple over the span between them (port ``c{a}_{b}``).

    Examples
    --------
    >>> from phs import interconnect
    >>> rod = interconnect("rod", [CosseratRod("rod", n=3, tau=0.01)])
    >>> len(rod.states), rod.J[0, 3], rod.J[3, 0]
    (18, 1, -1)
    >>> rod.measured_names
    ['rod.tip_x', 'rod.tip_y', 'rod.tip_theta']
    """

    def __init__(self, name: str, n: int = 10, *, L=1.0, rho=1000.0, A=1e-4, I=1e-9, E=1e6, G=None,  # noqa: E741
                 k_s=5 / 6, tau=0.0, damping: str = "stiffness_proportional", c_v=0.0, c_q=0.0, gravity: bool = False,
                 g=9.81, rho_w=0.0, beta: float = 0.0,
                 tip: str = "free", distributed: Sequence[str] = (), node_forces: Sequence[int] = (),
                 couples: Sequence[int] = ()):
        super().__init__(name)
        if not isinstance(n, int) or isinstance(n, bool) or n < 1:
            raise ModelError(f"component {name!r}: the number of elements n must be a positive integer, got {n!r}")
        for key, value in (("L", L), ("rho", rho), ("A", A), ("I", I), ("E", E), ("k_s", k_s)):
            require_positive(name, key, value)
        if isinstance(tau, (int, float)) and tau < 0:
            raise ModelError(f"component {name!r}: the retardation time tau must be >= 0, got {tau}")
        if damping not in DAMPING:
            raise ModelError(f"component {name!r}: unknown damping {damping!r}; use one of {DAMPING}")
        for key, value in (("c_v", c_v), ("c_q", c_q)):
            if isinstance(value, (int, float)) and value < 0:
                raise ModelError(f"component {name!r}: the drag coefficient {key} must be >= 0, got {value}")
        if tip not in TIP_LOADS:
            raise ModelError(f"component {name!r}: unknown tip load {tip!r}; use one of {TIP_LOADS}")
        bad = [d for d in distributed if d not in ("x", "y")]
        if bad:
            raise ModelError(f"component {name!r}: distributed loads act along 'x' or 'y', not {bad}")
        wrong = [k for k in node_forces if not (isinstance(k, int) and 1 <= k <= n)]
        wrong += [c for c in couples if not (isinstance(c, int) and 1 <= c <= n) and not (
            isinstance(c, tuple) and len(c) == 2 and all(isinstance(k, int) for k in c) and 0 <= c[0] < c[1] <= n)]
        if wrong:
            raise ModelError(f"component {name!r}: node_forces must be nodes in 1..{n} and couples elements in 1..{n} "
                             f"or node pairs (a, b) with 0 <= a < b <= {n}; got {wrong}")
        self.n = n
        self.values = dict(L=L, rho=rho, A=A, I=I, E=E, G=E / 3 if G is None else G, k_s=k_s, tau=tau, c_v=c_v, c_q=c_q,
                           g=g, rho_w=rho_w)
        self.damping = damping
        self.gravity, self.beta, self.tip = bool(gravity), float(beta), tip
        self.distributed, self.node_forces, self.couples = tuple(distributed), tuple(node_forces), tuple(couples)

    # -- parameters and scales -------------------------------------------------------------------
    _UNITS = {"L": ("m", "length"), "rho": ("kg/m**3", "density"), "A": ("m**2", "cross-section area"),
              "I": ("m**4", "second moment of area"), "E": ("Pa", "Young's modulus"), "G": ("Pa", "shear modulus"),
              "k_s": ("1", "shear correction factor"), "tau": ("s", "Kelvin-Voigt retardation time"),
              "c_v": ("N*s/m**2", "viscous drag per unit length"),
              "c_q": ("kg/m**2", "quadratic drag per unit length"),
              "g": ("m/s**2", "gravitational acceleration"), "rho_w": ("kg/m**3", "density of the surrounding fluid")}

    def _params(self):
        keys = ["L", "rho", "A", "I", "E", "G", "k_s"] + [k for k in ("tau", "c_v", "c_q") if self.values[k] != 0]
        keys += ["g", "rho_w"] if self.gravity else []
        syms, decls = {}, []
        for key in keys:
            unit, desc = self._UNITS[key]
            sym, decl = self._param(key, self.values[key], unit, desc)
            syms[key] = sym
            decls.extend(decl)
        return syms, tuple(decls)

    def _numeric(self, key: str, default: float) -> float:
        v = self.values[key]
        v = v.value if hasattr(v, "value") and not isinstance(v, sp.Expr) else v
        try:
            return float(v)
        except (TypeError, ValueError):
            return default

    def scales(self) -> dict[str, float]:
        """Typical magnitudes (length, angle, momentum per unit mass velocity) used to scale states.

        Examples
        --------
        >>> CosseratRod("rod", n=4, L=2.0).scales()["length"]
        0.2
        """
        L = self._numeric("L", 1.0)
        EI = self._numeric("E", 1.0) * self._numeric("I", 1.0)
        rA = self._numeric("rho", 1.0) * self._numeric("A", 1.0)
        omega1 = 3.516 * (EI / (rA * L**4)) ** 0.5  # first clamped-free bending frequency
        v = 0.1 * L * omega1
        h = L / self.n
        return {"length": 0.1 * L, "angle": 0.1, "velocity": v, "momentum": rA * h * v,
                "angular_momentum": self._numeric("rho", 1.0) * self._numeric("I", 1.0) * h * 0.1 * omega1}

    # -- the piece -------------------------------------------------------------------------------------
    def piece(self) -> Piece:
        P, params = self._params()
        n, beta = self.n, self.beta
        h = P["L"] / n
        sc = self.scales()
        L = self._numeric("L", 1.0)
        storages, q_of, p_of = [], [], []
        for k in range(1, n + 1):
            node_q, node_p = [], []
            for local, unit, rng, desc, kind, dom, s in (
                (f"ux{k}", "m", (-2 * L, 2 * L), f"x-displacement of node {k}", "C", "translational", sc["length"]),
                (f"uy{k}", "m", (-2 * L, 2 * L), f"y-displacement of node {k}", "C", "translational", sc["length"]),
                (f"theta{k}", "rad", (-4.0, 4.0), f"rotation of cross-section {k}", "C", "rotational", sc["angle"]),
            ):
                st = self._state(local, None, unit, rng, desc, kind, dom, s)
                storages.append(st)
                node_q.append(st)
            for local, unit, desc, s in ((f"px{k}", "kg*m/s", f"x-momentum of node {k}", sc["momentum"]),
                                         (f"py{k}", "kg*m/s", f"y-momentum of node {k}", sc["momentum"]),
                                         (f"pth{k}", "kg*m**2/s", f"angular momentum of node {k}", sc["angular_momentum"])):
                dom = "rotational" if local.startswith("pth") else "translational"
                st = self._state(local, None, unit, (-100 * s, 100 * s), desc, "I", dom, s)
                storages.append(st)
                node_p.append(st)
            q_of.append(node_q)
            p_of.append(node_p)
        qsym = [[st.state.symbol for st in node] for node in q_of]
        vel = [[st.coenergy for st in node] for node in p_of]  # dH/dp: nodal velocities
        zero = (sp.Integer(0),) * 3

        def pose(k):
            """Position and rotation of node k (0: the clamp) as expressions of the states."""
            if k == 0:
                return zero
            ux, uy, th = qsym[k - 1]
            return (k * h * sp.cos(beta) + ux, k * h * sp.sin(beta) + uy, th)

        def velocity(k):
            return zero if k == 0 else tuple(vel[k - 1])

        EA, GA, EI = P["E"] * P["A"], P["k_s"] * P["G"] * P["A"], P["E"] * P["I"]
        bending, shear, kinetic, weight = [], [], [], []
        forces = [[sp.Integer(0)] * 3 for _ in range(n)]  # damping forces on each node's three dofs
        dissipated = []
        for e in range(1, n + 1):
            a, b = pose(e - 1), pose(e)
            nu1, nu2, kappa = element_strains(*a, *b, h, beta)
            shear.append(h * (EA * nu1**2 + GA * nu2**2) / 2)
            bending.append(h * EI * kappa**2 / 2)
            if "tau" in P:
                dofs = [(e - 1, i) for i in range(3)] * (e > 1) + [(e, i) for i in range(3)]
                va, vb = velocity(e - 1), velocity(e)
                vloc = {**({(e - 1, i): va[i] for i in range(3)} if e > 1 else {}), **{(e, i): vb[i] for i in range(3)}}
                qloc = {**({(e - 1, i): qsym[e - 2][i] for i in range(3)} if e > 1 else {}),
                        **{(e, i): qsym[e - 1][i] for i in range(3)}}
                damp, local_power = [], []
                at_rest = {qloc[d]: 0 for d in dofs} if self.damping == "stiffness_proportional" else {}
                for strain, stiff in ((nu1, EA), (nu2, GA), (kappa, EI)):
                    grads = {d: sp.diff(strain, qloc[d]).xreplace(at_rest) for d in dofs}
                    rate = sp.Add(*[grads[d] * vloc[d] for d in dofs])
                    sigma = P["tau"] * h * stiff * rate
                    damp.append((grads, sigma))
                    local_power.append(sigma * rate)
                dissipated.append((f"damping{e}", sp.Add(*local_power)))
                for grads, sigma in damp:
                    for (node, i), gr in grads.items():
                        if gr != 0:
                            forces[node - 1][i] += gr * sigma
        for k in range(1, n + 1):
            hk = h / 2 if k == n else h
            m, j = P["rho"] * P["A"] * hk, P["rho"] * P["I"] * hk
            px, py, pth = (st.state.symbol for st in p_of[k - 1])
            kinetic.append((px**2 + py**2) / (2 * m) + pth**2 / (2 * j))
            if "c_v" in P:
                for i in range(2):
                    forces[k - 1][i] += P["c_v"] * hk * velocity(k)[i]
                dissipated.append((f"drag{k}", P["c_v"] * hk * (velocity(k)[0] ** 2 + velocity(k)[1] ** 2)))
            if "c_q" in P:
                self._quadratic_drag(k, P["c_q"] * hk, m, (px, py), velocity(k), forces, dissipated, 1e-3 * sc["velocity"])
            if self.gravity:
                weight.append((P["rho"] - P["rho_w"]) * P["A"] * hk * P["g"] * pose(k)[1])
        energy = [EnergyTerm(f"{self.name}.bending", sp.Add(*bending)),
                  EnergyTerm(f"{self.name}.shear_extension", sp.Add(*shear)),
                  EnergyTerm(f"{self.name}.kinetic", sp.Add(*kinetic))]
        if weight:
            energy.append(EnergyTerm(f"{self.name}.gravity", sp.Add(*weight)))
        ports, loads = self._load_ports(h, pose, velocity)
        relations = []
        for k in range(1, n + 1):
            for i in range(3):
                qs, ps = q_of[k - 1][i], p_of[k - 1][i]
                ext = sp.Add(*[coef * port.effort for (node, dof, coef, port) in loads if node == k and dof == i])
                relations.append(Relation(qs.rate - ps.coenergy, self.name, "kinematic"))
                relations.append(Relation(ps.rate + qs.coenergy + forces[k - 1][i] - ext, self.name, "balance"))
        by_port: dict[str, list] = {}
        for node, dof, coef, port in loads:
            by_port.setdefault(port.name, [port, []])[1].append(coef * velocity(node)[dof])
        for port, flows in by_port.values():
            relations.append(Relation(port.flow - sp.Add(*flows), self.name, "port"))
        # one dissipator per element and node: each power is local, so its quadratic form is cheap to extract
        dissipators = tuple(Dissipator(f"{self.name}.{label}", (), power) for label, power in dissipated)
        tip = pose(n)
        measured = (Measured(f"{self.name}.tip_x", tip[0], "m", "tip position along x"),
                    Measured(f"{self.name}.tip_y", tip[1], "m", "tip position along y"),
                    Measured(f"{self.name}.tip_theta", beta + tip[2], "rad", "direction of the tip cross-section"))
        return Piece(self.name, storages=tuple(storages), energy=tuple(energy), ports=tuple(ports),
                     relations=tuple(relations), dissipators=dissipators, params=params, measured=measured,
                     references=("Simo, Vu-Quoc (1986); Reissner (1972): planar geometrically exact rod",))

    @staticmethod
    def _quadratic_drag(k, c, m, momenta, v, forces, dissipated, v_s) -> None:
        """Add node ``k``'s quadratic drag ``c |v| v`` (``|v| = |p|/m``, smoothed) to its forces and powers."""
        speed = sp.sqrt((momenta[0] ** 2 + momenta[1] ** 2) / m**2 + sp.Float(v_s) ** 2)
        for i in range(2):
            forces[k - 1][i] += c * speed * v[i]
        dissipated.append((f"quadratic_drag{k}", c * speed * (v[0] ** 2 + v[1] ** 2)))

    def _load_ports(self, h, pose, velocity) -> tuple[list[Port], list[tuple]]:
        """Ports asked for and their loads as ``(node, dof, coefficient, port)``: the port's effort times
        the coefficient is a force on dof ``dof`` of ``node``; the port's flow is the matching sum of
        coefficient times velocity."""
        n, ports, loads = self.n, [], []

        def add(local, domain, *entries):
            port = self._port(local, domain)
            ports.append(port)
            loads.extend((node, dof, coef, port) for node, dof, coef in entries)

        if self.tip == "force":
            add("tip_x", "translational", (n, 0, 1))
            add("tip_y", "translational", (n, 1, 1))
        if self.tip == "follower":
            phi = self.beta + pose(n)[2]
            c, s = sp.cos(phi), sp.sin(phi)
            add("tip_t", "translational", (n, 0, c), (n, 1, s))
            add("tip_n", "translational", (n, 0, -s), (n, 1, c))
        if self.tip in ("force", "follower"):
            add("tip_m", "rotational", (n, 2, 1))
        for axis in self.distributed:
            dof = 0 if axis == "x" else 1
            add(f"q{axis}", "translational", *[(k, dof, h / 2 if k == n else h) for k in range(1, n + 1)])
        for k in self.node_forces:
            add(f"fx{k}", "translational", (k, 0, 1))
            add(f"fy{k}", "translational", (k, 1, 1))
        for c in self.couples:
            a, b = (c - 1, c) if isinstance(c, int) else c
            add(f"c{c}" if isinstance(c, int) else f"c{a}_{b}", "rotational", *([(b, 2, 1)] + ([(a, 2, -1)] if a > 0 else [])))
        return ports, loads


__all__ = ["CosseratRod", "element_strains", "TIP_LOADS", "DAMPING"]
