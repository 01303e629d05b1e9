"""``python -m switchobs_ros.bag`` = ``switchobs_bag``."""

import sys

from ..entry import switchobs_bag

sys.exit(switchobs_bag())
