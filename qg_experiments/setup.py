import os

from setuptools import find_packages, setup

package_name = 'qg_experiments'
# The repository's config/ is the one source of the numbers; this package installs the
# experiments' profiles and the report's random bar (the demo's plot draws it) from there to
# share/qg_experiments/config (symlinked by --symlink-install). The stack files the runs read
# are the node packages' own.
config_files = [os.path.join('..', 'config', name) for name in ('experiments.yaml',
                                                               'random_bar.json')]

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
    description='The thesis experiments in process: the bridge loop, EKF, episode logic and learner composed without DDS, the profiles of config/experiments.yaml, the report, the Ray backend and the ch. 7 toys.',
    license='Apache-2.0',
    entry_points={
        # gymnasium 0.26-0.29 call this on import (1.x does not: see qg_experiments/gym_envs).
        'gymnasium.envs': ['qg_experiments = qg_experiments.gym_envs:register_envs'],
    },
)
