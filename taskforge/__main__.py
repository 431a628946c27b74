"""The `taskforge` command (console script and `python -m taskforge`).

A thin door in front of `taskforge.cli`: nothing heavy is imported before the `try`, so a Ctrl-C
at any moment, the first half-second of imports included, ends quietly with exit code 130.
"""

import sys


def run() -> None:
    try:
        from taskforge.cli import main

        code = main()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        code = 130
    sys.exit(code)


if __name__ == "__main__":
    run()
