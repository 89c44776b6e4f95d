import os

from setuptools import find_packages, setup

package_name = 'qg_common'
# The repository's config/ is the one source of the numbers; this package installs the files
# every side of the stack reads (the task's cell) to share/qg_common/config.
config_files = [os.path.join('..', '..', '..', 'config', name) for name in ('shaft_task.yaml', 'peg_task.yaml')]

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', config_files),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='QG developers',
    maintainer_email='dev@qg.local',
    description='What every package of the stack shares: config dataclasses and their loading, message conversions, topic names and QoS, the node runtime. No pybullet, no torch.',
    license='Apache-2.0',
)
