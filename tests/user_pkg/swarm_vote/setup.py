from setuptools import setup

package_name = "swarm_vote"

setup(
    name=package_name,
    version="0.1.0",
    packages=[package_name],
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", ["config/params.yaml"]),
    ],
    install_requires=["setuptools"],
    entry_points={
        "console_scripts": [
            "sensor_layer = swarm_vote.sensor_layer:main",
            "behaviour = swarm_vote.behaviour:main",
            "safety = swarm_vote.safety:main",
            "mission_control = swarm_vote.mission_control:main",
        ],
    },
)
