"""ament_python build of idpose_ros: three Python packages, config, launch files and the ament marker."""
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "idpose_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=["idpose_core*", "msg_adapters*", "idpose_ros*"]),
    package_data={"idpose_core": ["assets/*", "assets/demo_model/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ] + [(f"share/{PACKAGE}/{bag}", glob(f"{bag}/*")) for bag in sorted(
        str(Path(metadata).parent) for metadata in glob("data/demo_bags/**/metadata.yaml", recursive=True))],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="idpose_ros developers",
    maintainer_email="idpose-ros@example.com",
    description="Sparse-view camera pose estimation by inverting Zero-1-to-3 (ID-Pose) as a ROS 2 node.",
    license="MIT",
    entry_points={
        "console_scripts": [
            "estimator = idpose_ros.node.process:main",
            "evaluate_bag = idpose_ros.evaluate_bag:main",
            "evaluate_dataset = idpose_ros.evaluate_dataset:main",
            "make_synthetic_bag = idpose_ros.make_synthetic_bag:main",
            "demo = idpose_ros.demo:main",
            "seal_recording = idpose_ros.seal_recording:main",
        ],
    },
)
