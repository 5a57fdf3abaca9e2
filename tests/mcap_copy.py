"""An MCAP file copied message by message by the `mcap` library, optionally re-chunked or
with payloads changed: how tests make logs another writer would have written, or damage
one message of a real layout."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.writer import CompressionType, Writer

Change = Callable[[Schema, Channel, Message], bytes]
"""A message's new payload (return `message.data` to keep it)."""


def copy_mcap(
    src: Path, dst: Path, *, chunk_size: int = 1024 * 1024, change: Change | None = None
) -> Path:
    """`src` written again to `dst` in chunks of `chunk_size` (zstd), each message's payload
    passed through `change`; `dst`."""
    with src.open("rb") as f_in, dst.open("wb") as f_out:
        reader = make_reader(f_in)
        writer = Writer(f_out, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        writer.start(profile=reader.get_header().profile, library="syncaudit tests")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema is not None
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id], channel.metadata
                )
            data = message.data if change is None else change(schema, channel, message)
            writer.add_message(
                channels[channel.id], message.log_time, data, message.publish_time, message.sequence
            )
        writer.finish()  # type: ignore[no-untyped-call]
    return dst
