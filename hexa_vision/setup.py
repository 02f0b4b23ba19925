from setuptools import find_packages, setup

package_name = "hexa_vision"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    zip_safe=True,
    description="hexa vision nodes: camera sources, plate pose, collision isolation",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "hexa-camera = hexa_vision.camera_node:main",
        "hexa-vision-pose = hexa_vision.pose_node:main",
        "hexa-vision-isolation = hexa_vision.isolation_node:main",
    ]},
)
