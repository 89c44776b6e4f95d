from setuptools import find_packages, setup

package_name = 'qg_bringup'

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
    description='qgl: brings the stack up (launcher with respawn), runs episodes, training runs '
                'and the demo, and handles recordings and policy files.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'qgl = qg_bringup.main:main',
        ],
    },
)
