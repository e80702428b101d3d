"""ament_python / setuptools build script for jident_ros.

Works both with ``colcon build`` (ROS 2 workspace) and with plain
``pip install [-e] .`` (see scripts/setup.sh).  Default configuration files stay
in the top-level ``config/`` folder (single source of truth) and are installed
as data_files to ``<prefix>/share/jident_ros/config``; jident_ros/resources.py
finds them in every install mode.
"""

import os
from glob import glob

from setuptools import find_packages, setup

package_name = 'jident_ros'

data_files = [
    ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
    ('share/' + package_name, ['package.xml']),
    ('share/' + package_name + '/config', sorted(glob('config/*.yaml') + glob('config/*.json'))),
    ('share/' + package_name + '/config/profiles', sorted(glob('config/profiles/*.yaml'))),
]
if os.path.isdir('launch'):
    data_files.append(('share/' + package_name + '/launch', sorted(glob('launch/*.launch.py'))))

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=data_files,
    install_requires=[
        # Never rclpy or ros-* wheels here: a ROS distribution's own rclpy must
        # not be replaced.  A plain venv gets them from requirements-ros.txt.
        'numpy',
        'scipy',
        'PyWavelets',
        'PyYAML',
        'matplotlib',
        'tqdm',
        # recordings: CDR, message definitions and type hashes (typestore), reading any rosbag2 bag
        'rosbags',
        # the diagnostic node records by default (MCAP, zstd chunks)
        'mcap',
        'zstandard',
        'lz4',
    ],
    extras_require={
        'test': ['pytest', 'rosbags'],
        # byte-compatibility tests against mcap-ros2-support's writer/reader
        'mcap': ['mcap-ros2-support'],
        # the third validation drive (jident_ros.research.vector_drive, the zoo report): written for motulator's 0.5 API
        'zoo': ['motulator==0.5.0; python_version < "3.12"'],
    },
    zip_safe=True,
    maintainer='jident developers',
    maintainer_email='jident@example.com',
    description=(
        'Identification of the moment of inertia J1 of an induction-motor drive '
        'from the backlash-zone transient (wavelet scalograms + k-harmonic means)'
    ),
    license='Apache-2.0',
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'jident = jident_ros.cli.main:main',
            'simulator = jident_ros.nodes.entry:simulator',
            'windowing = jident_ros.nodes.entry:windowing',
            'diagnostic = jident_ros.nodes.entry:diagnostic',
            'replay = jident_ros.nodes.entry:replay',
        ],
    },
)
