"""LZ4 frame layouts real ROS 1 writers produce, as `lz4.frame.compress` keyword arguments.

Shared by the frame decoder's tests and the ROS 1 bag reader's tests.
"""

from __future__ import annotations

import lz4.frame

LZ4_LAYOUTS: dict[str, dict[str, object]] = {
    # rosbags' writer: lz4.frame.compress defaults (linked 64 KiB blocks, a content size)
    "rosbags": {"block_size": lz4.frame.BLOCKSIZE_MAX64KB, "store_size": True},
    # roslz4 (rosbag): independent 1 MiB blocks, a content checksum, no content size
    "roslz4": {
        "block_size": lz4.frame.BLOCKSIZE_MAX1MB,
        "block_linked": False,
        "content_checksum": True,
        "store_size": False,
    },
    # the LZ4 library's other options: block checksums too
    "block-checksums": {
        "block_size": lz4.frame.BLOCKSIZE_MAX256KB,
        "block_checksum": True,
        "content_checksum": True,
    },
}
