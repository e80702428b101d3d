"""``jident samples <recording> <out_dir>``: the recording's drive/signals one sample per message, stamped with
drive time, for plotting in Foxglove / PlotJuggler (:mod:`jident_ros.bag.per_sample`; config/foxglove_layout.json)."""
from __future__ import annotations

import sys

from jident_ros.bag.errors import RecordingError
from jident_ros.bag.per_sample import write_per_sample
from jident_ros.cli.argtypes import raising_parser

__all__ = ["samples_main"]


def samples_main(argv: list[str] | None = None) -> int:
    """Prints one line and returns 0, or one error line and 2."""
    parser = raising_parser(RecordingError, prog="jident samples",
                            description="Write a recording's drive/signals as one message per sample on /drive/sample, "
                                        "log time = drive time t (a new bag for Foxglove: config/foxglove_layout.json).")
    parser.add_argument("recording", help="bag directory or .mcap file")
    parser.add_argument("out_dir", help="new bag directory to write (must not exist)")
    try:
        args = parser.parse_args(argv)
        counts = write_per_sample(args.recording, args.out_dir,
                                  note=lambda text: print(f"jident samples: {text}", file=sys.stderr))
    except (RecordingError, OSError, ValueError) as exc:
        print(f"jident samples: error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.out_dir}: " + ", ".join(f"{t} {n}" for t, n in sorted(counts.items())))
    return 0
