"""`python -m fabwire` and the console script."""

import sys


def run() -> None:
    if sys.argv[1:] in (["--version"], ["-V"]):  # answered before click and the CLI are imported
        from fabwire import __version__

        sys.stdout.write(f"fabwire, version {__version__}\n")
        sys.exit(0)
    from fabwire.cli import main

    sys.exit(main())


if __name__ == "__main__":
    run()
