from setuptools import find_packages, setup

package_name = "hexa_dynamics"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    zip_safe=True,
    description="hexa dynamics nodes: singularity indices, SRM releaser, simulated 3UPS+RPU (observer/rnea later)",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "hexa-singularity = hexa_dynamics.singularity_node:main",
        "hexa-srm = hexa_dynamics.srm_node:main",
        "hexa-upsrpu-sim = hexa_dynamics.upsrpu_sim_node:main",
        "hexa-observer = hexa_dynamics.observer_node:main",
        "hexa-rnea = hexa_dynamics.rnea_node:main",
        "hexa-trajectory = hexa_dynamics.trajectory_node:main",
    ]},
)
