"""Every ready-made system passes the dimensional analysis of its whole structure (phs.structure_units): J, R, G,
P, S, N, its ports and its measured outputs agree with its states' and ports' units (the constructor refuses a
model where its declared units decide otherwise: each system below is built).

Reduced sizes (2 segments, shells, stages, 1 hydrogel segment with 2 actuators): the entries are the same
per segment, so a unit error of the full model shows up in the small one; the full sizes run under -m slow.
"""

from __future__ import annotations

from importlib import import_module

import pytest

from phs.structure_units import structure_unit_problems

# the modules (``systems`` exports functions of the same names)
catheter_bender, curling_hasel, electrostatic_actuator, examples, hydrogel_arm, lab, manta_ray_fin, msd_hasel, \
    peano_swimmer = (import_module(f"systems.{m}") for m in (
        "catheter_bender", "curling_hasel", "electrostatic_actuator", "examples", "hydrogel_arm", "lab",
        "manta_ray_fin", "msd_hasel", "peano_swimmer"))

SYSTEMS = {
    "catheter_bender": lambda: catheter_bender.catheter_bender(),
    "catheter_bender_constrained": lambda: catheter_bender.catheter_bender("constrained"),
    "curling_hasel_2": lambda: curling_hasel.curling_hasel(2),
    "electrostatic_actuator": electrostatic_actuator.electrostatic_actuator,
    "duffing_oscillator": examples.duffing_oscillator,
    "mass_spring_damper": examples.mass_spring_damper,
    "pd_servo": examples.pd_servo,
    "rc_circuit": examples.rc_circuit,
    "rlc_circuit": examples.rlc_circuit,
    "air_chamber": lab.air_chamber,
    "emps_stage": lab.emps_stage,
    "emps_stage_matrices": lab.emps_stage_matrices,
    "seal_friction_rig": lab.seal_friction_rig,
    "manta_ray_fin_2": lambda: manta_ray_fin.manta_ray_fin(2),
    "msd_hasel": msd_hasel.msd_hasel,
    "peano_swimmer": peano_swimmer.peano_swimmer,
    "hydrogel_arm_small": lambda: hydrogel_arm.hydrogel_arm(per_segment=1, svas=(1, 2)),
}
FULL = {
    "curling_hasel": curling_hasel.curling_hasel,
    "manta_ray_fin": manta_ray_fin.manta_ray_fin,
    "hasel_platform": msd_hasel.hasel_platform,
    "hydrogel_arm": hydrogel_arm.hydrogel_arm,
}


@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_ready_made_systems_have_consistent_units(name):
    problems, _ = structure_unit_problems(SYSTEMS[name]())
    assert problems == []


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FULL))
def test_ready_made_systems_at_full_size_have_consistent_units(name):
    system = FULL[name]()
    assert structure_unit_problems(system)[0] == []
    assert system.check(samples=50)["units"].verdict == "pass"


def test_cascaded_tanks_units():
    """Its volumes (m**3) were once read as levels (m) through a bare cross-section 1 in the energy, the orifices
    and the level sensor (the constructor now refuses such a model): with the cross-section A (1 m**2) a
    parameter, every term has its unit, energy included."""
    system = lab.cascaded_tanks()
    assert structure_unit_problems(system) == ([], 0)
    assert system.check(samples=20)["units"].verdict == "pass"
