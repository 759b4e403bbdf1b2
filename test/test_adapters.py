"""msg_adapters: Image round trips for every encoding, row padding, big-endian data, clear
errors, and the REP-104 CameraInfo, PoseArray and MarkerArray builders."""
import array

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from fcop_ros.core.pose import ObjectPose
from msg_adapters import (DEPTH_ENCODINGS, MASK_ENCODINGS, NOCS_ENCODINGS, ImageFormatError,
                          ImageSizeMismatch, camera_info, depth_from_image, depth_to_image,
                          frame_from_images, image_to_array, mask_from_image, mask_to_image,
                          marker_array, nocs_from_image, nocs_to_image, pose_array)

H, W = 7, 11


def depth_sample(rng):
    d = rng.uniform(0.3, 5.0, (H, W))
    d[0, 0] = np.nan
    return d


def nocs_sample(rng):
    p = rng.random((H, W, 3))
    p[1, 1] = 0.0
    return p


def repad(msg: Image, pad: int, bigendian: bool) -> Image:
    """The same pixels with ``pad`` bytes per row of padding and, optionally, big-endian words."""
    arr = image_to_array(msg)
    if bigendian:
        arr = arr.astype(arr.dtype.newbyteorder(">"))
    raw = np.frombuffer(arr.tobytes(), np.uint8).reshape(msg.height, -1)
    rows = np.concatenate([raw, np.full((msg.height, pad), 0xAB, np.uint8)], axis=1)
    out = Image(header=msg.header, height=msg.height, width=msg.width, encoding=msg.encoding,
                is_bigendian=int(bigendian), step=rows.shape[1])
    out.data = array.array("B", rows.tobytes())
    return out


@pytest.mark.parametrize("encoding", DEPTH_ENCODINGS)
@pytest.mark.parametrize("pad,big", [(0, False), (5, False), (3, True)])
def test_depth_round_trip(encoding, pad, big, rng):
    d = depth_sample(rng)
    msg = repad(depth_to_image(d, encoding), pad, big)
    back = depth_from_image(msg)
    assert back.dtype == np.float32 and back.shape == (H, W) and np.isnan(back[0, 0])
    tol = 0.0005 if encoding == "16UC1" else 1e-6 * 5
    np.testing.assert_allclose(back[1:], d[1:], atol=tol)


def test_depth_16uc1_scale_and_zero_invalid():
    msg = depth_to_image(np.array([[0.0, 1.2345, np.nan]]), "16UC1", depth_scale=0.0001)
    assert image_to_array(msg).tolist() == [[0, 12345, 0]]
    back = depth_from_image(msg, depth_scale=0.0001)
    assert np.isnan(back[0, 0]) and np.isnan(back[0, 2]) and abs(back[0, 1] - 1.2345) < 1e-6
    inf = depth_to_image(np.array([[np.inf, 1.0]]), "32FC1")
    assert np.isnan(depth_from_image(inf)[0, 0])


@pytest.mark.parametrize("encoding", NOCS_ENCODINGS)
@pytest.mark.parametrize("pad,big", [(0, False), (7, False), (2, True)])
def test_nocs_round_trip(encoding, pad, big, rng):
    p = nocs_sample(rng)
    msg = repad(nocs_to_image(p, encoding), pad, big)
    back = nocs_from_image(msg)
    tol = {"rgb8": 0.5 / 255 + 1e-6, "bgr8": 0.5 / 255 + 1e-6,
           "16UC3": 0.5 / 65535 + 1e-7}.get(encoding, 1e-6)
    np.testing.assert_allclose(back, p, atol=tol)
    assert (back[1, 1] == 0).all()


def test_bgr8_is_channel_reversed_on_the_wire():
    p = np.zeros((1, 1, 3))
    p[0, 0] = [1.0, 0.5, 0.0]
    assert list(bytes(nocs_to_image(p, "bgr8").data)) == [0, 128, 255]
    assert list(bytes(nocs_to_image(p, "rgb8").data)) == [255, 128, 0]


@pytest.mark.parametrize("encoding", MASK_ENCODINGS)
@pytest.mark.parametrize("pad,big", [(0, False), (1, False), (3, True)])
def test_mask_round_trip(encoding, pad, big, rng):
    top = 255 if encoding in ("mono8", "8UC1") else 60000
    m = rng.integers(0, top, (H, W))
    back = mask_from_image(repad(mask_to_image(m, encoding), pad, big))
    assert back.dtype == {"mono8": np.uint8, "8UC1": np.uint8, "32SC1": np.int32}.get(
        encoding, np.uint16
    )
    np.testing.assert_array_equal(back, m)


def test_clear_errors(rng):
    d = depth_to_image(depth_sample(rng), "32FC1")
    wrong = Image(height=H, width=W, encoding="rgb8", step=W * 3, data=bytes(H * W * 3))
    with pytest.raises(
        ImageFormatError,
        match=r"depth: unsupported encoding 'rgb8'; supported: 32FC1, 64FC1, 16UC1",
    ):
        depth_from_image(wrong)
    with pytest.raises(ImageFormatError, match="nocs: unsupported encoding '32FC1'"):
        nocs_from_image(d)
    with pytest.raises(ImageFormatError, match="mask: unsupported encoding"):
        mask_from_image(d)
    short = Image(height=H, width=W, encoding="32FC1", step=W * 4, data=bytes(W * 4 * H - 1))
    with pytest.raises(ImageFormatError, match="step\\*height needs"):
        depth_from_image(short)
    narrow = Image(height=H, width=W, encoding="32FC1", step=W * 4 - 1, data=bytes(W * 4 * H))
    with pytest.raises(ImageFormatError, match="shorter than width\\*channels\\*size"):
        depth_from_image(narrow)
    with pytest.raises(ImageFormatError, match="empty image"):
        depth_from_image(Image(encoding="32FC1"))
    with pytest.raises(ImageFormatError, match="do not fit"):
        mask_to_image(np.array([[300]]), "mono8")
    with pytest.raises(ImageFormatError, match="unsupported"):
        depth_to_image(depth_sample(rng), "mono8")


def test_a_frame_is_three_images_of_one_size_in_this_packages_nocs_convention(rng):
    """The node's conversion of a matched set: depth in metres from 16UC1 millimetres, the NOCS
    dataset's z flipped (pixels without a prediction stay zero), sizes checked."""
    depth = np.round(depth_sample(rng) * 1000)
    depth[0, 0] = 0
    nocs = nocs_sample(rng).astype(np.float32)
    mask = rng.integers(0, 4, (H, W)).astype(np.uint8)
    msgs = (depth_to_image(depth / 1000, "16UC1"), nocs_to_image(nocs), mask_to_image(mask))
    d, p, m = frame_from_images(*msgs, depth_scale=0.001, nocs_convention="nocs_dataset")
    assert np.isnan(d[0, 0]) and np.allclose(d[1:], depth[1:] / 1000, atol=1e-6)
    assert np.allclose(p[2:, :, 2], 1 - nocs[2:, :, 2]) and np.all(p[1, 1] == 0)
    assert np.array_equal(m, mask)
    assert np.array_equal(frame_from_images(*msgs)[1], nocs)  # 'fcop': as sent
    small = mask_to_image(mask[:-1])
    sizes = r"depth \(11, 7\), nocs \(11, 7\), mask \(11, 6\)"
    with pytest.raises(ImageSizeMismatch, match=sizes):
        frame_from_images(msgs[0], msgs[1], small)
    with pytest.raises(ImageFormatError, match="nocs: unsupported encoding"):
        frame_from_images(msgs[0], msgs[0], msgs[2])


def test_built_image_survives_serialisation(rng):
    msg = nocs_to_image(nocs_sample(rng), "32FC3")
    back = deserialize_message(serialize_message(msg), Image)
    np.testing.assert_array_equal(nocs_from_image(back), nocs_from_image(msg))
    assert isinstance(msg.data, array.array) and msg.step == W * 12


def test_camera_info_rep104():
    h = Header(frame_id="cam_optical")
    h.stamp.sec, h.stamp.nanosec = 12, 345
    info = camera_info(612.5, 319.5, 239.5, 640, 480, h)
    assert info.header.frame_id == "cam_optical" and info.header.stamp.nanosec == 345
    assert info.header is not h
    assert info.width == 640 and info.height == 480 and info.distortion_model == "plumb_bob"
    np.testing.assert_array_equal(info.k, [612.5, 0, 319.5, 0, 612.5, 239.5, 0, 0, 1])
    np.testing.assert_array_equal(info.r, np.eye(3).ravel())
    np.testing.assert_array_equal(np.reshape(info.p, (3, 4)),
                                  np.column_stack([np.reshape(info.k, (3, 3)), np.zeros(3)]))
    assert list(info.d) == [0.0] * 5 and info.binning_x == info.binning_y == 0
    assert (info.roi.x_offset, info.roi.y_offset, info.roi.width, info.roi.height) == (0, 0, 0, 0)
    deserialize_message(serialize_message(info), CameraInfo)


def test_pose_and_marker_arrays():
    R = Rotation.from_euler("xyz", [10, 20, 30], degrees=True).as_matrix()
    objs = [ObjectPose(3, R, np.array([0.1, 0.2, 1.5]), 0.3, 1.0, 0.0, 100),
            ObjectPose(7, np.eye(3), np.array([-0.1, 0.0, 0.9]), 0.15, 1.0, 0.0, 100)]
    h = Header(frame_id="f")
    pa = pose_array(objs, h)
    assert pa.header.frame_id == "f" and len(pa.poses) == 2
    q = pa.poses[0].orientation
    np.testing.assert_allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), R, atol=1e-12)
    assert (pa.poses[0].position.x, pa.poses[0].position.z) == (0.1, 1.5)
    ma = marker_array(objs, h)
    assert ma.markers[0].action == ma.markers[0].DELETEALL
    assert [m.id for m in ma.markers[1:]] == [3, 7]
    assert abs(ma.markers[1].scale.x - 0.3 / np.sqrt(3)) < 1e-12 and ma.markers[1].color.a > 0


def test_header_from_nanoseconds_and_back():
    from msg_adapters import header_from_ns, stamp_ns, time_from_ns, time_to_ns
    ns = 1_700_000_000_123_456_789
    h = header_from_ns(ns, "cam_optical")
    assert (h.stamp.sec, h.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert h.frame_id == "cam_optical"
    assert stamp_ns(Image(header=h)) == ns and time_to_ns(time_from_ns(ns)) == ns
    assert header_from_ns(0).frame_id == ""
    assert time_to_ns(header_from_ns(999_999_999).stamp) == 999_999_999
