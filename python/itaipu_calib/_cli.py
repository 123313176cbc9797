"""The ``itaipu-calib`` command installed with the wheel: the Rust command line, in process."""

import sys
from typing import List, Optional

from ._core import _cli_main


def main(argv: Optional[List[str]] = None) -> int:
    """Runs ``itaipu-calib`` with ``argv`` (default: this process's arguments) and exits with
    its exit code (see ``itaipu-calib --help``)."""
    args = list(sys.argv[1:] if argv is None else argv)
    sys.stdout.flush()
    code = _cli_main(["itaipu-calib", *args])
    if argv is None:
        sys.exit(code)
    return code


if __name__ == "__main__":
    main()
