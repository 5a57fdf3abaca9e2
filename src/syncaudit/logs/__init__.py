"""Reading logs: one `open_log` for MCAP, ROS 2 bags and ROS 1 bags, streaming raw messages."""

from syncaudit.logs.base import LogReader
from syncaudit.logs.model import LogSummary, LogWarning, RawMessage, TopicInfo
from syncaudit.logs.open import open_log
from syncaudit.logs.typesys import TypeRegistry

__all__ = [
    "LogReader",
    "LogSummary",
    "LogWarning",
    "RawMessage",
    "TopicInfo",
    "TypeRegistry",
    "open_log",
]
