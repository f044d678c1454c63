"""``python -m planeray``: the same as the ``planeray`` command."""

from planeray.cli import main

if __name__ == "__main__":
    main()
