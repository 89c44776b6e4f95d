from setuptools import find_packages, setup

package_name = 'qg_recording'

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
    description='Episode recording in rosbag2 layout (metadata.yaml + MCAP, ROS 2 CDR): writer, reader and player, shared by the robot process and the learner.',
    license='Apache-2.0',
)
