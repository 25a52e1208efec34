from setuptools import setup
from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(packages=['global_goal_manager', 'global_goal_manager.core'], package_dir={'': 'src'}))
