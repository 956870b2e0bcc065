"""``python -m fignet_gym``: the ``fignet-gym`` command line."""

import sys

from fignet_gym.cli import main

sys.exit(main())
