"""The control law of an IDA-PBC controller and the closed loop's functions, in CasADi.

From the design model's generated expressions at the controller's parameter
values and the solved structure (``H_a``, ``J_a``, ``R_a`` and, when ``Phi`` has no
closed form, its gradient ``v``), :func:`functions` builds the law
``u = (g^T g)^-1 g^T [(J_d - R_d) dH_d/dx - (J - R) dH/dx - f_fix]`` with its
integral action, the passive output ``y_d = g^T dH_d/dx``, ``H_d`` and the
Jacobians the certificates linearise.  The controller caches them
(:attr:`codegen.idapbc.Controller.law_function`).
"""

from __future__ import annotations

import casadi as ca

from codegen.translate import Translator


def functions(ctrl) -> dict:
    """CasADi functions of the controller: law, passive output, H_d (explicit part), v, closed-loop rhs.

    Keys: ``law`` (``{name}_law(x, xi) -> u``), ``u_full`` (every plant input), ``yd`` / ``yd_xi`` (passive
    output), ``xi_rate``, ``Hd`` / ``Hd_export`` (explicit part of ``H_d``), ``dHd``, ``v``, ``target``
    (``(J_d - R_d) dH_d/dx``), ``plant`` (the closed loop's rate), ``Rd``, ``Jd``, ``g``, ``f0``, ``u_c``, and the
    Jacobians ``cl_jac``, ``hess``, ``yd_jac``.

    Examples
    --------
    >>> from codegen.idapbc import design
    >>> from systems.examples import mass_spring_damper
    >>> fx = functions(design(mass_spring_damper(), {"position": 0.5}, damping=1.0))
    >>> fx["law"].name(), round(float(fx["law"]([0.0, 0.5], [])), 9)   # at rest at x*: u = u* = k q*
    ('msd_law', 2.0)
    """
    s, num = ctrl.system, ctrl.num
    fn = num.fn
    sx = fn.sx
    n = num.n
    X = ca.SX.sym("x", n)
    P = ca.DM(num.p)
    sub = lambda e: ca.substitute(ca.substitute(e, sx["p"], P), sx["x"], X)  # noqa: E731
    u_fix = ca.DM(ctrl.u_base)
    H = sub(sx["H"])
    dH = sub(sx["dH"])
    J, R, G, Pm = (sub(sx[k]) for k in ("J", "R", "G", "P"))
    Gm = G - Pm
    ctrl_idx = list(ctrl.ctrl)
    fixed = [j for j in range(num.m) if j not in ctrl_idx]
    g = Gm[:, ctrl_idx]
    f0 = ca.mtimes(J - R, dH) + (ca.mtimes(Gm[:, fixed], u_fix[fixed]) if fixed else 0)
    tr = Translator({xi: X[i] for i, xi in enumerate(s.x)})
    st = ctrl.structure
    Ha = tr(st.H_a) if st.H_a != 0 else ca.SX(0)
    v = tr(st.v) if st.v is not None else ca.SX.zeros(n, 1)
    dHd = dH + ca.gradient(Ha, X) + v
    Jd = J + tr(st.J_a)
    Rd = R + tr(st.R_a)
    target = ca.mtimes(Jd - Rd, dHd)
    u_c = ca.solve(ca.mtimes(g.T, g), ca.mtimes(g.T, target - f0))
    yd = ca.mtimes(g.T, dHd)
    nxi = ctrl.n_xi
    Xi = ca.SX.sym("xi", nxi)
    ystar = ca.DM([t.value for t in ctrl.targets])
    if ctrl.integral == "passive":
        u_law = u_c - ca.mtimes(ca.DM(ctrl.K_i), Xi)
        xi_rate = yd
    elif ctrl.integral == "output":
        u_law = u_c + ca.mtimes(ca.DM(ctrl.K_i), Xi)
        xi_rate = ystar - _target_sx(ctrl, X, _full_u(num.m, ctrl_idx, u_law, u_fix), sub)
    else:
        u_law = u_c
        xi_rate = ca.SX(0, 1)
    u_full = _full_u(num.m, ctrl_idx, u_law, u_fix)
    xdot = ca.substitute(ca.substitute(sx["xdot"], sx["p"], P), ca.vertcat(sx["x"], sx["u"]), ca.vertcat(X, u_full))
    name = ctrl.name
    out = {
        "law": ca.Function(f"{name}_law", [X, Xi], [u_law], ["x", "xi"], ["u"]),
        "u_full": ca.Function("u_full", [X, Xi], [u_full]),
        "yd": ca.Function("yd", [X], [yd]),
        "yd_xi": ca.Function(f"{name}_passive_output", [X], [yd], ["x"], ["y_d"]),
        "xi_rate": ca.Function("xi_rate", [X, Xi], [xi_rate]),
        "Hd": ca.Function("Hd", [X], [H + Ha]),
        "Hd_export": ca.Function(f"{name}_hd", [X], [H + Ha], ["x"], ["H_d_explicit"]),
        "dHd": ca.Function("dHd", [X], [dHd]),
        "v": ca.Function("v", [X], [v]),
        "target": ca.Function("target", [X], [target]),
        "plant": ca.Function("plant", [X, Xi], [xdot]),
        "Rd": ca.Function("Rd", [X], [Rd]),
        "Jd": ca.Function("Jd", [X], [Jd]),
        "g": ca.Function("g", [X], [g]),
        "f0": ca.Function("f0", [X], [f0]),
        "u_c": ca.Function("u_c", [X], [u_c]),
    }
    aug = ca.vertcat(xdot, xi_rate)
    Z = ca.vertcat(X, Xi)
    out["cl_jac"] = ca.Function("cl_jac", [X, Xi], [ca.jacobian(aug, Z)])
    out["hess"] = ca.Function("hessian_hd", [X], [ca.jacobian(dHd, X)])
    out["yd_jac"] = ca.Function("yd_jac", [X], [ca.jacobian(yd, X)])
    return out


def _full_u(m, ctrl_idx, u_c, u_fix):
    parts = []
    k = 0
    for j in range(m):
        if j in ctrl_idx:
            parts.append(u_c[ctrl_idx.index(j)])
            k += 1
        else:
            parts.append(u_fix[j])
    return ca.vertcat(*parts) if parts else ca.SX(0, 1)


def _target_sx(ctrl, X, u, sub):
    """The targets as SX of the design state (and input, for measured outputs that use it)."""
    sx = ctrl.num.fn.sx
    meas = ca.substitute(ca.substitute(sx["measured"], sx["p"], ca.DM(ctrl.num.p)), ca.vertcat(sx["x"], sx["u"]),
                         ca.vertcat(X, u)) if ctrl.system.measured else ca.SX(0, 1)
    parts = [X[t.index] if t.kind == "state" else meas[t.index] for t in ctrl.targets]
    return ca.vertcat(*parts)
