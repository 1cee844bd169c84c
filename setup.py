"""Which packages the wheel holds (everything else is in pyproject.toml).

The repository root *is* the package ``relightable_textures`` (pyproject.toml's package-dir maps
it), and ``[tool.setuptools.packages.find]`` cannot prefix the packages it finds with that name,
so they are found here: the root and every package below it, whatever modules move between
subpackages. A hand-kept list missed ``lt_addon.export`` (issue 31): a wheel had no
``relight export``. tests/blender/test_packaging.py builds and installs a wheel and runs it.
"""

import os

from setuptools import find_packages, setup

NAME = "relightable_textures"

#: Folders of the checkout that are not the package: what the Blender zip leaves out
#: (blender_manifest.toml, [build] paths_exclude_pattern) except devtools, which the source
#: checkout's CLI uses (`relight bench`), and the outputs of builds. find_packages() descends
#: only into folders with an __init__.py and skips names with a dot (.venv, *.egg-info).
NOT_PACKAGED = ("tests", "benchmarks", "tools", "docs", "build", "dist", "out", "wheels",
                "node_modules")

HERE = os.path.dirname(os.path.abspath(__file__))
FOUND = find_packages(where=HERE, exclude=[p for d in NOT_PACKAGED for p in (d, d + ".*")])

# script_name: distutils leaves the setup script out of the package it sits in (here the root),
# but under pip (PEP 517) it takes the name from sys.argv[0], pip's backend runner.
setup(packages=[NAME] + [f"{NAME}.{p}" for p in sorted(FOUND)], script_name=__file__)
