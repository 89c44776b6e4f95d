from setuptools import find_packages, setup

package_name = 'franka_sim_node'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='QG developers',
    maintainer_email='dev@qg.local',
    description='franky-sim\'s MuJoCo FR3 serving libfranka on loopback with the shaft task\'s cell: the Franka plugin\'s rehearsal robot.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'franka_sim = franka_sim_node.franka_sim:main',
        ],
    },
)
