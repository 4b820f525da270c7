"""``python -m control``: the controller node (same as ``cdw-twin controller``)."""

from __future__ import annotations

import sys

from control.cmd_controller import main

if __name__ == "__main__":
    sys.exit(main())
