"""``python -m voxwarp``: the same as the ``voxwarp`` command."""

import sys

from voxwarp.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
