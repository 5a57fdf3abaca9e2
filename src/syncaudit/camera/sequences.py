"""What the sequence numbers of a camera's frames and triggers count, so pairing by them is sound.

Two kinds of number end up in a camera table's `frame_sequence`:

- a message's own frame counter (`CameraExposure.frame_sequence`,
  `TriggerEvent.frame_sequence`): the frame number of the camera the message names, the
  same in the image, exposure and trigger records of one frame;
- ROS 1 `header.seq`, which roscpp and rospy fill per publisher: it counts the messages
  one publisher sent on one topic. On a topic one camera owns that is the camera's frame
  count; on a topic several cameras share (one driver node for a multi-camera board) it
  counts every camera's messages, so one camera's frames carry every third or fourth
  number and say nothing of its own frame count. (ROS 2 headers have no seq; ROS 1 bags
  converted from ROS 2, and some drivers, write 0 everywhere.)

Frames pair with triggers by number only where both numbers count the same thing: both
this camera's frames, or both the header.seq of topics shared by the very same cameras
(one driver publishing each frame on each topic in turn; the time check of
`analysis.pairing.sequence_problem` still has the last word). Otherwise frames pair by time.

The counters are `columns.sequence_counter.SequenceCounter`s (what the analysis reads); whether
two of them can pair is `analysis.pairing.incomparable`.
"""

from __future__ import annotations

from syncaudit.columns.sequence_counter import SequenceCounter

__all__ = ["SequenceCounter", "field_counter", "header_seq_counter"]


def field_counter(msgtype: str, camera: str) -> SequenceCounter:
    """The frame counter a message type carries in its `frame_sequence` field."""
    return SequenceCounter(f"{msgtype.rsplit('/', 1)[-1]}.frame_sequence", (camera,))


def header_seq_counter(topic: str | None, cameras: tuple[str, ...]) -> SequenceCounter:
    """ROS 1 header.seq of `topic`, which `cameras` read (sorted)."""
    where = f"header.seq of {topic}" if topic else "header.seq"
    return SequenceCounter(where, tuple(sorted(cameras)), topic)
