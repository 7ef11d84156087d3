"""Force Field Simulation (Lakaemper, Adluru, Latecki & Madhavan 2007): all keyframes of all
robots aligned at once as rigid bodies in a Gaussian force field.

Modules: ``config`` (FfsConfig, units), ``bodies`` (resampling, regions of interest),
``simulation`` (the force field and Algorithm 1). The ``ffs`` merging method (FFS after the
joint merger's placement) is :mod:`multi_robot_mapper.core.merging.ffs`: merging imports this
package, never the other way round."""

from multi_robot_mapper.core.ffs.bodies import Bodies, facing_sensor, make_bodies, resample
from multi_robot_mapper.core.ffs.config import FfsConfig
from multi_robot_mapper.core.ffs.simulation import FfsResult, force_field, run_ffs

__all__ = [
    "Bodies",
    "FfsConfig",
    "FfsResult",
    "facing_sensor",
    "force_field",
    "make_bodies",
    "resample",
    "run_ffs",
]
