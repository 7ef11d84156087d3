"""Force Field Simulation (Lakaemper, Adluru, Latecki & Madhavan 2007): all keyframes of all
robots aligned at once as rigid bodies in a Gaussian force field.

Modules: ``config`` (FfsConfig, units), ``bodies`` (resampling, regions of interest),
``simulation`` (the force field and Algorithm 1), ``far`` (FFS from afar, issue 51) and
``method`` (the ``ffs`` merging method: FFS after the joint merger's placement). This package
imports only ``config``, ``bodies`` and ``simulation``: ``method`` imports the joint merger,
whose config imports :class:`FfsConfig` from here, so importing ``method`` here would be a
cycle."""

from multi_robot_mapper.core.merging.ffs.bodies import Bodies, facing_sensor, make_bodies, resample
from multi_robot_mapper.core.merging.ffs.config import FfsConfig
from multi_robot_mapper.core.merging.ffs.simulation import FfsResult, force_field, run_ffs

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
