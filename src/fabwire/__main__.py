"""`python -m fabwire` and the console script."""

import sys

from fabwire.cli import main


def run() -> None:
    sys.exit(main())


if __name__ == "__main__":
    run()
