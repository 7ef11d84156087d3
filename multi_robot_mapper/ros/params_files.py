"""The nodes' params files and docs/parameters.md, generated from the node configs
(``make config``: ``python -m multi_robot_mapper.ros.params_files config``).

The generators (io/config_files.py) take the nodes as arguments: the node configs live here in
ros/, which the io layer never imports. Importing this module loads no rclpy.
"""

from __future__ import annotations

import sys
from pathlib import Path

from multi_robot_mapper.io.config_files import (
    PARAMETERS_DOC,
    SYSTEM_PARAMS_FILE,
    default_params_file,
    parameters_doc,
    system_params_text,
)
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig
from multi_robot_mapper.ros.merger_config import MapMergerConfig

__all__ = ["NODES", "SYSTEM_PARAMS_FILE", "parameters_markdown", "system_params_file", "write"]

# Every node with parameters, by its node name, in the order the files list them.
NODES: tuple[tuple[str, type], ...] = (
    ("robot_mapper", RobotMapperConfig),
    ("map_merger", MapMergerConfig),
)


def system_params_file() -> str:
    """``config/multi_robot_mapper.yaml``: both nodes' parameters in one params file."""
    return system_params_text(NODES)


def parameters_markdown() -> str:
    """``docs/parameters.md``: every field of both nodes."""
    return parameters_doc(NODES)


def write(folder: Path, docs: Path) -> None:
    """Rewrite both nodes' params files and the system's in ``folder``, and
    docs/parameters.md in ``docs``."""
    for node, config_class in NODES:
        text = default_params_file(config_class, node)
        (folder / f"{node}.yaml").write_text(text, encoding="utf-8")
    (folder / SYSTEM_PARAMS_FILE).write_text(system_params_file(), encoding="utf-8")
    (docs / PARAMETERS_DOC).write_text(parameters_markdown(), encoding="utf-8")


if __name__ == "__main__":  # `make config`: the folder given, and the docs folder beside it
    # (or the folder given second)
    folder = Path(sys.argv[1])
    write(folder, Path(sys.argv[2]) if len(sys.argv) > 2 else folder.resolve().parent / "docs")
