"""Which bodies FFS's re-convergence experiment (FFS Sec. 4.2, issue 51) leaves off, and where:
each body off by more than 1 cm or 0.5 deg, with its offset (cm, x and y in the map frame) and
its turn, for R0 against the reference poses and for each seed against R0 and against the
reference poses.

    .venv/bin/python -m bench.ffs_bodies [--log csail] [--seeds 0,1] [--distortion 0.30,20]
        [--no-reseat]

The same problem as ``bench.ffs_bench`` (the log's first 60 keyframes, the first body fixed, σ
from ``start_width``, :func:`run_ffs_escaped`, with ``--no-escape`` :func:`run_ffs_reseated`, with
``--no-reseat`` :func:`run_ffs_far`),
the same seeds; where ``bench.ffs_bench`` prints how far the worst body is, this prints every
body that is off, so that a slide along a corridor (offsets along one axis) or a run of bodies
(consecutive indices) shows. Prints CPU ms per iteration too.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from bench.ffs_bench import distorted, experiment_bodies, keyframe_scans, widened  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.merging.ffs import FfsConfig  # noqa: E402
from multi_robot_mapper.core.merging.ffs.escape import run_ffs_escaped  # noqa: E402
from multi_robot_mapper.core.merging.ffs.far import run_ffs_far  # noqa: E402
from multi_robot_mapper.core.merging.ffs.reseat import run_ffs_reseated  # noqa: E402


def bodies_off(name: str, poses_map: np.ndarray, against_map: np.ndarray) -> str:
    """One line: the largest offset, then every body off by > 1 cm or > 0.5 deg as
    ``index:offset cm (dx, dy)/turn deg``."""
    offset = (poses_map[:, :2] - against_map[:, :2]) * 100.0
    gaps = np.hypot(*offset.T)
    turns = np.degrees(np.abs(se2.wrap_angle(poses_map[:, 2] - against_map[:, 2])))
    off = np.flatnonzero((gaps > 1.0) | (turns > 0.5))
    listed = " ".join(
        f"{k}:{gaps[k]:.0f}({offset[k, 0]:.0f},{offset[k, 1]:.0f})/{turns[k]:.1f}" for k in off
    )
    return f"{name}: max {gaps.max():.1f} cm / {turns.max():.2f} deg; {len(off)} off: {listed}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--log", default="csail")
    parser.add_argument("--seeds", default="0", help="comma-separated seeds; '': R0 only")
    parser.add_argument("--distortion", default="0.30,20", help="METRES,DEGREES (uniform +-)")
    parser.add_argument("--no-reseat", action="store_true", help="FFS from afar alone")
    parser.add_argument("--no-escape", action="store_true", help="without the escape pass")
    args = parser.parse_args()
    shift, turn = (float(v) for v in args.distortion.split(","))
    sets, reference, _ = keyframe_scans(args.log, 60)
    config = FfsConfig(time_budget=0.0, max_iterations=1000)
    bodies, fixed = experiment_bodies(sets, config)
    config = widened(config, bodies, shift, turn)
    simulate = (
        run_ffs_far if args.no_reseat else run_ffs_reseated if args.no_escape else run_ffs_escaped
    )
    cpu = time.process_time()
    r0 = simulate(bodies, reference, config, fixed=fixed)
    print(f"R0: {r0.iterations} iterations, {_ms(cpu, r0.iterations)} CPU ms per iteration")
    print(bodies_off("R0 from the reference poses", r0.poses, reference), flush=True)
    for seed in (int(s) for s in args.seeds.split(",") if s):
        # As bench.ffs_bench: every free body moved by uniform +-shift, +-turn from R0.
        start = distorted(r0.poses, fixed, shift, turn, seed)
        cpu = time.process_time()
        result = simulate(bodies, start, config, fixed=fixed)
        print(f"seed {seed}: {result.iterations} iterations, {_ms(cpu, result.iterations)} ms")
        print(bodies_off(f"seed {seed} from R0", result.poses, r0.poses))
        print(bodies_off(f"seed {seed} from the reference poses", result.poses, reference))


def _ms(cpu_started: float, iterations: int) -> str:
    return f"{(time.process_time() - cpu_started) * 1000.0 / max(iterations, 1):.1f}"


if __name__ == "__main__":
    main()
