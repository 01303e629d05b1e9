"""ament_python package switchobs_ros: the Python packages switchobs_core, msg_bridge and
switchobs_ros, with the executables estimator, camera_sim and switchobs.

The compiled kernel switchobs_core/numerics/_dense_step.c (the rigorous bound's dense step,
switchobs_core/numerics/dense_kernel.py) is optional: where it does not build (no C compiler) the
package installs without it and the numpy step runs. Its flags keep every rounding as written: no
FMA contraction, no -ffast-math, no -march (the same doubles on every x86-64 CPU). It is x86-64 only
(GCC's target_clones): elsewhere it does not build and the numpy step runs.

Works both with colcon on a ROS 2 Jazzy system (``colcon build``; setup.cfg puts the
executables in ``<prefix>/lib/switchobs_ros`` where ``ros2 run`` looks for them) and with
``pip install -e .`` into a virtual environment that takes ROS 2 from PyPI (the executables
then land on the environment's ``bin``). Version pins live in requirements.txt only.
"""

import hashlib
import os
from glob import glob

from setuptools import Extension, find_packages, setup

package_name = "switchobs_ros"
#: The kernel's flags, after the environment's CFLAGS on the command line (so they win): -fno-fast-math
#: undoes a -ffast-math there (-ffp-contract=off alone does not: it would drop the isfinite tests and
#: reassociate sums); _dense_step.c refuses to compile under __FAST_MATH__ / __FINITE_MATH_ONLY__.
KERNEL_FLAGS = ["-O2", "-fno-fast-math", "-ffp-contract=off", "-Wno-psabi"]
KERNEL_SOURCE = "switchobs_core/numerics/_dense_step.c"
#: The module carries the SHA-256 of the source it was built from (dense_kernel refuses another's).
with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), KERNEL_SOURCE), "rb") as _f:
    KERNEL_SHA256 = hashlib.sha256(_f.read()).hexdigest()

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["switchobs_core", "switchobs_core.*", "msg_bridge", "msg_bridge.*",
                                    "switchobs_ros", "switchobs_ros.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", sorted(glob("config/*.yaml")) + sorted(glob("config/*.rviz"))
         + sorted(glob("config/*.xml"))),
        ("share/" + package_name + "/launch", sorted(glob("launch/*.launch.py"))),
    ],
    ext_modules=[Extension("switchobs_core.numerics._dense_step", [KERNEL_SOURCE], extra_compile_args=KERNEL_FLAGS,
                           define_macros=[("SOURCE_SHA256", f'"{KERNEL_SHA256}"')], optional=True)],
    # Unpinned: colcon on a ROS system resolves these through package.xml / rosdep; in a venv
    # scripts/bootstrap.sh installs the pinned set from requirements.txt first.
    install_requires=["setuptools", "numpy", "scipy", "cvxpy", "PyYAML", "threadpoolctl", "tqdm"],
    extras_require={
        "ros": [
            "ros-jazzy-rclpy[fastrtps]", "ros-jazzy-std-msgs", "ros-jazzy-geometry-msgs",
            "ros-jazzy-nav-msgs", "ros-jazzy-diagnostic-msgs", "ros-jazzy-std-srvs",
            "ros-jazzy-rosgraph-msgs", "ros-jazzy-visualization-msgs",
        ],
        "demo": ["matplotlib", "tqdm"],
        "test": ["pytest", "hypothesis", "ruff"],
    },
    zip_safe=False,
    maintainer="switchobs maintainers",
    maintainer_email="switchobs@example.org",
    description="Switched Luenberger observers for systems observed one output channel at a time",
    license="MIT",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            "estimator = switchobs_ros.entry:estimator",
            "managed_estimator = switchobs_ros.entry:managed_estimator",
            "camera_sim = switchobs_ros.entry:camera_sim",
            "switchobs = switchobs_core.cli:main",
            "switchobs_bag = switchobs_ros.entry:switchobs_bag",
        ],
    },
)
