"""``python -m detector``: the detector's command-line jobs (:mod:`detector.cmd`)."""

from __future__ import annotations

import sys

from detector.cmd import main

if __name__ == "__main__":
    sys.exit(main())
