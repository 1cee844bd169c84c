"""``python -m relightable_textures``: the same CLI as the ``relight`` console script."""

from .operators.cli import main

main()
