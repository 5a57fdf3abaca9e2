"""What the `frame_sequence` numbers of a camera's frame or trigger table count.

`camera.sequences` says which counter each message type and topic gives (a message's own
frame counter, or ROS 1 header.seq per publisher); `analysis.pairing` pairs frames with
triggers by number only where both count the same thing.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SequenceCounter"]


@dataclass(frozen=True, slots=True)
class SequenceCounter:
    """What the `frame_sequence` numbers of one frame or trigger table count."""

    label: str
    """Where the numbers come from, for messages: `TriggerEvent.frame_sequence`,
    `header.seq of /cameras/meta`."""
    cameras: tuple[str, ...]
    """The cameras whose messages the counter counts (sorted; one for a camera's own)."""
    topic: str | None = None
    """The topic whose header.seq it is (None: a message field)."""

    @property
    def shared(self) -> bool:
        """Whether it counts the messages of several cameras."""
        return len(self.cameras) > 1

    def describe(self) -> str:
        """The counter in words: `header.seq of /cameras/meta (shared by a, b, c: it counts
        all their messages)`."""
        if not self.shared:
            return self.label
        names = ", ".join(self.cameras)
        return f"{self.label} (shared by cameras {names}: it counts all their messages)"
