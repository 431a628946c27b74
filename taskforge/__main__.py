"""The `taskforge` command (console script and `python -m taskforge`).

A thin door in front of `taskforge.cli`: nothing heavy is imported before the `try`, so a Ctrl-C
at any moment, the first half-second of imports included, ends quietly with exit code 130; a
closed pipe ends it quietly too (141).
"""

import os
import sys


def run() -> None:
    try:
        from taskforge.cli import main

        code = main()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        # An interrupt that landed inside an import can leave the interpreter flagged as killed by
        # SIGINT, so a plain exit would end the process by the signal (-2), not with status 130.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    except BrokenPipeError:
        # The reader went away (`taskforge validate x.yaml | head -1`): as any Unix tool, stop
        # quietly. stdout is pointed at devnull so the interpreter's final flush does not fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(141)  # 128 + SIGPIPE, what a shell reports for a tool killed by it
    sys.exit(code)


if __name__ == "__main__":
    run()
