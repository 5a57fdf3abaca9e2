"""Velodyne defects real sensors' bytes expose: azimuth 36000 at the wrap, and early VLP-16s
writing the HDL-32E's product id (told apart by the packet cadence, or the rig's model)."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.errors import DecodeError
from syncaudit.lidar import velodyne as v
from syncaudit.lidar import velodyne_encode as ve
from syncaudit.lidar.samples import packet_samples

START_NS = 1_700_000_000_000_000_000


def _packets(
    model: str, mode: int = v.RETURN_STRONGEST
) -> tuple[NDArray[np.uint8], NDArray[np.int64]]:
    sched = ve.velodyne_revolution_schedule(model, 600.0, START_NS, return_mode=mode, n_packets=40)
    data = ve.encode_velodyne(model, sched.block_azimuth_deg, sched.packet_toh_us, mode)
    return data, sched.packet_stamp_ns


def _set_azimuth(data: NDArray[np.uint8], packet: int, block: int, raw: int) -> None:
    offset = block * v.BLOCK_BYTES + 2
    data[packet, offset] = raw & 0xFF
    data[packet, offset + 1] = raw >> 8


def test_azimuth_36000_is_the_wrap_and_counted() -> None:
    data, stamps = _packets("HDL-32E")
    _set_azimuth(data, 5, 4, 36000)
    timing = v.decode_velodyne(data, stamps)
    assert timing.wrap_blocks == 1
    assert timing.block_azimuth_deg[5, 4] == 0.0
    assert packet_samples(timing, stamps).wrap_blocks == 1
    firings = v.velodyne_firing_times(data, stamps)
    assert np.all((firings.azimuth_deg >= 0) & (firings.azimuth_deg < 360))


def test_azimuth_past_36000_is_still_refused() -> None:
    data, stamps = _packets("HDL-32E")
    _set_azimuth(data, 2, 1, 36001)
    with pytest.raises(DecodeError, match="azimuth 36001 > 36000"):
        v.decode_velodyne(data, stamps)


@pytest.mark.parametrize("mode", [v.RETURN_STRONGEST, v.RETURN_DUAL])
def test_vlp16_with_the_hdl32e_id_is_told_by_its_cadence(mode: int) -> None:
    data, stamps = _packets("VLP-16", mode)
    data[:, v.PRODUCT_ID_OFFSET] = v.MODEL_PRODUCT_ID["HDL-32E"]
    timing = v.decode_velodyne(data, stamps)
    assert timing.model == "VLP-16"
    assert timing.product_id_model == "HDL-32E"
    truth = v.decode_velodyne(_packets("VLP-16", mode)[0], stamps)
    np.testing.assert_array_equal(timing.block_time_ns, truth.block_time_ns)


@pytest.mark.parametrize("mode", [v.RETURN_STRONGEST, v.RETURN_DUAL])
def test_a_real_hdl32e_stays_one(mode: int) -> None:
    data, stamps = _packets("HDL-32E", mode)
    timing = v.decode_velodyne(data, stamps)
    assert timing.model == "HDL-32E"
    assert timing.product_id_model == ""


def test_cadence_thresholds_whatever_the_rpm() -> None:
    assert v.model_by_cadence("HDL-32E", 1327.0, False) == "VLP-16"
    assert v.model_by_cadence("HDL-32E", 553.0, False) == "HDL-32E"
    assert v.model_by_cadence("VLP-16", 553.0, False) == "HDL-32E"
    assert v.model_by_cadence("HDL-32E", float("nan"), False) == "HDL-32E"
    assert v.model_by_cadence("VLP-32C", 1327.0, False) == "VLP-32C"


def test_one_packet_keeps_the_product_byte() -> None:
    data, stamps = _packets("VLP-16")
    data[:, v.PRODUCT_ID_OFFSET] = v.MODEL_PRODUCT_ID["HDL-32E"]
    assert v.decode_velodyne(data[:1], stamps[:1]).model == "HDL-32E"


def test_the_rig_states_the_model() -> None:
    data, stamps = _packets("VLP-16")
    data[:, v.PRODUCT_ID_OFFSET] = v.MODEL_PRODUCT_ID["HDL-32E"]
    timing = v.decode_velodyne(data[:1], stamps[:1], "VLP-16")
    assert timing.model == "VLP-16"
    assert timing.product_id_model == "HDL-32E"
    with pytest.raises(DecodeError, match="the rig states VLP-32C"):
        v.decode_velodyne(data, stamps, "VLP-32C")
    with pytest.raises(DecodeError, match="not a known model"):
        v.decode_velodyne(data, stamps, "VLP-99")
