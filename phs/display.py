"""Text summary and LaTeX rendering of a PHSystem."""

from __future__ import annotations

import sympy as sp


def _latex_name(name: str) -> str:
    parts = name.split(".")
    base = sp.latex(sp.Symbol(parts[-1]))
    if len(parts) == 1:
        return base
    return base + r"^{\mathrm{" + ".".join(parts[:-1]).replace("_", r"\_") + "}}"


def _names(system) -> dict:
    out = {s.symbol: _latex_name(s.name) for s in system.states}
    out.update({q.symbol: _latex_name(q.name) for q in system.params})
    out.update({u.symbol: _latex_name(u.name) for u in system.inputs})
    return out


def latex(system) -> str:
    """LaTeX of the structure: x' = (J - R) grad H + (G - P) u, y, and H."""
    names = _names(system)

    def L(e):
        return sp.latex(e, symbol_names=names)

    x = sp.Matrix(system.x)
    parts = [
        r"\begin{aligned}",
        r"\dot x &= \left(" + L(system.J - system.R) + r"\right)\nabla H" + (
            r" + " + L(system.G - system.P) + r"\,u" if system.inputs else ""
        ) + r"\\",
        r"x &= " + L(x) + r"\\",
    ]
    if system.inputs:
        parts.append(r"y &= " + L((system.G + system.P).T) + r"\nabla H + " + L(system.S + system.N)
                     + r"\,u,\quad u = " + L(sp.Matrix(system.u)) + r"\\")
    parts.append(r"H &= " + L(system.H))
    parts.append(r"\end{aligned}")
    return "$$" + "\n".join(parts) + "$$"


def summary(system) -> str:
    """Readable multi-line description of states, inputs, parameters, energy and structure."""
    lines = [f"PHSystem {system.name!r}" + (f": {system.description}" if system.description else "")]
    lines.append(f"  states ({len(system.states)}):")
    for s in system.states:
        lines.append(f"    {s.name:<22} [{s.unit}]  range {s.range[0]:.4g} .. {s.range[1]:.4g}  {s.description}")
    lines.append(f"  inputs ({len(system.inputs)}):")
    for u in system.inputs:
        lines.append(f"    {u.name:<22} [{u.unit}] ({u.kind}) -> output {u.output} [{u.output_unit}]")
    if system.measured:
        lines.append(f"  measured outputs ({len(system.measured)}):")
        for mo in system.measured:
            lines.append(f"    {mo.name:<22} [{mo.unit}]  {mo.description}")
    lines.append(f"  parameters ({len(system.params)}):")
    for q in system.params:
        lines.append(f"    {q.name:<22} = {q.value:.6g} {q.unit}  {q.description}")
    lines.append("  energy:")
    for t in system.energy_terms:
        txt = str(t.expr)
        lines.append(f"    {t.label:<22} {txt if len(txt) < 90 else txt[:87] + '...'}")
    nz = lambda M: sum(1 for v in M if v != 0)  # noqa: E731
    lines.append(f"  structure: J {nz(system.J)} nonzeros, R {nz(system.R)}, G {nz(system.G)}, P {nz(system.P)}, S {nz(system.S)}")
    if system.dissipators:
        lines.append("  dissipators: " + ", ".join(label for label, _ in system.dissipators))
    if system.conditions:
        lines.append(f"  validity conditions ({len(system.conditions)}): " + "; ".join(c.label for c in system.conditions[:6])
                     + (" ..." if len(system.conditions) > 6 else ""))
    return "\n".join(lines)


def param_table(params) -> str:
    """Markdown table of parameters (name, value, unit, range, description).

    ``params`` is a PHSystem or a sequence of Param; docs tables are generated
    with it, never retyped.

    Examples
    --------
    >>> from phs import Param
    >>> print(param_table([Param("K_b", 0.04, "N*m/rad", "torsional stiffness")]))
    | parameter | value | unit | range | description |
    | --- | --- | --- | --- | --- |
    | `K_b` | 0.04 | N*m/rad | 0.004 .. 0.4 | torsional stiffness |
    """
    items = getattr(params, "params", params)
    lines = ["| parameter | value | unit | range | description |", "| --- | --- | --- | --- | --- |"]
    for q in items:
        lines.append(f"| `{q.name}` | {q.value:.6g} | {q.unit} | {q.range[0]:.4g} .. {q.range[1]:.4g} | {q.description} |")
    return "\n".join(lines)
