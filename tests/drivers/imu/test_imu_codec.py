"""Codec of one ICM-20948 burst: known bytes, round trips, and garbage in -> only
ImuProtocolError out."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.imu import registers as reg
from drivers.imu.codec import ImuRanges, RawImuSample, decode_burst, decode_fifo, encode_burst
from drivers.imu.errors import ImuProtocolError

G = 9.80665
ALL_RANGES = [ImuRanges(a, g) for a in (2, 4, 8, 16) for g in (250, 500, 1000, 2000)]


def burst(accel=(0, 0, 0), gyro=(0, 0, 0), temp=0, st1=0x01, mag=(0, 0, 0), st2=0x00) -> bytes:
    return struct.pack(">7h", *accel, *gyro, temp) + struct.pack("<BhhhBB", st1, *mag, 0, st2)


def test_burst_layout_matches_the_register_map() -> None:
    assert reg.BURST_START == 0x2D
    assert reg.BURST_LENGTH == 23 <= reg.SMBUS_BLOCK_MAX
    assert reg.bank_select_value(2) == 0x20
    with pytest.raises(ValueError, match="0..3"):
        reg.bank_select_value(4)


def test_known_burst_decodes_to_si_units() -> None:
    # +-4 g: 8192 LSB/g; +-500 dps: 65.5 LSB/dps; 333.87 LSB/degC around 21 degC
    data = burst(
        accel=(8192, -4096, 16384),
        gyro=(655, -131, 0),
        temp=3339,
        st1=0x03,
        mag=(100, 200, -300),
    )
    sample = decode_burst(data, ImuRanges(accel_full_scale_g=4, gyro_full_scale_dps=500))
    assert sample.accel_m_s2 == pytest.approx((G, -G / 2, 2 * G))
    assert sample.gyro_rad_s == pytest.approx((math.radians(10.0), math.radians(-2.0), 0.0))
    assert sample.temperature_degc == pytest.approx(21.0 + 3339 / 333.87)
    # AK09916 die axes -> accel/gyro frame: X kept, Y and Z negated; 0.15 uT/LSB
    assert sample.mag_ut == pytest.approx((15.0, -30.0, 45.0))
    assert sample.mag_data_ready and sample.mag_data_overrun and not sample.mag_overflow


def test_magnetic_overflow_is_flagged_not_returned_as_data() -> None:
    sample = decode_burst(burst(mag=(32752, 32752, 32752), st2=0x08), ImuRanges())
    assert sample.mag_overflow
    assert sample.mag_ut is None
    assert sample.accel_m_s2 == (0.0, 0.0, 0.0)


def test_stale_magnetometer_value_is_marked_not_ready() -> None:
    sample = decode_burst(burst(st1=0x00, mag=(1, 1, 1)), ImuRanges())
    assert not sample.mag_data_ready
    assert sample.mag_ut == pytest.approx((0.15, -0.15, -0.15))


@pytest.mark.parametrize("length", [0, 1, 14, 22, 24, 32])
def test_wrong_length_raises_protocol_error(length: int) -> None:
    with pytest.raises(ImuProtocolError, match="23 bytes"):
        decode_burst(bytes(length), ImuRanges())


@pytest.mark.parametrize(("st1", "st2"), [(0x04, 0x00), (0x80, 0x00), (0x01, 0x01), (0x01, 0x80)])
def test_status_bytes_with_reserved_bits_are_rejected(st1: int, st2: int) -> None:
    with pytest.raises(ImuProtocolError, match="reserved bits"):
        decode_burst(burst(st1=st1, st2=st2), ImuRanges())


def test_magnetometer_counts_outside_the_ak09916_range_are_rejected() -> None:
    with pytest.raises(ImuProtocolError, match="32752"):
        decode_burst(burst(mag=(0, -32768, 0)), ImuRanges())
    # ... unless HOFL already says the data are meaningless
    assert decode_burst(burst(mag=(0, -32768, 0), st2=0x08), ImuRanges()).mag_ut is None


@pytest.mark.parametrize("junk", [23, "x" * 23, [256] * 23, [-1] * 23, None, 1.5])
def test_non_byte_input_raises_protocol_error(junk: object) -> None:
    with pytest.raises(ImuProtocolError):
        decode_burst(junk, ImuRanges())  # type: ignore[arg-type]


def test_ranges_are_validated() -> None:
    with pytest.raises(ValueError, match="accel_full_scale_g"):
        ImuRanges(accel_full_scale_g=3)
    with pytest.raises(ValueError, match="gyro_full_scale_dps"):
        ImuRanges(gyro_full_scale_dps=300)
    assert ImuRanges(16, 2000).accel_fs_sel == 3
    assert ImuRanges(2, 250).gyro_fs_sel == 0


def test_sample_requires_mag_none_exactly_on_overflow() -> None:
    with pytest.raises(ValueError, match="mag_ut"):
        RawImuSample((0, 0, 0), (0, 0, 0), 20.0, None, mag_overflow=False)
    with pytest.raises(ValueError, match="accel_m_s2"):
        RawImuSample((0, 0, math.nan), (0, 0, 0), 20.0, (0, 0, 0))


def test_encode_saturates_at_full_scale_like_the_sensor() -> None:
    ranges = ImuRanges(accel_full_scale_g=2, gyro_full_scale_dps=250)
    sample = RawImuSample((100.0, -100.0, 0.0), (100.0, 0.0, 0.0), 25.0, (10000.0, 0.0, 0.0))
    decoded = decode_burst(encode_burst(sample, ranges), ranges)
    assert decoded.accel_m_s2[0] == pytest.approx(32767 * G / 16384)
    assert decoded.accel_m_s2[1] == pytest.approx(-32768 * G / 16384)
    assert decoded.gyro_rad_s[0] == pytest.approx(math.radians(32767 / 131.0))
    assert decoded.mag_ut[0] == pytest.approx(32752 * 0.15)  # type: ignore[index]


def _in_range_vector(limit: float) -> st.SearchStrategy[tuple[float, float, float]]:
    component = st.floats(min_value=-limit, max_value=limit, allow_nan=False)
    return st.tuples(component, component, component)


@st.composite
def samples_and_ranges(draw: st.DrawFn) -> tuple[RawImuSample, ImuRanges]:
    ranges = draw(st.sampled_from(ALL_RANGES))
    accel_limit = 0.99 * ranges.accel_full_scale_g * G
    gyro_limit = 0.99 * math.radians(ranges.gyro_full_scale_dps)
    overflow = draw(st.booleans())
    mag = None if overflow else draw(_in_range_vector(4000.0))
    sample = RawImuSample(
        accel_m_s2=draw(_in_range_vector(accel_limit)),
        gyro_rad_s=draw(_in_range_vector(gyro_limit)),
        temperature_degc=draw(st.floats(min_value=-40.0, max_value=85.0)),
        mag_ut=mag,
        mag_data_ready=draw(st.booleans()),
        mag_data_overrun=draw(st.booleans()),
        mag_overflow=overflow,
    )
    return sample, ranges


@settings(max_examples=200, deadline=None)
@given(samples_and_ranges())
def test_round_trip_within_half_an_lsb(case: tuple[RawImuSample, ImuRanges]) -> None:
    sample, ranges = case
    decoded = decode_burst(encode_burst(sample, ranges), ranges)
    half_accel = ranges.accel_m_s2_per_lsb / 2 + 1e-12
    half_gyro = ranges.gyro_rad_s_per_lsb / 2 + 1e-12
    assert all(abs(a - b) <= half_accel for a, b in zip(decoded.accel_m_s2, sample.accel_m_s2))
    assert all(abs(a - b) <= half_gyro for a, b in zip(decoded.gyro_rad_s, sample.gyro_rad_s))
    assert abs(decoded.temperature_degc - sample.temperature_degc) <= 0.5 / 333.87 + 1e-12
    assert decoded.mag_overflow == sample.mag_overflow
    assert (decoded.mag_data_ready, decoded.mag_data_overrun) == (sample.mag_data_ready, sample.mag_data_overrun)
    if sample.mag_ut is None:
        assert decoded.mag_ut is None
    else:
        assert decoded.mag_ut is not None
        assert all(abs(a - b) <= 0.075 + 1e-9 for a, b in zip(decoded.mag_ut, sample.mag_ut))


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64), st.sampled_from(ALL_RANGES))
def test_arbitrary_bytes_raise_only_protocol_error(data: bytes, ranges: ImuRanges) -> None:
    try:
        sample = decode_burst(data, ranges)
    except ImuProtocolError:
        return
    assert len(data) == 23
    # a decodable burst round-trips exactly (every field is an integer count)
    assert decode_burst(encode_burst(sample, ranges), ranges) == sample


@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=23, max_size=23), st.sampled_from(ALL_RANGES))
def test_any_23_bytes_either_decode_or_raise_protocol_error(data: bytes, ranges: ImuRanges) -> None:
    st1, st2 = data[14], data[22]
    counts = struct.unpack_from("<hhh", data, 15)
    out_of_range = not st2 & 0x08 and max(abs(c) for c in counts) > 32752
    if st1 & 0xFC or st2 & 0x87 or out_of_range:
        with pytest.raises(ImuProtocolError):
            decode_burst(data, ranges)
        return
    sample = decode_burst(data, ranges)
    assert sample.mag_overflow == bool(st2 & 0x08)
    assert (sample.mag_ut is None) == sample.mag_overflow


def test_fifo_records_decode_oldest_first() -> None:
    records = burst(accel=(8192, 0, 0)) + burst(accel=(0, 8192, 0)) + burst(accel=(0, 0, 8192))
    samples = decode_fifo(records, ImuRanges(accel_full_scale_g=4))
    assert [s.accel_m_s2 for s in samples] == [pytest.approx(v) for v in ((G, 0, 0), (0, G, 0), (0, 0, G))]
    assert decode_fifo(b"", ImuRanges()) == []


@pytest.mark.parametrize("length", [1, 22, 24, 45, 47])
def test_fifo_data_cut_mid_record_raises_protocol_error(length: int) -> None:
    with pytest.raises(ImuProtocolError, match="whole number of 23-byte records"):
        decode_fifo(bytes(length), ImuRanges())


@settings(max_examples=100, deadline=None)
@given(st.lists(samples_and_ranges(), min_size=1, max_size=8))
def test_fifo_round_trip_matches_one_burst_per_record(cases: list[tuple[RawImuSample, ImuRanges]]) -> None:
    ranges = cases[0][1]
    data = b"".join(encode_burst(sample, ranges) for sample, _ in cases)
    assert decode_fifo(data, ranges) == [decode_burst(encode_burst(s, ranges), ranges) for s, _ in cases]


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=120), st.sampled_from(ALL_RANGES))
def test_arbitrary_fifo_bytes_raise_only_protocol_error(data: bytes, ranges: ImuRanges) -> None:
    try:
        samples = decode_fifo(data, ranges)
    except ImuProtocolError:
        return
    assert len(samples) * 23 == len(data)
