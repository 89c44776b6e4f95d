import os

from setuptools import find_packages, setup

package_name = 'sim_robot_node'
# The repository's config/ is the one source of the numbers; this package installs its
# nodes' files from there to share/sim_robot_node/config (symlinked by --symlink-install).
config_files = [os.path.join('..', 'config', name) for name in (
    'panda_scene.yaml', 'panda_ideal.yaml', 'panda_mujoco.yaml', 'panda_pybullet.yaml', 'xarm_scene.yaml', 'nextage.yaml', 'peg_env.yaml')]

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', config_files),
    ],
    package_data={package_name: ['assets/**/*', 'assets/*/*']},
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='QG developers',
    maintainer_email='dev@qg.local',
    description='Simulated hardware: pybullet torque arms (Panda, xArm 7) with a shaft/bearing press fit and a Nextage arm with peg-in-hole, 1 kHz, ground truth for evaluation.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'sim = sim_robot_node.sim_node:main',
        ],
        # The robots this package simulates, loaded by name by robot_bridge_node's robot process.
        'robot_bridge_node.robots': [
            'sim_panda = sim_robot_node.plugins:SIM_PANDA',
            'sim_panda_mujoco = sim_robot_node.plugins:SIM_PANDA_MUJOCO',
            'sim_panda_pybullet = sim_robot_node.plugins:SIM_PANDA_PYBULLET',
            'sim_xarm7 = sim_robot_node.plugins:SIM_XARM7',
            'sim_nextage = sim_robot_node.plugins:SIM_NEXTAGE',
        ],
        # What viewers draw of each robot's task beside its URDF (robot_bridge_node.task_scenes).
        'robot_bridge_node.task_scenes': [
            'sim_panda = sim_robot_node.core.task_visuals:shaft_task_scene',
            'sim_panda_mujoco = sim_robot_node.core.task_visuals:shaft_task_scene',
            'sim_panda_pybullet = sim_robot_node.core.task_visuals:shaft_task_scene',
            'sim_xarm7 = sim_robot_node.core.task_visuals:shaft_task_scene',
            'sim_nextage = sim_robot_node.core.task_visuals:nextage_task_scene',
        ],
        # The episode renderer of `qgl render` and the Gymnasium environments' render modes.
        'qg_learning_node.renderers': [
            'pybullet = sim_robot_node.core.episode_render',
        ],
        # Environments of the in-process experiments (qg_experiments.environments).
        'qg_experiments.environments': [
            'peg = sim_robot_node.core.peg_env:make_peg_env',
        ],
    },
)
