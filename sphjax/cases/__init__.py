"""Ready-to-run set-ups: ``sphjax.cases.<name>(...) -> Case``.

Each case takes a resolution argument and physical parameters with the defaults of its
reference (cited in its docstring), and returns a :class:`sphjax.Case` (initial State, static Model,
differentiable Params, a stable time step and a default end time).
"""

from __future__ import annotations

import inspect

from sphjax.cases._resolution import n_for_spacing
from sphjax.cases.cavity import lid_driven_cavity
from sphjax.cases.channel import channel_flow
from sphjax.cases.fluid import (
    DAM_BREAK_WALL_SENSORS,
    dam_break,
    dam_break_impact,
    dam_break_wall_sensors,
    hydrostatic_tank,
    poiseuille,
    poiseuille_startup_speed,
    taylor_green,
    taylor_green_velocity,
)
from sphjax.cases.fluid3d import (
    abc_flow_3d,
    abc_pressure,
    abc_velocity,
    dam_break_3d,
    duct_poiseuille_3d,
    duct_velocity,
    hydrostatic_tank_3d,
    spheric_dam_break_3d,
    water_height,
)
from sphjax.cases.fsi import (
    dam_break_elastic_obstacle,
    elastic_gate_dam_break,
    hydrostatic_fsi_plate,
    hydrostatic_fsi_plate_3d,
    midspan_deflection,
    plate_deflection_reference,
)
from sphjax.cases.rigid import (
    body_bottom,
    body_velocity,
    floating_body,
    settling_disk,
    sinking_body,
)
from sphjax.cases.setup_file import SetupError, from_toml
from sphjax.cases.solid import (
    oscillating_plate,
    plate_mode_shape,
    plate_reference,
    plate_sound_speed,
    relax_to_rest,
    turek_hron_csm,
)
from sphjax.cases.solid3d import beam_angular_frequency, cantilever_3d, cantilever_reference
from sphjax.observables import (
    centreline_profiles,
    channel_mass_flux,
    channel_profile,
    channel_startup_profile,
    oscillation_stats,
    poiseuille_centreline_speed,
    poiseuille_profile,
    probe_pressure,
    surge_front,
    tip_displacement,
)

CASES = {
    "taylor_green": taylor_green,
    "poiseuille": poiseuille,
    "lid_driven_cavity": lid_driven_cavity,
    "hydrostatic_tank": hydrostatic_tank,
    "dam_break": dam_break,
    "oscillating_plate": oscillating_plate,
    "turek_hron_csm": turek_hron_csm,
    "abc_flow_3d": abc_flow_3d,
    "hydrostatic_tank_3d": hydrostatic_tank_3d,
    "cantilever_3d": cantilever_3d,
    "duct_poiseuille_3d": duct_poiseuille_3d,
    "dam_break_3d": dam_break_3d,
    "spheric_dam_break_3d": spheric_dam_break_3d,
    "hydrostatic_fsi_plate": hydrostatic_fsi_plate,
    "hydrostatic_fsi_plate_3d": hydrostatic_fsi_plate_3d,
    "elastic_gate_dam_break": elastic_gate_dam_break,
    "dam_break_elastic_obstacle": dam_break_elastic_obstacle,
    "floating_body": floating_body,
    "sinking_body": sinking_body,
    "settling_disk": settling_disk,
    "channel_flow": channel_flow,
}


def get(name: str, *, dx: float | None = None, **kwargs):
    """Build the case called ``name`` (see ``CASES``) with keyword arguments.

    ``dx`` gives the resolution as a particle spacing instead of ``n`` (``n = L / dx``
    rounded, ``L`` the case's length scale; see ``case.info["dx"]`` for the one used).
    """
    try:
        factory = CASES[name]
    except KeyError:
        raise ValueError(
            f"unknown case {name!r}; available cases: {', '.join(sorted(CASES))}"
        ) from None
    accepted = inspect.signature(factory).parameters
    unknown = sorted(set(kwargs) - set(accepted))
    if unknown:
        raise ValueError(
            f"case {name!r} has no argument {', '.join(map(repr, unknown))}; "
            f"it accepts {', '.join(accepted)}"
        )
    if dx is not None:
        if "n" in kwargs:
            raise ValueError("give either n or dx, not both")
        kwargs["n"] = n_for_spacing(factory, dx, **kwargs)
    return factory(**kwargs)


__all__ = [
    "CASES",
    "get",
    "from_toml",
    "SetupError",
    "taylor_green",
    "taylor_green_velocity",
    "poiseuille",
    "poiseuille_startup_speed",
    "poiseuille_centreline_speed",
    "lid_driven_cavity",
    "centreline_profiles",
    "hydrostatic_tank",
    "dam_break",
    "dam_break_impact",
    "dam_break_wall_sensors",
    "DAM_BREAK_WALL_SENSORS",
    "surge_front",
    "probe_pressure",
    "oscillating_plate",
    "turek_hron_csm",
    "relax_to_rest",
    "tip_displacement",
    "oscillation_stats",
    "plate_mode_shape",
    "plate_reference",
    "plate_sound_speed",
    "abc_flow_3d",
    "abc_velocity",
    "abc_pressure",
    "hydrostatic_tank_3d",
    "cantilever_3d",
    "cantilever_reference",
    "beam_angular_frequency",
    "duct_poiseuille_3d",
    "duct_velocity",
    "dam_break_3d",
    "spheric_dam_break_3d",
    "water_height",
    "hydrostatic_fsi_plate",
    "hydrostatic_fsi_plate_3d",
    "elastic_gate_dam_break",
    "dam_break_elastic_obstacle",
    "midspan_deflection",
    "plate_deflection_reference",
    "floating_body",
    "sinking_body",
    "body_bottom",
    "settling_disk",
    "body_velocity",
    "channel_flow",
    "channel_profile",
    "channel_startup_profile",
    "channel_mass_flux",
    "poiseuille_profile",
]
