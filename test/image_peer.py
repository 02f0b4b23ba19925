"""Peer for the DDS profile test: `pub N` sends N 640x480 rgb8 frames at 30 Hz with sensor-data QoS;
`sub SECONDS` counts the frames it receives intact and prints the count."""
from __future__ import annotations

import sys
import time

from hexa_bringup.rosenv import apply_defaults


def main() -> int:
    if "--no-profile" not in sys.argv:
        apply_defaults()
    import numpy as np
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    mode = sys.argv[1]
    rclpy.init()
    node = rclpy.create_node(f"image_{mode}")
    try:
        if mode == "pub":
            n = int(sys.argv[2])
            pub = node.create_publisher(Image, "/img", qos_profile_sensor_data)
            while pub.get_subscription_count() == 0:
                rclpy.spin_once(node, timeout_sec=0.05)
            time.sleep(0.5)
            msg = Image(height=480, width=640, encoding="rgb8", step=640 * 3)
            base = np.arange(480 * 640 * 3, dtype=np.uint32).astype(np.uint8)
            for k in range(n):
                msg.header.frame_id = str(k)
                msg.data = np.roll(base, k).tobytes()
                pub.publish(msg)
                time.sleep(1 / 30)
            time.sleep(0.5)
        else:
            count = 0

            def on_img(m):
                nonlocal count
                k = int(m.header.frame_id)
                arr = np.frombuffer(bytes(m.data), dtype=np.uint8)
                ok = arr.size == 480 * 640 * 3 and arr[k % arr.size] == 0  # np.roll moved element 0 to index k
                count += int(ok)

            node.create_subscription(Image, "/img", on_img, qos_profile_sensor_data)
            end = time.monotonic() + float(sys.argv[2])
            while time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.05)
            print(count, flush=True)
    finally:
        node.destroy_node()
        rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
