"""How wrong are the joint graph's wrong links? (issue 13: "0 wrong links accepted")

Reads a ``bench/merge_table.py`` JSON (its runs' ``merge_graph_links``) and the bags it made,
and prints every link the reference calls wrong (``reference_check.ReferenceJudge``, as the
table counts them) with how far it is off: position (m) and heading (deg) of keyframe b
relative to keyframe a against the reference, and the length of the link. A look-alike
place is metres off; a link between two slightly bent partial maps is a near miss beyond the
0.30 m / 5 deg tolerance.

    .venv/bin/python -m bench.link_errors [--json bench_output/merge_table/merge_table.json]
        [--work bench_output/merge_table]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench.harness import OUTPUT
from bench.reference_check import ReferenceJudge
from multi_robot_mapper.core import se2
from multi_robot_mapper.io.bags import read_recordings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=OUTPUT / "merge_table")
    parser.add_argument("--json", type=Path, help="default WORK/merge_table.json")
    args = parser.parse_args()
    table = json.loads((args.json or args.work / "merge_table.json").read_text())
    print("| log | robots | links | wrong | each wrong link: robots, off by m / deg, length m |")
    print("| --- | --- | --- | --- | --- |")
    for row in table["rows"]:
        links = row.get("stats", {}).get("merge_graph_links", [])
        bag = args.work / "bags" / f"{row['log']}_{row['robots']}"
        if not links or not bag.exists():
            continue
        judge = ReferenceJudge(read_recordings(bag))
        wrong = []
        for a, stamp_a, b, stamp_b, x, y, theta in links:
            if judge.verdict(a, stamp_a, b, stamp_b, (x, y, theta)) != "wrong":
                continue
            truth = se2.between(judge.reference(a, stamp_a), judge.reference(b, stamp_b))  # type: ignore[arg-type]
            dx, dy, dtheta = se2.between(truth, (x, y, theta))
            wrong.append(
                f"{a}–{b} {np.hypot(dx, dy):.2f} / {np.degrees(dtheta):+.1f} ({np.hypot(x, y):.1f})"
            )
        print(
            f"| {row['log']} | {row['robots']} | {len(links)} | {len(wrong)} | "
            f"{'; '.join(wrong) or '–'} |"
        )


if __name__ == "__main__":
    main()
