"""The errors of the bag layer (writing, reading and salvaging rosbag2 MCAP recordings)."""


class RecordingError(RuntimeError):
    """A recording cannot be written or read (the message names the file or topic)."""


class SalvageError(RecordingError):
    """The input of :func:`salvage` is missing or is not an MCAP file."""
