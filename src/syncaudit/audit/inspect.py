"""`inspect_log`: what a log holds for a sync audit, as the `info` command shows it.

`info` and `audit` agree on what is damaged: the LiDAR topic the audit would use (the
rig's, else the first packet topic by name) is scanned the same way, and where that
fails (damaged packets, unreadable encoding, a rig contradicting the packets) the report
records the error and its exit code. By default `inspect_log` then raises it (so `info`
exits as `audit` would); with `partial=True` it returns the report with `error` and
`exit_code` set, for a caller that prints what could be read and then exits non-zero.

The cameras are the rig's, else the ones `audit` guesses (`rig_guess.guess_cameras`): a
topic several cameras share is counted per camera as the audit routes its messages
(`camera.census`), so `info` shows each camera's own frames and the frame ids seen.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from syncaudit.audit.cloud_info import cloud_agreement, info_cloud_scan
from syncaudit.audit.health import check_chunk_crcs, log_health, no_packets_error
from syncaudit.audit.probe import LogProbe
from syncaudit.audit.rig_check import check_rig_against_log
from syncaudit.audit.rig_guess import guess_cameras
from syncaudit.camera.camera_topics import EXPOSURE_TYPES, TRIGGER_TYPES, detect_cameras
from syncaudit.camera.census import SharedCensus, shared_topic_census
from syncaudit.camera.routing import SharedTopicCount
from syncaudit.columns.lidar import LidarScan
from syncaudit.errors import NoDataError, SyncauditError
from syncaudit.lidar.cloud_scan import is_cloud_type
from syncaudit.lidar.cloud_topics import guess_cloud_topics
from syncaudit.lidar.scan import scan_lidar
from syncaudit.logs import LogReader, open_log
from syncaudit.logs.parallel import default_jobs
from syncaudit.rig import CameraConfig, Rig
from syncaudit.units import json_ready

CHECKPOINTS_BY_TYPE: dict[str, tuple[int, ...]] = {
    "syncaudit_msgs/msg/TriggerEvent": (240, 242, 244, 246, 248),
    "builtin_interfaces/msg/Time": (246,),
    "sensor_msgs/msg/TimeReference": (246,),
}
"""Checkpoints of the trigger chain each trigger message type records."""


@dataclass(frozen=True, slots=True)
class TopicRow:
    """One line of the topic table."""

    name: str
    msgtype: str
    count: int | None
    rate_hz: float | None


@dataclass(frozen=True, slots=True)
class LidarRow:
    """What the packets of one LiDAR topic say."""

    topic: str
    vendor: str
    model: str
    scans: int
    packets: int
    revolutions: int
    rpm: float
    packets_per_revolution: float
    dropped_packets: int
    dual_return: bool
    cropped_sector: str | None
    outlier_blocks: int
    clock_offset_s: float | None
    clock_synchronised: bool | None
    t1_p50_us: float | None
    t1_p99_us: float | None
    azimuth_36000_blocks: int = 0
    """Blocks whose azimuth read 36000 (the wrap), taken as 0 (modulo 36000)."""


@dataclass(frozen=True, slots=True)
class CameraRow:
    """What the topics of one camera say."""

    name: str
    image_topic: str | None
    frames: int
    """Its images: the image topic's messages, or those naming it on a shared topic."""
    rate_hz: float | None
    exposure_metadata: str | None
    stamp_semantics: str
    trigger_topic: str | None
    checkpoints: tuple[int, ...]
    frame_id: str | None = None
    """The header.frame_id its messages carry (rig, or the frame the image topic showed)."""
    shared_topics: tuple[str, ...] = ()
    """Its topics that other cameras read too (messages told apart by frame id)."""
    trigger_design: str | None = None
    """The trigger design its records look like (audit.design_info) ..."""
    trigger_design_why: str | None = None
    """... and why."""


@dataclass(frozen=True, slots=True)
class SharedTopicRow:
    """A topic several cameras share: which camera its messages went to, as `audit` routes them."""

    topic: str
    kind: str
    """'image', 'exposure' or 'trigger'."""
    msgtype: str
    messages: int
    cameras: dict[str, int]
    """Camera name -> messages it gets."""
    frame_ids: dict[str, int]
    """header.frame_id seen -> messages carrying it ("" for none)."""
    unnamed: int
    """Messages naming no camera (no frame id, no camera field)."""
    unknown: dict[str, int]
    """Messages naming a frame or camera of no camera of the topic, by what they name."""
    damaged: int


@dataclass(slots=True)
class InfoReport:
    """The `info` summary of one log."""

    path: str
    container: str
    start_ns: int | None
    end_ns: int | None
    duration_s: float | None
    messages: int | None
    topics: list[TopicRow] = field(default_factory=list)
    lidars: list[LidarRow] = field(default_factory=list)
    cameras: list[CameraRow] = field(default_factory=list)
    shared_topics: list[SharedTopicRow] = field(default_factory=list)
    guessed: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    error: str | None = None
    """Why the audit's LiDAR topic cannot be read (None where it can)."""
    exit_code: int = 0
    """The exit code `audit` gives on this log for that error (0 where none)."""
    health: dict[str, Any] = field(default_factory=dict)
    """The file's condition as `audit` records it (`audit.health.LogHealth.to_dict`)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form; NaN becomes None."""
        cleaned: dict[str, Any] = json_ready(asdict(self))
        return cleaned


def lidar_row(scan: LidarScan, *, offset_ns: int | None = None) -> LidarRow:
    """The table row of a scanned LiDAR topic.

    `offset_ns` is the host-minus-sensor offset the audit measured (from its triggers):
    the row then shows the one offset the analysis used, as the warning and JSON do.
    """
    clock = scan.clock
    return LidarRow(
        topic=scan.topic,
        vendor=scan.vendor,
        model=scan.model,
        scans=scan.scans,
        packets=scan.packets,
        revolutions=scan.whole_turns,  # whole turns: the same whatever the zero azimuth
        rpm=scan.rpm,
        packets_per_revolution=scan.packets_per_revolution,
        dropped_packets=scan.dropped_packets,
        dual_return=scan.dual_return,
        cropped_sector=None
        if scan.cropped_sector is None
        else f"{scan.cropped_sector[1]:.0f} packets/turn are never recorded before the "
        f"sector resumes {scan.cropped_sector[0]:.0f} deg past the zero crossing, in "
        f"{scan.cropped_sector[2]} revolutions (FOV-cropped recording, not counted as drops)",
        outlier_blocks=scan.outlier_blocks,
        # Host minus sensor as the audit uses it (0 when synchronised, else the minimum
        # filter); `audit` replaces it with the trigger-based offset where it has one.
        clock_offset_s=None
        if clock is None
        else (clock.offset_ns if offset_ns is None else offset_ns) / 1e9,
        clock_synchronised=None if clock is None else clock.synchronised,
        t1_p50_us=None if clock is None else clock.t1_p50_ns / 1e3,
        t1_p99_us=None if clock is None else clock.t1_p99_ns / 1e3,
        azimuth_36000_blocks=scan.wrap_blocks,
    )


def lidar_warnings(row: LidarRow) -> list[str]:
    """What `info` and `audit` both warn about a LiDAR: a FOV-cropped recording, ignored blocks."""
    warnings = []
    if row.cropped_sector:
        warnings.append(f"{row.topic}: {row.cropped_sector}")
    if row.outlier_blocks:
        warnings.append(
            f"{row.topic}: {row.outlier_blocks} blocks ignored, their azimuth contradicts their packet"
        )
    if row.azimuth_36000_blocks:
        warnings.append(
            f"{row.topic}: {row.azimuth_36000_blocks} "
            f"block{'s' if row.azimuth_36000_blocks != 1 else ''} read azimuth 36000 (the "
            "wrap, as real sensors write it), taken as 0"
        )
    return warnings


def inspect_log(
    path: str | Path,
    rig: Rig | None = None,
    *,
    partial: bool = False,
    jobs: int | None = None,
    lidar_metadata: str | Path | None = None,
    lidar_capture: str | Path | None = None,
    check_crc: bool = False,
) -> InfoReport:
    """Summarise a log: container, topics, LiDARs (measured), cameras and trigger records.

    Raises the error that makes `audit` fail on the LiDAR topic, unless `partial`: then
    the report is returned with `error` and `exit_code` set. `jobs` worker processes read
    the LiDAR and shared camera topics where the log allows, as `audit` does (default:
    one per core). `lidar_metadata` / `lidar_capture`: as `logs.open_log`.
    one per core). `check_crc` verifies every MCAP chunk's CRC for the report's `health`.
    """
    with open_log(path, lidar_metadata=lidar_metadata, lidar_capture=lidar_capture) as log:
        report, failure = _inspect(log, rig, default_jobs() if jobs is None else max(1, jobs))
        crc_check = check_chunk_crcs(log) if check_crc else None
        report.health = log_health(
            log.warnings, report.warnings, failure=failure, crc_check=crc_check
        ).to_dict()
    if failure is not None and not partial:
        raise failure
    return report


def _inspect(
    log: LogReader, rig: Rig | None, jobs: int
) -> tuple[InfoReport, SyncauditError | None]:
    summary = log.summary
    probe = LogProbe(log)
    duration = summary.duration_s
    report = InfoReport(
        path=summary.path,
        container=summary.container,
        start_ns=summary.start_ns,
        end_ns=summary.end_ns,
        duration_s=duration,
        messages=summary.message_count,
    )
    for info in sorted(log.topics.values(), key=lambda t: t.name):
        rate = info.count / duration if info.count and duration else None
        report.topics.append(TopicRow(info.name, info.msgtype, info.count, rate))
    if summary.message_count == 0:
        raise NoDataError(f"{summary.path}: the log holds no messages")
    guess = None if rig else probe.lidar_guess()
    lidar_topics = [rig.lidar.topic] if rig else guess.topics if guess else []
    if guess is not None and lidar_topics:
        report.guessed.append(f"LiDAR packet topics by type: {', '.join(lidar_topics)}")
    clouds = guess_cloud_topics(log, rig.lidar.time_field if rig else None)
    if not lidar_topics and clouds.topics:
        lidar_topics = clouds.topics[:1]
        report.guessed.append(f"LiDAR cloud topics by type and fields: {', '.join(clouds.topics)}")
    report.warnings.extend(guess.notes if guess else [])
    # The topic `audit` would use decides: the rig's, else the first guessed by name.
    audited = rig.lidar.topic if rig else (lidar_topics[0] if lidar_topics else None)
    failure: SyncauditError | None = None
    if rig is not None:
        try:
            rig, skipped = check_rig_against_log(probe, rig)
            report.warnings.extend(skipped)
        except SyncauditError as exc:
            failure = exc
    first_problem: SyncauditError | None = None
    scans: dict[str, LidarScan] = {}
    for topic in lidar_topics:
        if failure is not None and topic == audited:
            continue
        try:
            if topic not in log.topics:
                raise NoDataError(f"LiDAR topic {topic} (from the rig) is not in the log")
            if is_cloud_type(log.topics[topic].msgtype):
                scan, notes = info_cloud_scan(log, topic, rig, None, jobs)
                report.warnings.extend(notes)
                report.lidars.append(lidar_row(scan))
                continue
            scan = scan_lidar(
                log,
                topic,
                zero_azimuth_deg=rig.lidar.zero_azimuth_deg if rig else 0.0,
                azimuth_increases=rig.lidar.azimuth_increases if rig else True,
                ouster_metadata_topic=rig.lidar.metadata_topic if rig else None,
                jobs=jobs,
                model=rig.lidar.model if rig else None,
            )
            if scan.packets == 0:
                raise no_packets_error(log, topic)
        except SyncauditError as exc:
            if topic == audited:
                failure = exc
                continue
            first_problem = first_problem or exc
            if isinstance(exc, NoDataError) and "holds no packets" in str(exc):
                report.warnings.append(f"{topic}: no LiDAR data packets (e.g. an IMU packet topic)")
            else:
                report.warnings.append(f"{topic}: {exc}")
            continue
        scans[topic] = scan
        row = lidar_row(scan)
        report.lidars.append(row)
        report.warnings.extend(scan.warnings)
        report.warnings.extend(lidar_warnings(row))
    if failure is None and rig is None and not report.lidars:
        failure = first_problem
    report.warnings.extend(_check_clouds(log, probe, rig, report, clouds.topics, jobs))
    cameras = _cameras(probe, rig, report)
    try:
        census = shared_topic_census(log, cameras, jobs=jobs)
    except SyncauditError as exc:  # info goes on: the LiDAR decides its exit code
        report.warnings.append(f"topics cameras share could not be counted: {exc}")
        census = SharedCensus([], [])
    report.shared_topics.extend(_shared_row(log, count) for count in census.topics)
    report.warnings.extend(census.warnings)
    from syncaudit.audit.design_info import camera_design

    audited_scan = scans.get(audited) if audited else None
    for cam in cameras:
        design, why = camera_design(log, cam, rig, audited_scan)
        cam_row = _camera_row(log, cam, duration, census.topics)
        report.cameras.append(replace(cam_row, trigger_design=design, trigger_design_why=why))
    report.warnings.extend(w.message for w in log.warnings)
    if failure is not None:
        report.error = str(failure)
        report.exit_code = failure.exit_code
        report.warnings.append(f"the audit cannot use the LiDAR: {failure}")
    elif not lidar_topics:
        report.warnings.append("no LiDAR packet topic found: the sync audit needs one")
    if not report.cameras:
        report.warnings.append("no camera topic found: only the LiDAR side can be audited")
    return report, failure


def _check_clouds(
    log: LogReader,
    probe: LogProbe,
    rig: Rig | None,
    report: InfoReport,
    cloud_topics: list[str],
    jobs: int,
) -> list[str]:
    """Where the log has packets and clouds, whether the clouds' times agree with them."""
    scanned = {row.topic for row in report.lidars}
    packets = [row.topic for row in report.lidars if probe.family(row.topic) is not None]
    if not packets:
        return []
    notes: list[str] = []
    vendor = probe.packet_vendor(packets[0])
    reference = scan_lidar(
        log,
        packets[0],
        zero_azimuth_deg=rig.lidar.zero_azimuth_deg if rig else 0.0,
        ouster_metadata_topic=rig.lidar.metadata_topic if rig else None,
        jobs=jobs,
    )
    for topic in cloud_topics:
        try:
            scan, stamp_notes = info_cloud_scan(log, topic, None, vendor, jobs)
        except SyncauditError as exc:
            notes.append(f"{topic}: its clouds cannot be checked against the packets: {exc}")
            continue
        notes.extend(stamp_notes)
        if topic not in scanned:
            report.lidars.append(lidar_row(scan))
        notes.append(cloud_agreement(scan, reference).note())
    return notes


def _cameras(probe: LogProbe, rig: Rig | None, report: InfoReport) -> list[CameraConfig]:
    """The rig's cameras, else those the audit would guess (by topic types alone where the
    camera topics cannot be read)."""
    if rig and rig.cameras:
        return list(rig.cameras)
    try:
        cameras, notes = guess_cameras(probe)
    except SyncauditError as exc:
        cameras = detect_cameras(probe.topics)
        notes = ["cameras by topic type and name: " + ", ".join(c.name for c in cameras)]
        report.warnings.append(f"camera topics could not be read to guess the cameras: {exc}")
    report.guessed.extend(notes if cameras else [])
    return cameras


def _shared_row(log: LogReader, count: SharedTopicCount) -> SharedTopicRow:
    return SharedTopicRow(
        topic=count.topic,
        kind=count.kind,
        msgtype=log.topics[count.topic].msgtype,
        messages=sum(count.frame_ids.values()) + count.damaged,
        cameras=count.per_camera,
        frame_ids=count.frame_ids,
        unnamed=count.unnamed,
        unknown=count.unknown,
        damaged=count.damaged,
    )


def _camera_row(
    log: LogReader, cam: CameraConfig, duration: float | None, shared: list[SharedTopicCount]
) -> CameraRow:
    image = log.topics.get(cam.image_topic) if cam.image_topic else None
    exposure = log.topics.get(cam.exposure_topic) if cam.exposure_topic else None
    trigger = log.topics.get(cam.trigger_topic) if cam.trigger_topic else None
    mine = [s for s in shared if cam.name in s.cameras]
    shared_image = next((s for s in mine if s.kind == "image"), None)
    if shared_image is not None:
        frames = shared_image.per_camera[cam.name]
    else:
        frames = image.count or 0 if image else 0
    return CameraRow(
        name=cam.name,
        image_topic=cam.image_topic,
        frames=frames,
        rate_hz=frames / duration if frames and duration else None,
        exposure_metadata=exposure.msgtype
        if exposure and exposure.msgtype in EXPOSURE_TYPES
        else None,
        stamp_semantics=cam.stamp,
        trigger_topic=cam.trigger_topic,
        checkpoints=CHECKPOINTS_BY_TYPE.get(trigger.msgtype, ())
        if trigger and trigger.msgtype in TRIGGER_TYPES
        else (),
        frame_id=cam.frame_id,
        shared_topics=tuple(s.topic for s in mine),
    )
