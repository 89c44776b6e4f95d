import os

from setuptools import find_packages, setup

package_name = 'franka_robot_node'
# The repository's config/ is the one source of the numbers; this package installs its
# file from there to share/franka_robot_node/config (symlinked by --symlink-install).
config_files = [os.path.join('..', 'config', name) for name in ('franka.yaml', 'franka_real.yaml')]

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={package_name: ['description/fr3.urdf', 'description/meshes/*.stl', 'description/meshes/*.dae']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', config_files),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='QG developers',
    maintainer_email='dev@qg.local',
    description='A Franka FR3 as a torque robot plugin of the bridge through libfranka (franky).',
    license='Apache-2.0',
    entry_points={
        # Loaded by name by robot_bridge_node's robot process (robot:=franka).
        'robot_bridge_node.robots': [
            'franka = franka_robot_node.plugin:FRANKA',
        ],
    },
)
