import os

from setuptools import find_packages, setup

package_name = 'robot_bridge_node'
# The repository's config/ is the one source of the numbers; this package installs its
# nodes' files from there to share/robot_bridge_node/config (symlinked by --symlink-install).
config_files = [os.path.join('..', 'config', name) for name in (
    'bridge.yaml', 'wrench_estimator.yaml', 'recorder.yaml', 'sim.yaml')]

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', config_files),
    ],
    include_package_data=True,
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='QG developers',
    maintainer_email='dev@qg.local',
    description='Hardware bridge: 1 kHz hybrid force/impedance (torque arms from their URDF) or task-space position (Nextage) control with safety limits, and the EKF contact-wrench estimator.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'bridge = robot_bridge_node.bridge_node:main',
            'wrench_estimator = robot_bridge_node.estimator_node:main',
            'robot = robot_bridge_node.robot_process:main',
        ],
        # The hardware interface kinds the bridge drives, looked up by the name a robot plugin
        # gives (robot_bridge_node.core.interface_kinds).
        'robot_bridge_node.interfaces': [
            'torque = robot_bridge_node.core.torque_kind:TORQUE',
            'position = robot_bridge_node.core.position_kind:POSITION',
        ],
    },
)
