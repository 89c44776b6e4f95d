import os

from setuptools import find_packages, setup

package_name = 'qg_learning_node'
# The repository's config/ is the one source of the numbers; this package installs its
# nodes' files from there to share/qg_learning_node/config (symlinked by --symlink-install).
config_files = [os.path.join('..', 'config', name) for name in (
    'executor.yaml', 'learner.yaml', 'stack.yaml',
    'executor_nextage.yaml', 'learner_nextage.yaml', 'stack_nextage.yaml')]

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
    description='QG-DDPG: the residual force-policy executor (episodes, rewards, MCAP recording) and the learner (Q-Graph, replay memory, networks, checkpoints).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'executor = qg_learning_node.executor_node:main',
            'learner = qg_learning_node.learner_node:main',
        ],
    },
)
