"""ament_python package evsync_ros: builds with colcon in a ROS 2 install, installs with pip here."""

from pathlib import Path

from setuptools import Extension, find_packages, setup

PACKAGE = 'evsync_ros'

setup(
    name=PACKAGE,
    version='1.0.0',
    packages=find_packages(include=[PACKAGE, f'{PACKAGE}.*', 'msg_adapters']),
    # The word loops of the stateful decoders (evt3, libcaer_cmp): plain C over the buffer protocol.
    package_data={PACKAGE: ['py.typed', 'bag/_records.pyi'], 'msg_adapters': ['py.typed', '_kernels.pyi']},
    # and an mcap chunk's Message records, walked and built (evsync_ros/bag/mcapchunks.py)
    ext_modules=[Extension('msg_adapters._kernels', ['msg_adapters/_kernels.c'], extra_compile_args=['-O3']),
                 Extension(f'{PACKAGE}.bag._records', [f'{PACKAGE}/bag/_records.c'], extra_compile_args=['-O3'])],
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', sorted(str(p) for p in Path('config').glob('*.yaml'))
         + sorted(str(p) for p in Path('config').glob('*.xml'))),
        (f'share/{PACKAGE}/launch', sorted(str(p) for p in Path('launch').glob('*.launch.py'))),
    ],
    # rosbags brings ruamel.yaml, lz4 and apsw too, but the package imports them itself: declared
    install_requires=['setuptools', 'numpy', 'rosbags', 'ruamel.yaml', 'lz4', 'apsw'],
    extras_require={'plot': ['matplotlib'], 'test': ['pytest', 'hypothesis']},
    zip_safe=False,
    maintainer='evsync_ros maintainers',
    maintainer_email='maintainers@evsync-ros.org',
    description='Software synchronisation of several event cameras by event-density alignment.',
    license='Apache-2.0',
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'evsync = evsync_ros.cli.main:main',
            'evsync_node = evsync_ros.ros.node:main',
        ],
    },
)
