"""Render what the shipped Foxglove layout shows from a running `hexa view`: the two JPEG camera channels, the
residual force with its thresholds, the servo-space residual, min Ω and the /diagnostics levels, as one PNG.

Usage: python scripts/view_figure.py [ws://127.0.0.1:8765] [docs/img/view_layout.png] [seconds]
"""
from __future__ import annotations

import sys

import numpy as np


def main(argv: list[str]) -> int:
    import cv2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hexa.foxglove_client import FoxgloveClient

    url = argv[0] if argv else "ws://127.0.0.1:8765"
    out = argv[1] if len(argv) > 1 else "docs/img/view_layout.png"
    seconds = float(argv[2]) if len(argv) > 2 else 30.0
    ns = "/hexa"
    topics = [f"{ns}/cam_top/color/image_raw/compressed", f"{ns}/cam_side/color/image_raw/compressed",
              f"{ns}/residual", f"{ns}/singularity", f"{ns}/collision", "/diagnostics"]
    with FoxgloveClient(url) as c:
        c.wait_for_topics(set(topics))
        c.subscribe(topics)
        msgs = c.messages(seconds)
    by = {t: [m for m in msgs if m.topic == t] for t in topics}
    fig = plt.figure(figsize=(13, 7.5))
    gs = fig.add_gridspec(3, 4)
    for k, cam in enumerate(("cam_top", "cam_side")):
        ax = fig.add_subplot(gs[0, 2 * k:2 * k + 2])
        frames = by[f"{ns}/{cam}/color/image_raw/compressed"]
        if frames:
            bgr = cv2.imdecode(np.frombuffer(frames[-1].data.data, np.uint8), cv2.IMREAD_COLOR)
            ax.imshow(bgr[:, :, ::-1])
        ax.set_title(f"Image: {ns}/{cam} (JPEG, {len(frames)} frames)")
        ax.axis("off")
    res = by[f"{ns}/residual"]
    t0 = res[0].log_time_ns if res else 0
    t = np.array([(m.log_time_ns - t0) * 1e-9 for m in res])
    ax = fig.add_subplot(gs[1, 0:2])
    for i, a in enumerate("xyz"):
        ax.plot(t, [m.data["wrench"]["force"][a] for m in res], label=f"r f{a}")
        ax.plot(t, [m.data["threshold"][i] for m in res], "--", lw=0.8, label=f"threshold f{a}")
    ax.set_title("Plot: residual force (N) and thresholds")
    ax.legend(fontsize=6, ncol=2)
    ax = fig.add_subplot(gs[1, 2:4])
    for i in range(6):
        ax.plot(t, [m.data["servo_torque"][i] for m in res], label=f"servo {i + 1}")
    if res:
        ax.axhline(res[-1].data["servo_threshold"][0], ls="--", c="k", lw=0.8, label="servo threshold")
    ax.set_title("Plot: residual servo torque (N·m)")
    ax.legend(fontsize=6, ncol=3)
    ax = fig.add_subplot(gs[2, 0:2])
    ax.step(t, [int(m.data["in_collision"]) for m in res], where="post")
    for m in by[f"{ns}/collision"]:
        ax.axvline((m.log_time_ns - t0) * 1e-9, c="r", lw=0.8)
    ax.set_title("State: in_collision (red: collision events)")
    ax.set_xlabel("s")
    ax = fig.add_subplot(gs[2, 2])
    sg = by[f"{ns}/singularity"]
    ax.plot([(m.log_time_ns - t0) * 1e-9 for m in sg], [np.degrees(m.data["min_omega"]) for m in sg])
    ax.set_title("Plot: singularity min Ω (deg)")
    ax = fig.add_subplot(gs[2, 3])
    last: dict[str, int] = {}
    for m in by["/diagnostics"]:
        for s in m.data["status"]:
            last[s["name"]] = int(s["level"])
    names = sorted(last)[:12]
    ax.barh(range(len(names)), [1] * len(names), color=[("g", "orange", "r", "grey")[min(last[n], 3)] for n in names])
    ax.set_yticks(range(len(names)), [n[-38:] for n in names], fontsize=6)
    ax.set_xticks([])
    ax.set_title("/diagnostics (green OK, orange WARN, red ERROR)")
    fig.suptitle(f"hexa view → Foxglove layout, from {url} ({seconds:g} s wall time of the simulated graph)")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    print(f"{out}: {len(res)} residuals, {len(sg)} singularity, {sum(len(v) for v in by.values())} messages")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
