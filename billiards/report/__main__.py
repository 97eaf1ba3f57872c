"""``python -m billiards.report DIR...``."""

from . import main

main()
