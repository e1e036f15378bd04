"""Meta-tests of the public API (python-control's ``docstrings_test.py`` and ``kwargs_test.py``).

* every name exported in ``__all__`` of ``phs``, ``components``, ``codegen``
  and ``systems`` has a numpydoc docstring with an ``Examples`` section that
  shows code;
* public constructors and entry points reject unknown keyword arguments;
* ``import phs`` (the modelling core) does not import casadi, and ``dir(phs)``
  lists the workflows it loads on first use.
"""

from __future__ import annotations

import inspect
import os
import re
import subprocess
import sys

import numpy as np
import pytest
import sympy as sp

import codegen
import components
import phs
import systems

PACKAGES = [phs, components, codegen, systems]
PUBLIC = [(pkg.__name__, name) for pkg in PACKAGES for name in pkg.__all__]
EXAMPLES = re.compile(r"^\s*Examples\n\s*-{8,}\n(.*?)(^\s*\S.*\n\s*-{3,}\n|\Z)", re.M | re.S)

# Exported names whose docstring has no Examples section yet (STYLE violations, reported).  The
# marker is strict: adding the section makes the test pass unexpectedly, and the name must be
# removed from this list.
MISSING_EXAMPLES: set[str] = set()


def _doc(obj) -> str:
    return (obj.__doc__ if inspect.ismodule(obj) else inspect.getdoc(obj)) or ""


def _public_params():
    for pkg, name in PUBLIC:
        full = f"{pkg}.{name}"
        marks = [pytest.mark.xfail(strict=True, reason=f"STYLE violation: {full} has no Examples section")] \
            if full in MISSING_EXAMPLES else []
        yield pytest.param(pkg, name, id=full, marks=marks)


@pytest.mark.parametrize(("package", "name"), list(_public_params()))
def test_public_name_has_a_docstring_with_examples(package, name):
    obj = getattr(sys.modules[package], name)
    doc = _doc(obj)
    assert doc.strip(), f"{package}.{name} has no docstring"
    m = EXAMPLES.search(doc + "\n")
    assert m, f"{package}.{name}: no 'Examples' section"
    assert ">>>" in m.group(1), f"{package}.{name}: the Examples section shows no code"


def test_all_lists_only_existing_unique_names():
    for pkg in PACKAGES:
        assert len(pkg.__all__) == len(set(pkg.__all__)), pkg.__name__
        for name in pkg.__all__:
            assert hasattr(pkg, name), f"{pkg.__name__}.{name}"


def test_every_exported_component_class_is_in_components_all():
    """Component subclasses defined in the components package are all exported."""
    exported = {getattr(components, n) for n in components.__all__}
    for modname, mod in list(sys.modules.items()):
        if not modname.startswith("components.") or mod is None:
            continue
        for obj in vars(mod).values():
            if (inspect.isclass(obj) and issubclass(obj, phs.Component) and obj.__module__ == modname
                    and not obj.__name__.startswith("_") and not inspect.isabstract(obj)
                    and obj.__module__ != "components._base"):
                assert obj in exported, f"{modname}.{obj.__name__} is not in components.__all__"


# -- unknown keyword arguments ------------------------------------------------------------------------------------
q = sp.Symbol("q", real=True)
th = phs.symbol_of_state("j.theta")
CONSTRUCTORS = {
    "Capacitor": lambda **kw: components.Capacitor("C", C=1e-6, **kw),
    "VariableCapacitor": lambda **kw: components.VariableCapacitor("C", C=sp.Float(1e-6) * (2 + sp.cos(th)), **kw),
    "Inductor": lambda **kw: components.Inductor("L", L=1e-3, **kw),
    "Resistor": lambda **kw: components.Resistor("R", R=1.0, **kw),
    "VoltageSource": lambda **kw: components.VoltageSource("U", **kw),
    "CurrentSource": lambda **kw: components.CurrentSource("I", **kw),
    "DriftBranch": lambda **kw: components.DriftBranch("D", **kw),
    "Mass": lambda **kw: components.Mass("m", m=1.0, **kw),
    "RotationalInertia": lambda **kw: components.RotationalInertia("J", I=1e-6, **kw),
    "LinearSpring": lambda **kw: components.LinearSpring("k", K=1.0, **kw),
    "TorsionalSpring": lambda **kw: components.TorsionalSpring("kb", K=1.0, **kw),
    "NonlinearSpring": lambda **kw: components.NonlinearSpring("s", force=q**3, variable=q, **kw),
    "Damper": lambda **kw: components.Damper("b", b=1.0, **kw),
    "RotationalDamper": lambda **kw: components.RotationalDamper("b", b=1.0, **kw),
    "Gravity": lambda **kw: components.Gravity("g", height=sp.cos(th), **kw),
    "Potential": lambda **kw: components.Potential("pot", sp.cos(th), **kw),
    "ForceSource": lambda **kw: components.ForceSource("F", **kw),
    "TorqueSource": lambda **kw: components.TorqueSource("T", **kw),
    "Transformer": lambda **kw: components.Transformer("tf", 2.0, **kw),
    "Gyrator": lambda **kw: components.Gyrator("gy", 2.0, **kw),
    "Geometry": lambda **kw: components.Geometry("geo", {"tip": sp.sin(th)}, **kw),
    "GeometricConstraint": lambda **kw: components.GeometricConstraint("c", "x", components.geometric_symbol("x")
                                                                       - th, **kw),
    "KinematicChain": lambda **kw: components.KinematicChain("arm", ["j.theta"], lengths=[0.1], masses=[0.1], **kw),
    "ConfigurationInertia": lambda **kw: components.ConfigurationInertia("rod", ["j.theta"], sp.Matrix([[1]]), **kw),
    "PositionLoop": lambda **kw: components.PositionLoop("pd", K_p=10.0, K_d=1.0, **kw),
    "VelocityLoop": lambda **kw: components.VelocityLoop("vc", K_v=1.0, **kw),
    "CosseratRod": lambda **kw: components.CosseratRod("rod", n=2, **kw),
    "HydrogelActuator": lambda **kw: components.HydrogelActuator("sva", **kw),
    "PeanoHasel": lambda **kw: components.PeanoHasel("act", strain=0.02 + 0.01 * th, **kw),
    "Chamber": lambda **kw: components.Chamber("ch", k1=1e9, **kw),
    "FlowSource": lambda **kw: components.FlowSource("q", **kw),
    "PressureTransducer": lambda **kw: components.PressureTransducer("wall", A=1e-5, **kw),
}


def test_every_component_class_has_a_constructor_case():
    classes = {n for n in components.__all__ if inspect.isclass(getattr(components, n))
               and issubclass(getattr(components, n), phs.Component)}
    assert classes <= set(CONSTRUCTORS), f"add constructor cases for {sorted(classes - set(CONSTRUCTORS))}"


@pytest.mark.parametrize("name", sorted(CONSTRUCTORS))
def test_components_reject_unknown_keywords(name):
    assert CONSTRUCTORS[name]().piece() is not None  # the valid call works
    with pytest.raises(TypeError, match="bogus"):
        CONSTRUCTORS[name](bogus=1.0)


def _entry_points(rc):
    t = np.linspace(0.0, 1e-3, 5)
    return {
        "simulate": lambda **kw: codegen.simulate(rc, t, u={"U": 1.0}, **kw),
        "simulator": lambda **kw: codegen.simulator(rc, **kw),
        "generate": lambda **kw: codegen.generate(rc, **kw),
        "equilibrium": lambda **kw: phs.equilibrium(rc, u={"U": 1.0}, **kw),
        "interconnect": lambda **kw: phs.interconnect(
            "x", [components.VoltageSource("U"), components.Resistor("R", R=1.0), components.Capacitor("C")],
            [phs.series("U", "R", "C")], **kw),
        "PHSystem": lambda **kw: phs.PHSystem("s", ["q"], q**2 / 2, J=[[0]], R=[[0]], **kw),
        "Param": lambda **kw: phs.Param("k", 1.0, "N/m", **kw),
        "with_params": lambda **kw: rc.with_params(**kw),
        "square": lambda **kw: phs.signals.square(1.0, 1.0, **kw),
        "rc_circuit": lambda **kw: systems.rc_circuit(**kw),
    }


@pytest.mark.parametrize("name", ["simulate", "simulator", "generate", "equilibrium", "interconnect", "PHSystem",
                                  "Param", "square", "rc_circuit"])
def test_entry_points_reject_unknown_keywords(rc, name):
    call = _entry_points(rc)[name]
    call()  # the valid call works
    with pytest.raises(TypeError, match="bogus"):
        call(bogus=1.0)


def test_keyword_overrides_reject_unknown_names(rc):
    """Entry points taking parameter values by keyword reject names that are not parameters."""
    with pytest.raises(phs.ParameterError, match="bogus"):
        rc.with_params(bogus=1.0)
    for build in (systems.curling_hasel, systems.manta_ray_fin):
        with pytest.raises((TypeError, phs.PHSError), match="bogus"):
            build(bogus=1.0)


def test_importing_the_core_does_not_import_casadi():
    code = "import sys, phs, components, systems; sys.exit('casadi' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 0


def test_dir_lists_the_lazy_workflows_without_importing_them():
    """Tab completion finds ``phs.simulate`` and the other workflows; listing them imports nothing."""
    code = ("import sys, phs; names = dir(phs); "
            "assert {'simulate', 'identify', 'diagnose', 'sweep', 'Recording'} <= set(names), names; "
            "assert names == sorted(names) and 'PHSystem' in names and 'load' in names; "
            "assert 'casadi' not in sys.modules; "
            "assert all(hasattr(phs, n) for n in phs.__all__)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_every_property_test_is_derandomized_and_writes_no_database():
    """Each ``@given`` test, with its own ``@settings`` merged over the profile of ``tests/conftest.py``,
    draws the same examples on every run and keeps no example database in the checkout."""
    import importlib
    import pathlib

    if os.environ.get("HYPOTHESIS_PROFILE", "ci") != "ci":
        pytest.skip("another hypothesis profile was chosen")
    root = pathlib.Path(__file__).parent
    found = 0
    for path in sorted(root.rglob("test_*.py")):
        if "@given" not in path.read_text():
            continue
        name = ".".join(path.relative_to(root.parent).with_suffix("").parts)
        module = sys.modules.get(name) or importlib.import_module(name)
        for attr in vars(module).values():
            s = getattr(attr, "_hypothesis_internal_use_settings", None)
            if s is not None and getattr(attr, "is_hypothesis_test", False):
                found += 1
                assert s.derandomize and s.database is None, f"{name}.{attr.__name__}: {s}"
    assert found >= 13
