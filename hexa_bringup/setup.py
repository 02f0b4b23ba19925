from setuptools import find_packages, setup

package_name = "hexa_bringup"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]) + [package_name + ".config"],  # config: data (profile, params)
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    package_data={package_name: ["config/*.yaml", "config/*.xml", "config/*.json"]},
    zip_safe=True,
    description="hexa graph bringup, supervisor, `hexa` CLI, config and Fast DDS profile",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "hexa = hexa_bringup.cli:main",
        "hexa-sim = hexa_bringup.sim_node:main",
        "hexa-view = hexa_bringup.view_node:main",
    ]},
)
