"""Camera sources without ROS: PNG-folder pairs in order and looped, their intrinsics, a bag's camera topics, and
sources that cannot start naming what is missing."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from hexa.vision.camera import CameraModel, intrinsics
from hexa.vision.sources import BagSource, FolderSource, SourceError, depth_to_mm, folder_pairs


def _write_pairs(folder, n: int) -> None:
    for k in range(n):
        rgb = np.full((6, 8, 3), (10 * k, 0, 255), np.uint8)
        cv2.imwrite(str(folder / f"color_{k:04d}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(folder / f"depth_{k:04d}.png"), np.full((6, 8), 500 + k, np.uint16))


def test_folder_pairs_play_in_order_and_loop(tmp_path) -> None:
    _write_pairs(tmp_path, 2)
    (tmp_path / "color_0009.png").write_bytes(b"")          # no depth partner: not a pair
    model = CameraModel(intrinsics(8, 6, 1.0), 8, 6)
    src = FolderSource(tmp_path, "cam_top", loop=True, fallback=lambda: model)
    assert len(src.pairs) == 2 and src.model is model
    seen = [src.next() for _ in range(3)]
    assert [int(d[0, 0]) for _, d in seen] == [500, 501, 500]
    assert seen[1][0][0, 0].tolist() == [10, 0, 255] and seen[1][1].dtype == np.uint16
    once = FolderSource(tmp_path, "cam_top", loop=False, fallback=lambda: model)
    assert once.next() is not None and once.next() is not None and once.next() is None


def test_a_looped_folder_decodes_each_pair_once_within_its_cache_budget(tmp_path) -> None:
    _write_pairs(tmp_path, 3)
    model = CameraModel(intrinsics(8, 6, 1.0), 8, 6)
    pair_bytes = 6 * 8 * 3 + 6 * 8 * 2
    src = FolderSource(tmp_path, "cam_top", loop=True, fallback=lambda: model, cache_bytes=2 * pair_bytes)
    assert FolderSource(tmp_path, "cam_top", loop=False, fallback=lambda: model).cache_bytes == 0   # played once
    first = [src.next() for _ in range(3)]
    for f in tmp_path.glob("*_000[01].png"):      # the first two pairs are cached, the third is not
        f.unlink()
    again = [src.next() for _ in range(2)]
    assert [int(d[0, 0]) for _, d in again] == [500, 501]
    assert all(a is b for a, b in zip(again[0], first[0]))
    assert not again[0][0].flags.writeable                   # shared with later cycles: read-only
    assert first[2][0].flags.writeable                       # over the budget: decoded each time
    (tmp_path / "depth_0002.png").unlink()
    with pytest.raises(SourceError):
        src.next()


def test_camera_info_yaml_overrides_the_fallback_intrinsics(tmp_path) -> None:
    _write_pairs(tmp_path, 1)
    (tmp_path / "camera_info.yaml").write_text("width: 8\nheight: 6\nk: [5, 0, 4, 0, 5, 3, 0, 0, 1]\n")
    src = FolderSource(tmp_path, "cam_top", fallback=lambda: pytest.fail("fallback used"))
    assert (src.model.width, src.model.height, src.model.K[0, 0]) == (8, 6, 5.0)


def test_sources_that_cannot_start_say_what_is_missing(tmp_path) -> None:
    with pytest.raises(SourceError, match="does not exist"):
        folder_pairs(tmp_path / "nope")
    with pytest.raises(SourceError, match="holds no color_<n>.png"):
        FolderSource(tmp_path, "cam_top")
    _write_pairs(tmp_path, 1)
    with pytest.raises(SourceError, match="no camera_info.yaml .* no intrinsics for cam_top"):
        FolderSource(tmp_path, "cam_top", fallback=lambda: {}["cam_top"])
    with pytest.raises(SourceError, match="bag .* does not exist"):
        BagSource(tmp_path / "no_bag", "cam_top")
    assert issubclass(SourceError, ValueError)               # a configuration error for hexa_ros.node


def test_a_bag_source_yields_one_cameras_topics(tmp_path) -> None:
    recorder = pytest.importorskip("hexa_bringup.bag")
    bag = tmp_path / "cams"
    with recorder.BagRecorder(bag) as rec:
        for topic, typ in (("/hexa/cam_top/color/image_raw", "sensor_msgs/msg/Image"),
                           ("/hexa/cam_side/color/image_raw", "sensor_msgs/msg/Image"),
                           ("/hexa/cam_top/color/camera_info", "sensor_msgs/msg/CameraInfo")):
            rec.add_topic(topic, typ, reliable=False)
        for k in range(3):
            rec.write("/hexa/cam_top/color/camera_info", k, b"info%d" % k)
            rec.write("/hexa/cam_side/color/image_raw", k, b"side")
            rec.write("/hexa/cam_top/color/image_raw", k, b"top%d" % k)
    src = BagSource(bag, "cam_top", rate=0.0, loop=False)
    got = list(src.messages())
    assert [(key, cdr) for key, _t, cdr in got] == [
        ("color/camera_info", b"info0"), ("color/image_raw", b"top0"), ("color/camera_info", b"info1"),
        ("color/image_raw", b"top1"), ("color/camera_info", b"info2"), ("color/image_raw", b"top2")]
    looping = BagSource(bag, "cam_top", rate=0.0, loop=True)
    it = looping.messages()
    first = [next(it) for _ in range(8)]                     # past the end: from the start again
    looping.stop()
    assert first[6][2] == b"info0" and list(it) == []


def test_depth_units_become_rounded_clipped_millimetres() -> None:
    raw = np.array([[0, 1000, 65535]], np.uint16)
    assert depth_to_mm(raw, 0.25).tolist() == [[0, 250, 16384]]
    assert depth_to_mm(raw, 2.0).tolist() == [[0, 2000, 65535]]
