"""``jident salvage <recording> <out_dir>`` (:func:`jident_ros.bag.salvage.salvage`)."""
from __future__ import annotations

import sys

from mcap.exceptions import McapError

from jident_ros.bag.errors import RecordingError, SalvageError
from jident_ros.bag.salvage import salvage, salvage_report_line
from jident_ros.cli.argtypes import raising_parser

__all__ = ["salvage_main"]


def salvage_main(argv: list[str] | None = None) -> int:
    """``jident salvage <recording> <out_dir>``: prints one line and returns 0 (the readable part was
    written: how much was lost and why is on that line), or prints a one-line error naming the file and
    returns 2."""
    parser = raising_parser(SalvageError, prog="jident salvage",
                            description="Recover every complete chunk of a cut-off or damaged MCAP recording "
                                        "(an .mcap file or a bag directory, also a split one) into a new bag directory.")
    parser.add_argument("source", help="the .mcap file or bag directory")
    parser.add_argument("out_dir", help="new bag directory to write (must not exist)")
    parser.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd")
    try:
        args = parser.parse_args(argv)
        report = salvage(args.source, args.out_dir,
                         compression=None if args.compression == "none" else args.compression)
    except (RecordingError, OSError, McapError) as exc:
        print(f"jident salvage: error: {exc}", file=sys.stderr)
        return 2
    print(salvage_report_line(report))
    return 0
