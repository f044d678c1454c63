"""``python -m planeray.cli``: the same as the ``planeray`` command."""

from . import main

main()
