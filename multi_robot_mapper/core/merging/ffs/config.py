"""Force Field Simulation's parameters, one typed config (SI units).

The paper (Lakaemper et al. 2007, Sec. 4.2) gives its values for data in centimetres: step
width Δt from 5 down to 1 (factor 0.96 per iteration), kernel width σ from 15 to 4 cm (0.25 cm
less per iteration), regions of interest of 5 cm radius, segments resampled every 10 cm. Here
lengths are metres and the accelerations are normalised by each body's stiffness (the
second derivative of its potential), so that ½·a·Δt² with Δt = 1 is the whole step that the
force field asks for: the step widths become fractions of that step, independent of units."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import ConfigError, param, validate


@dataclasses.dataclass(frozen=True)
class FfsConfig:
    """Force Field Simulation (FFS Sec. 3, Algorithm 1). Lengths in metres, angles in radians,
    times in seconds."""

    spacing: float = param(
        0.10,
        unit="m",
        doc="segments are resampled into points this far apart (FFS 3.3)",
        minimum=0.005,
        maximum=10.0,
    )
    body_length: float = param(
        10.0,
        unit="m",
        doc="consecutive keyframes of a robot are one rigid body until they own this much wall "
        "(a keyframe owns only the walls it saw first: alone, most would be a few points that "
        "the field slides along a wall)",
        minimum=0.0,
        maximum=10000.0,
    )
    sigma_start: float = param(
        0.10,
        unit="m",
        doc="width of the Gaussian force field at the first iteration (FFS 3.6; the paper's "
        "15 cm: from the joint graph's placement, 0.10 m ended closer to the reference on 4 "
        "of 6 cuts measured and within 2.4 mm on the others, README 'Force Field Simulation')",
        minimum=0.001,
        maximum=100.0,
    )
    sigma_end: float = param(
        0.04,
        unit="m",
        doc="width the force field cools down to, linearly (FFS 3.6)",
        minimum=0.001,
        maximum=100.0,
    )
    sigma_step: float = param(
        0.0025,
        unit="m",
        doc="the force field's width shrinks by this much per iteration",
        minimum=0.0,
        maximum=100.0,
    )
    dt_start: float = param(
        1.0,
        unit="",
        doc="step width at the first iteration: ½·Δt² of the normalised step "
        "(the paper's 5 in its units)",
        minimum=0.0,
        maximum=10.0,
    )
    dt_end: float = param(
        0.5,
        unit="",
        doc="step width the cooling ends at (the paper's 1)",
        minimum=0.0,
        maximum=10.0,
    )
    dt_factor: float = param(
        0.96,
        unit="",
        doc="the step width is multiplied by this each iteration (FFS 4.2)",
        minimum=0.0,
        maximum=1.0,
    )
    cutoff: float = param(
        3.0,
        unit="sigma",
        doc="point pairs farther apart than this many σ exert no force",
        minimum=0.5,
        maximum=10.0,
    )
    roi_radius: float = param(
        0.05,
        unit="m",
        doc="points this close to a corner (FFS 3.4: supporting lines meeting "
        "at 80-100 deg near both segments) lie in a region of interest",
        minimum=0.0,
        maximum=10.0,
    )
    roi_mass: float = param(
        3.0,
        unit="",
        doc="mass of a point in a region of interest (others: 1), for the force only",
        minimum=1.0,
        maximum=100.0,
    )
    chain_stiffness: float = param(
        0.3,
        unit="",
        doc="consecutive bodies of one robot are pulled back toward their relative pose in "
        "the robot's own map (as the pre-alignment placed them) with this stiffness, "
        "in units of a body lying fully on other bodies' walls: 1 holds a body's deviation from "
        "its neighbours' prediction as firmly as such walls hold it (issue 14 item 2's weak "
        "spring; 0.3 measured closer to the reference than 0 or 1 summed over 6 cuts); 0: no "
        "spring",
        minimum=0.0,
        maximum=100.0,
    )
    stop_relocation: float = param(
        0.0005,
        unit="m",
        doc="the simulation stops once σ has cooled and the bodies' mean "
        "relocation per iteration is below this (Algorithm 1 line 15)",
        minimum=0.0,
        maximum=1.0,
    )
    max_iterations: int = param(
        200,
        unit="iterations",
        doc="the simulation stops after this many iterations",
        minimum=1,
        maximum=100000,
    )
    time_budget: float = param(
        2.0,
        unit="s",
        doc="the simulation stops after this long (one merge update); 0: no limit",
        minimum=0.0,
        maximum=3600.0,
        tune="with method 'ffs' on large maps: more lets the simulation finish",
    )

    def __post_init__(self) -> None:
        validate(self)
        if self.sigma_end > self.sigma_start or self.dt_end > self.dt_start:
            raise ConfigError(
                f"FFS cools down: sigma_end ({self.sigma_end} m) must not exceed sigma_start "
                f"({self.sigma_start} m), nor dt_end ({self.dt_end}) dt_start ({self.dt_start})"
            )
