"""One pass over a LiDAR topic: revolutions, cadence, clock — everything timing needs.

The packets are read by `logs.parallel` (worker processes where the log allows), each
message reduced there to two timing samples per packet (`packet_samples_of`); the
`LidarScanner` then folds them, in log order, into a `columns.lidar.LidarScan`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from syncaudit.columns.lidar import ClockReport, LidarScan
from syncaudit.lidar import ouster
from syncaudit.lidar.clock import ClockEstimator
from syncaudit.lidar.revolutions import RevolutionTracker
from syncaudit.lidar.samples import PacketSamples, concat_samples, packet_samples
from syncaudit.lidar.stream import decode_ouster_message, decode_scan, packet_family
from syncaudit.logs import LogReader, RawMessage
from syncaudit.logs.parallel import WholeMessages, iter_items

__all__ = ["LidarScan", "LidarScanner", "PacketExtractor", "packet_samples_of", "scan_lidar"]


KEEP_PACKETS = 1_000_000
"""Packets whose samples a `keep_samples` scanner keeps at most (~40 MB): the first ones
(at least its first batch); past them it keeps none more and `kept_all` turns False
(`retracked` then cannot)."""
FEED_PACKETS = 4096
"""Packets gathered before the tracker and clock run: their numpy work per call is then
amortised over several scans (or many single-packet messages), memory still bounded."""


@dataclass(slots=True)
class LidarScanner:
    """Reduces decoded packet chunks, fed in log order, to a LidarScan."""

    topic: str
    tracker: RevolutionTracker
    clock: ClockEstimator
    vendor: str = ""
    model: str = ""
    scans: int = 0
    packets: int = 0
    modes: set[int] = field(default_factory=set)
    dual: bool = False
    declared_rpm_sum: float = 0.0
    declared_rpm_count: int = 0
    wrap_blocks: int = 0
    product_id_model: str = ""
    notes: dict[str, None] = field(default_factory=dict)
    keep_samples: bool = False
    """Keep the batches fed, so `retracked` can find the revolutions again at another zero
    azimuth (the audit's guessed one) without reading the log twice: ~40 bytes a packet,
    up to KEEP_PACKETS packets (a longer log is read again instead)."""
    kept_all: bool = True
    """Every batch fed is kept (False once KEEP_PACKETS was passed)."""
    _kept_packets: int = 0
    _pending: list[PacketSamples] = field(default_factory=list)
    _pending_packets: int = 0
    _kept: list[PacketSamples] = field(default_factory=list)
    _clock: ClockReport | None = None

    @classmethod
    def create(
        cls,
        topic: str,
        *,
        zero_azimuth_deg: float = 0.0,
        azimuth_increases: bool = True,
        target_azimuth_deg: tuple[float, ...] = (),
        clock_tolerance_ns: int = 50_000_000,
        keep_samples: bool = False,
    ) -> LidarScanner:
        """A scanner for one topic with the rig's zero crossing and target azimuths."""
        tracker = RevolutionTracker(
            zero_azimuth_deg=zero_azimuth_deg,
            direction=1 if azimuth_increases else -1,
            target_azimuth_deg=target_azimuth_deg,
        )
        return cls(
            topic,
            tracker,
            ClockEstimator(tolerance_ns=clock_tolerance_ns),
            keep_samples=keep_samples,
        )

    def feed(self, samples: PacketSamples, messages: int = 1) -> None:
        """Add one scan message (or a batch of `messages` single-packet messages)."""
        self.vendor, self.model = samples.vendor, samples.model
        self.scans += messages
        self.packets += samples.n_packets
        self.modes.update(samples.return_modes)
        self.dual = self.dual or samples.dual_return
        self.declared_rpm_sum += samples.declared_rpm_sum
        self.declared_rpm_count += samples.declared_rpm_count
        self.wrap_blocks += samples.wrap_blocks
        self.product_id_model = self.product_id_model or samples.product_id_model
        for note in samples.notes:
            self.notes.setdefault(note)
        self._pending.append(samples)
        self._pending_packets += samples.n_packets
        if self._pending_packets >= FEED_PACKETS:
            self._flush()

    def _flush(self) -> None:
        """Run the tracker and the clock over the gathered packets."""
        if not self._pending:
            return
        batch = concat_samples(self._pending)
        self._pending, self._pending_packets = [], 0
        if self.keep_samples and self.kept_all:
            if not self._kept or self._kept_packets + batch.n_packets <= KEEP_PACKETS:
                self._kept.append(batch)
                self._kept_packets += batch.n_packets
            else:
                self.kept_all = False
        self.tracker.feed(batch)
        self.clock.feed(batch.driver_stamp_ns, batch.sensor_time_ns)

    def finish(self) -> LidarScan:
        """The reduced timing of everything fed."""
        self._flush()
        self._clock = self.clock.finish()
        return self._scan(self.tracker)

    def retracked(self, zero_azimuth_deg: float) -> LidarScan:
        """The scan `finish` gave, its revolutions found again from `zero_azimuth_deg`.

        Needs `keep_samples`; the result is what a scanner created with that zero azimuth
        gives for the same packets (the same tracker fed the same batches).
        """
        if not self.keep_samples or not self.kept_all:
            raise ValueError("retracked needs a scanner that kept every batch (keep_samples)")
        tracker = RevolutionTracker(
            zero_azimuth_deg=zero_azimuth_deg,
            direction=self.tracker.direction,
            target_azimuth_deg=self.tracker.target_azimuth_deg,
        )
        for batch in self._kept:
            tracker.feed(batch)
        return self._scan(tracker)

    def packet_azimuth_deg(self, sensor_ns: NDArray[np.int64]) -> NDArray[np.float64]:
        """The packet azimuth at each sensor time, between the kept samples (NaN outside
        them, e.g. past the first KEEP_PACKETS packets).

        The forward step between the two samples around a time is interpolated, so a
        time at a sample is that sample's azimuth; a step of 90 deg or more (a gap) is NaN.
        """
        out = np.full(sensor_ns.shape, np.nan)
        if not self._kept or not sensor_ns.size:
            return out
        times = np.concatenate([b.sample_time_ns for b in self._kept])
        azimuth = (
            self.tracker.direction * np.concatenate([b.sample_azimuth_deg for b in self._kept])
        ) % 360.0  # oriented: grows with rotation
        n = times.size
        right = np.searchsorted(times, sensor_ns, side="left")  # first sample at/after
        at = np.minimum(right, n - 1)
        exact = (right < n) & (times[at] == sensor_ns)
        right = np.clip(right, 1, max(n - 1, 1))
        left = right - 1
        step = (azimuth[right] - azimuth[left]) % 360.0
        dt = (times[right] - times[left]).astype(np.float64)
        safe = np.where(dt > 0, dt, 1.0)
        between = (sensor_ns > times[left]) & (sensor_ns < times[right]) & (dt > 0) & (step < 90.0)
        oriented = np.where(
            exact, azimuth[at], azimuth[left] + step * (sensor_ns - times[left]) / safe
        )
        ok = exact | between
        out[ok] = (self.tracker.direction * oriented[ok]) % 360.0
        return out

    def _scan(self, tracker: RevolutionTracker) -> LidarScan:
        return LidarScan(
            topic=self.topic,
            vendor=self.vendor,
            model=self.model,
            scans=self.scans,
            packets=self.packets,
            return_modes=tuple(sorted(self.modes)),
            dual_return=self.dual,
            revolutions=tracker.finish(),
            clock=self._clock,
            omega_blocks_deg_s=tracker.omega_blocks_deg_s,
            cropped_sector=tracker.cropped_sector(),
            outlier_blocks=tracker.outlier_blocks,
            whole_turns=tracker.whole_turns,
            declared_rpm=self.declared_rpm_sum / self.declared_rpm_count
            if self.declared_rpm_count
            else float("nan"),
            wrap_blocks=self.wrap_blocks,
            product_id_model=self.product_id_model,
            decoder_notes=tuple(self.notes),
        )


def packet_samples_of(
    msg: RawMessage,
    family: str,
    ouster_meta: ouster.OusterMetadata | None,
    model: str | None = None,
) -> PacketSamples | None:
    """The timing samples of one packet message of `family` (None: no packet in it, e.g.
    an IMU-sized Ouster message); Ouster needs the sensor metadata, `model` is the rig's."""
    if family == "ouster":
        assert ouster_meta is not None
        chunk = decode_ouster_message(msg, ouster_meta)
    else:
        chunk = decode_scan(family, msg, 0, model)
    if chunk is None:
        return None
    return packet_samples(chunk.timing, chunk.driver_stamp_ns)


@dataclass(frozen=True, slots=True)
class PacketExtractor(WholeMessages):
    """What `logs.parallel` makes of one LiDAR topic's messages: their packets' timing
    samples (picklable for worker processes)."""

    family: str
    ouster_meta: ouster.OusterMetadata | None = None
    model: str | None = None
    """The model the rig states (`lidar.model`), else None: the packets tell."""

    def extract(self, msg: RawMessage, log: LogReader) -> PacketSamples | None:
        """The samples of one packet message."""
        return packet_samples_of(msg, self.family, self.ouster_meta, self.model)


def scan_lidar(
    log: LogReader,
    topic: str,
    *,
    zero_azimuth_deg: float = 0.0,
    azimuth_increases: bool = True,
    target_azimuth_deg: tuple[float, ...] = (),
    clock_tolerance_ns: int = 50_000_000,
    ouster_metadata_topic: str | None = None,
    jobs: int = 1,
    model: str | None = None,
) -> LidarScan:
    """Read the topic once, as the audit reads it (`logs.parallel.iter_items`: `jobs`
    worker processes where the log allows, one scan message at a time), and reduce it to
    revolutions and clock statistics."""
    family, meta = packet_family(log, topic, ouster_metadata_topic)
    scanner = LidarScanner.create(
        topic,
        zero_azimuth_deg=zero_azimuth_deg,
        azimuth_increases=azimuth_increases,
        target_azimuth_deg=target_azimuth_deg,
        clock_tolerance_ns=clock_tolerance_ns,
    )
    for samples in iter_items(log, PacketExtractor(topic, family, meta, model), jobs):
        scanner.feed(samples)
    return scanner.finish()
