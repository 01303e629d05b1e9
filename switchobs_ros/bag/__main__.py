"""``python -m switchobs_ros.bag`` = ``switchobs_bag``."""

import sys

from .cli import main

sys.exit(main())
