from setuptools import find_packages, setup

package_name = "hexa_ros"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]) + [package_name + ".config"],  # config: data (profile, params)
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    package_data={package_name: ["config/*.xml"]},
    zip_safe=True,
    description="hexa's shared ROS glue: node main/spin, composition, stamps, QoS, diagnostics, conversions",
    license="Apache-2.0",
)
