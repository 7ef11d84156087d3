"""ament_python build of multi_robot_mapper (colcon) and pip install (make test / make demo)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "multi_robot_mapper"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    # Fitted models are data the code loads (core/evidence/join_model.json, closure_model.json,
    # piece_join_model.json,
    # core/matching/confidence_model.json, core/local_mapping/context_model.json).
    package_data={
        PACKAGE: ["core/evidence/*.json", "core/matching/*.json", "core/local_mapping/*.json"]
    },
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        # Parameters, and the viewers' configurations for the outputs (mrm replay --record).
        (
            f"share/{PACKAGE}/config",
            [*glob("config/*.yaml"), *glob("config/*.json"), *glob("config/*.rviz")],
        ),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    # Runtime dependencies are declared in package.xml (colcon/rosdep) and in
    # requirements.txt (the PyPI venv that `make test` builds).
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="multi_robot_mapper maintainers",
    maintainer_email="maintainers@multi-robot-mapper.invalid",
    description="Multi-robot segment mapping without odometry or known relative poses",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "robot_mapper = multi_robot_mapper.ros.robot_mapper:main",
            "map_merger = multi_robot_mapper.ros.map_merger:main",
            "mrm = multi_robot_mapper.cli.main:main",
        ],
    },
)
