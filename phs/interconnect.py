"""Power-preserving interconnection of components into an explicit PHSystem.

The pieces' ports are joined by junctions (:func:`phs.series`,
:func:`phs.parallel`, :func:`phs.bond`); the junction equations, the resistive
laws and the transformer/gyrator relations are linear in the port variables.
They are solved block by block for every state's rate and every source's
conjugate output in terms of the co-energies ``dH/dx`` and the inputs ``u``:

    [ x' ]   [ A  B ] [ dH/dx ]
    [ y  ] = [ C  D ] [   u   ]

and split into the input-state-output port-Hamiltonian form with feedthrough,
``J = skew(A)``, ``R = -sym(A)``, ``G = (B + C^T)/2``, ``P = (C^T - B)/2``,
``S = sym(D)``, ``N = skew(D)``.  Because junctions, transformers and
gyrators conserve power and resistors dissipate it, ``[[R, P], [P^T, S]]``
is the sum of the resistors' dissipation forms and is positive semidefinite.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import replace

import sympy as sp
from sympy.core.exprtools import factor_terms
from sympy.simplify.simplify import signsimp

from phs._linsolve import StructuralProblem, solve_blt
from phs._sparse import nonzero_entries
from phs.component import Component, Piece, Port
from phs.errors import InterconnectionError, ModelError
from phs.junctions import Junction
from phs.params import Condition, EnergyTerm, Measured, Param
from phs.subsystem import subsystem_piece
from phs.system import PHSystem


def interconnect(
    name: str,
    components,
    connections=(),
    *,
    params=(),
    measured=(),
    conditions=(),
    description: str = "",
) -> PHSystem:
    """Assemble components into an explicit port-Hamiltonian system.

    Parameters
    ----------
    name : str
        Name of the system (used for generated functions ``{name}_rhs``).
    components : sequence of Component or PHSystem
        The building blocks.  A PHSystem is embedded as a component whose
        ports are its inputs (port ``{system}.{input}``).
    connections : sequence of Junction
        Junctions from :func:`series`, :func:`parallel`, :func:`bond`.
    params : sequence of Param
        Shared parameters used inside component expressions.
    measured : sequence of Measured or (name, expr) pairs
        Measured outputs: functions of states and inputs.
    conditions : sequence of Condition
        Extra validity conditions (``expr >= 0``).
    description : str
        One paragraph describing the model.

    Returns
    -------
    PHSystem

    Raises
    ------
    InterconnectionError
        Naming the components and ports involved when a port is unconnected
        or connected twice, storages are dependent, or a name is unknown.

    Examples
    --------
    >>> from components import VoltageSource, Resistor, Capacitor
    >>> from phs import series
    >>> rc = interconnect("rc", [VoltageSource("U"), Resistor("R0", R=1e3), Capacitor("C", C=1e-6)],
    ...                   [series("U", "R0", "C")])
    >>> rc.R[0, 0], rc.S[0, 0]
    (1/R0.R, 1/R0.R)
    """
    pieces = [_piece_of(c) for c in components]
    return _assemble(name, pieces, list(connections), list(params), list(measured), list(conditions), description)


def _piece_of(c) -> Piece:
    if isinstance(c, PHSystem):
        return subsystem_piece(c)
    if isinstance(c, Component):
        try:
            return c.piece()
        except ModelError:
            raise
        except Exception as exc:  # a user component failing inside sympy
            raise ModelError(f"component {c.name!r} could not build its piece: {exc}") from exc
    raise InterconnectionError(f"{c!r} is neither a Component nor a PHSystem")


def _assemble(name, pieces, connections, extra_params, measured, conditions, description) -> PHSystem:
    problems: list[str] = []
    # -- names ----------------------------------------------------------------
    seen_comp: set[str] = set()
    for pc in pieces:
        if pc.name in seen_comp:
            problems.append(f"component name {pc.name!r} is used twice")
        seen_comp.add(pc.name)
    params: dict[str, Param] = {}
    for p in extra_params + [p for pc in pieces for p in pc.params]:
        if not isinstance(p, Param):
            problems.append(f"{p!r} in params is not a Param")
            continue
        old = params.get(p.name)
        if old is not None and old != p:
            problems.append(f"parameter {p.name!r} is declared twice with different values/units "
                            f"({old.value} {old.unit} vs {p.value} {p.unit})")
        params.setdefault(p.name, p)
    storages = [s for pc in pieces for s in pc.storages]
    state_owner: dict[str, str] = {}
    for pc in pieces:
        for s in pc.storages:
            if s.state.name in state_owner:
                problems.append(f"state {s.state.name!r} is owned by both {state_owner[s.state.name]!r} and {pc.name!r}")
            state_owner[s.state.name] = pc.name
    sources = [s for pc in pieces for s in pc.sources]
    input_owner: dict[str, str] = {}
    for pc in pieces:
        for s in pc.sources:
            if s.info.name in input_owner:
                problems.append(f"input {s.info.name!r} is declared by both {input_owner[s.info.name]!r} and {pc.name!r}")
            input_owner[s.info.name] = pc.name
    if problems:
        raise InterconnectionError(f"cannot assemble {name!r}", problems)

    # -- ports ----------------------------------------------------------------
    ports: dict[str, Port] = {}
    by_comp: dict[str, list[Port]] = defaultdict(list)
    for pc in pieces:
        for p in pc.ports:
            ports[p.name] = p
            by_comp[pc.name].append(p)

    named: dict[str, Junction] = {}

    def collect(j: Junction):
        if j.name:
            if j.name in named and named[j.name] is not j:
                problems.append(f"two junctions are named {j.name!r}")
            if j.name in ports or j.name in by_comp:
                problems.append(f"junction name {j.name!r} clashes with a component or port")
            named[j.name] = j
        for m in j.members:
            if isinstance(m, Junction):
                collect(m)

    for j in connections:
        if not isinstance(j, Junction):
            raise InterconnectionError(f"connection {j!r} is not a junction; build it with series(), parallel() or bond()")
        collect(j)

    equations: list[sp.Expr] = []
    eq_where: list[str] = []
    used: dict[str, str] = {}
    bond_vars: list[sp.Symbol] = []
    junction_members: dict[int, tuple] = {}

    def resolve(ref: str, where: str) -> Port | None:
        if ref in ports:
            return ports[ref]
        if ref in by_comp:
            cand = by_comp[ref]
            if len(cand) == 1:
                return cand[0]
            problems.append(f"{where}: component {ref!r} has several ports ({', '.join(p.name for p in cand)}); name one")
            return None
        problems.append(f"{where}: no port, component or junction named {ref!r}")
        return None

    def ensure(j: Junction) -> None:
        """Register a junction once; members that are junctions are joined by a bond."""
        if id(j) in junction_members:
            return
        jdesc = j.describe()
        members: list[tuple[sp.Symbol, sp.Symbol, int]] = []  # (e, f, +1 if power enters the junction)
        junction_members[id(j)] = (j, members, jdesc)
        for m in j.members:
            key = m.lstrip("-") if isinstance(m, str) else None
            target = m if isinstance(m, Junction) else (named.get(key) if key not in ports and key not in by_comp else None)
            if target is not None:
                k = len(bond_vars) // 2
                e, f = sp.Symbol(f"e[bond{k}]", real=True), sp.Symbol(f"f[bond{k}]", real=True)
                bond_vars.extend([e, f])
                flip = -1 if isinstance(m, str) and m.startswith("-") else 1
                members.append((flip * e, flip * f, -1))  # reversed: the parent sees (-e, -f)
                ensure(target)
                junction_members[id(target)][1].append((e, f, +1))
                continue
            p = resolve(key, jdesc)
            if p is None:
                continue
            if p.name in used:
                problems.append(f"port {p.name!r} is connected twice: in {used[p.name]} and in {jdesc}")
                continue
            used[p.name] = jdesc
            sign = +1 if p.supplies else -1
            # a reversed member (terminals swapped) appears to the junction as (-e, -f): same power
            flip = -1 if m.startswith("-") else 1
            members.append((flip * p.effort, flip * p.flow, sign))

    for j in connections:
        ensure(j)
    for j, members, jdesc in junction_members.values():
        if j.kind == "L":
            (e1, f1, _), (e2, f2, _) = members[:2]
            p1, p2 = (ports[m.lstrip("-")] if m.lstrip("-") in ports else by_comp[m][0] for m in j.members)
            imp1, con1 = (e1, f1) if (p1.causality or "effort") == "effort" else (f1, e1)
            imp2, con2 = (e2, f2) if (p2.causality or "effort") == "effort" else (f2, e2)
            equations.extend([imp1 + con2, imp2 - con1])
            eq_where.extend([jdesc, jdesc])
            continue
        common = 1 if j.kind == "1" else 0  # 1-junction: common flow; 0-junction: common effort
        other = 1 - common
        first = members[0][common] if members else None
        for mbr in members[1:]:
            equations.append(mbr[common] - first)
            eq_where.append(jdesc)
        if members:
            equations.append(sum(mbr[2] * mbr[other] for mbr in members))
            eq_where.append(jdesc)

    for p in ports.values():
        if p.name not in used:
            problems.append(
                f"port {p.name!r} of component {p.component!r} is not connected; add it to a series()/parallel() junction"
            )
    if problems:
        raise InterconnectionError(f"cannot assemble {name!r}", problems)

    # -- definitions (geometric variables) -------------------------------------
    defs = {d.symbol: d.expr for pc in pieces for d in pc.definitions}
    defs = _resolve_definitions(defs, name)

    def subst(e):
        return e.xreplace(defs) if defs else e

    for pc in pieces:
        for r in pc.relations:
            equations.append(subst(r.expr))
            eq_where.append(f"component {r.component!r} ({r.kind})")

    # -- solve ------------------------------------------------------------------
    co = {s.coenergy: s for s in storages}
    imposed = {s.imposed: s for s in sources}
    knowns = set(co) | set(imposed)
    all_ports = dict(ports)
    for pc in pieces:
        for p in list(pc.internal) + [s.port for s in pc.storages]:
            all_ports.setdefault(p.name, p)
    allvars = [v for p in all_ports.values() for v in (p.effort, p.flow)] + bond_vars
    unknowns = [v for v in allvars if v not in knowns]
    try:
        sol = solve_blt(equations, unknowns)
    except StructuralProblem as sp_err:
        raise InterconnectionError(f"cannot assemble {name!r}: {_explain(sp_err, equations, eq_where, co, all_ports)}") from None

    def val(v):
        return v if v in knowns else sol[v]

    coenergy_syms = [s.coenergy for s in storages]
    input_syms = [s.imposed for s in sources]
    rates = sp.Matrix([val(s.rate) for s in storages])
    outs = sp.Matrix([val(s.conjugate) for s in sources])
    n, m = len(storages), len(sources)
    zsyms = coenergy_syms + input_syms
    tidy = _memo(_tidy_entry)  # element-wise models repeat the same coefficients: tidy each once
    A = _jac(rates, coenergy_syms, tidy)
    B = _jac(rates, input_syms, tidy) if m else sp.zeros(n, 0)
    C = _jac(outs, coenergy_syms, tidy) if m else sp.zeros(0, n)
    D = _jac(outs, input_syms, tidy) if m else sp.zeros(0, 0)
    leftover = (rates.free_symbols | outs.free_symbols) & (set(unknowns) | set(zsyms))
    for M in (A, B, C, D):
        if M.free_symbols & (set(unknowns) | set(zsyms)):
            raise ModelError(f"{name!r}: the port relations are not linear in the port variables ({leftover})")
    J = _half(A - A.T, tidy)
    R = _half(-(A + A.T), tidy)
    G = _half(B + C.T, tidy)
    P = _half(C.T - B, tidy)
    S = _half(D + D.T, tidy)
    N = _half(D - D.T, tidy)

    # dissipators: quadratic forms in z = [dH/dx; u]
    zindex = {z: i for i, z in enumerate(zsyms)}
    zset = set(zsyms)
    diss = []
    for pc in pieces:
        for d in pc.dissipators:
            if d.power is not None:
                power = d.power.xreplace({v: val(v) for v in d.power.free_symbols if v in knowns or v in sol})
            else:
                power = sum((val(p.effort) * val(p.flow) for p in d.ports), sp.Integer(0))
            entries = {}
            zs = sorted(power.free_symbols & zset, key=lambda z: zindex[z])
            first = {z: sp.diff(power, z) for z in zs}  # once per variable, shared by the pairs
            for a in range(len(zs)):
                for b in range(a, len(zs)):
                    h = tidy(_second_derivative(power, first, zs[a], zs[b]) / 2)
                    if h != 0:
                        entries[(zindex[zs[a]], zindex[zs[b]])] = h
            diss.append((d.label, entries))

    # -- energy, outputs, conditions --------------------------------------------
    energy = [EnergyTerm(t.label, subst(t.expr)) for pc in pieces for t in pc.energy]
    meas = []
    for mo in [mo for pc in pieces for mo in pc.measured] + measured:
        if isinstance(mo, tuple):
            mo = Measured(mo[0], mo[1])
        meas.append(replace(mo, expr=subst(_expression(mo.expr, f"measured output {mo.name!r} of {name!r}"))))
    conds = [Condition(c.label, subst(c.expr), c.description) for pc in pieces for c in pc.conditions]
    conds += [Condition(c.label, subst(c.expr), c.description) for c in conditions]

    return PHSystem(
        name,
        states=[s.state for s in storages],
        H=energy,
        J=J,
        R=R,
        G=G,
        P=P,
        S=S,
        N=N,
        inputs=[s.info for s in sources],
        params=list(params.values()),
        measured=meas,
        conditions=conds,
        dissipators=diss,
        definitions=[(d.symbol, subst(d.expr), d.label) for pc in pieces for d in pc.definitions],
        description=description,
        structure={"components": [pc.name for pc in pieces], "connections": [j.describe() for j in connections]},
    )


def _memo(f):
    """``f`` remembering its results by argument (sympy expressions compare and hash by structure)."""
    cache: dict = {}

    def call(e):
        try:
            return cache[e]
        except KeyError:
            r = cache[e] = f(e)
            return r

    return call


def _second_derivative(expr: sp.Expr, first: dict, a: sp.Symbol, b: sp.Symbol) -> sp.Expr:
    """``sp.diff(expr, a, b)`` reusing the first derivatives ``first[z] = sp.diff(expr, z)``.

    sympy differentiates in its canonical order of the variables and tidies a derivative of order
    two with ``factor_terms(signsimp(.))``; both are reproduced, so the result is the one
    ``sp.diff(expr, a, b)`` gives.  A repeated variable (``a == b``) is left to sympy, whose
    derivative of order two of a product is not two first derivatives in a row.
    """
    if a == b:
        return sp.diff(expr, a, b)
    (v1, _), (v2, _) = sp.Derivative._sort_variable_count([(a, 1), (b, 1)])
    d1 = first[v1]
    if d1.is_zero:
        return d1
    d2 = sp.diff(d1, v2)
    if d2.is_zero:
        return d2
    if d2.has(sp.Derivative):  # sympy makes unevaluated derivatives canonical first: leave that to it
        return sp.diff(expr, a, b)
    return factor_terms(signsimp(d2))


def _jac(vec: sp.Matrix, syms, tidy) -> sp.Matrix:
    sset = set(syms)
    idx = {s: j for j, s in enumerate(syms)}
    out = sp.zeros(vec.rows, len(syms))
    for i in range(vec.rows):
        e = sp.expand(vec[i], deep=False, mul=True, multinomial=False, power_exp=False, power_base=False, log=False)
        for s in e.free_symbols & sset:
            out[i, idx[s]] = tidy(sp.diff(e, s))
    return out


def _half(M: sp.Matrix, tidy) -> sp.Matrix:
    """``M / 2`` entry by entry, tidied; only the nonzero entries are visited."""
    out = sp.zeros(M.rows, M.cols)
    for i, j, v in nonzero_entries(M):
        out[i, j] = tidy(v / 2)
    return out


def _tidy_entry(e: sp.Expr) -> sp.Expr:
    if e == 0 or e.is_Atom:
        return e
    try:
        c = sp.cancel(sp.together(e))
    except (sp.PolynomialError, TypeError, ValueError):
        return e
    if c == 0:
        return sp.Integer(0)
    return c if sp.count_ops(c) <= sp.count_ops(e) + 2 else e


def _resolve_definitions(defs: dict, name: str) -> dict:
    """Substitute definitions into each other until none refers to another."""
    out = dict(defs)
    for _ in range(len(out) + 1):
        changed = False
        for k, v in out.items():
            if v.free_symbols & out.keys():
                out[k] = v.xreplace(out)
                changed = True
        if not changed:
            return out
    cyc = [str(k) for k, v in out.items() if v.free_symbols & out.keys()]
    raise InterconnectionError(f"{name!r}: geometric definitions refer to each other in a cycle: {', '.join(cyc)}")


def _explain(err: StructuralProblem, equations, eq_where, co, ports) -> str:
    port_of = {}
    for p in ports.values():
        port_of[p.effort] = p.name
        port_of[p.flow] = p.name
    if err.kind == "overdetermined":
        involved = set()
        where = set()
        for i in err.equations:
            where.add(eq_where[i])
            for s in equations[i].free_symbols:
                if s in co:
                    involved.add(co[s].state.name)
        if involved:
            return (
                "storages " + ", ".join(sorted(involved)) + " are dependent: "
                + "; ".join(sorted(where))
                + " ties their co-energies (e.g. two capacitors in parallel, or two masses moving with one velocity). "
                "Merge them into one storage, put a resistor or spring between them, or use a KinematicChain"
            )
        return "the connections over-determine the port variables in " + "; ".join(sorted(where))
    if err.kind == "underdetermined":
        names = sorted({port_of.get(u, str(u)) for u in err.unknowns})
        return (
            "the port variables of " + ", ".join(names) + " are not determined by the connections "
            "(a loop of sources/transformers only, or a port that needs a storage or resistor)"
        )
    where = sorted({eq_where[i] for i in err.equations})
    if err.kind == "singular":
        return "the equations of " + "; ".join(where) + " are singular (a degenerate transformer ratio or a resistor of value zero?)"
    return "the relations of " + "; ".join(where) + " are not linear in the port variables"


def _expression(value, where: str) -> sp.Expr:
    """``value`` as a sympy expression: a sympy object or a number, never a string (a string would be
    parsed by ``eval``; expressions from files go through :mod:`phs.safe_parse`).

    Examples
    --------
    >>> _expression(2, "x"), _expression(sp.Symbol("q") ** 2, "x")
    (2, q**2)
    """
    try:
        return sp.sympify(value, strict=True)
    except sp.SympifyError:
        raise ModelError(f"{where}: expected a sympy expression or a number, got {type(value).__name__} {value!r}") from None
