from setuptools import find_packages, setup

package_name = "hexa_driver"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "firmware"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", ["config/driver.yaml"]),
    ],
    zip_safe=True,
    description="hexa serial driver node (Uno servos + Mega current sensors)",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "hexa-driver = hexa_driver.driver_node:main",
    ]},
)
