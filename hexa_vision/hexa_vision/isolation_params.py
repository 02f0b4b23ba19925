"""The isolation node's parameters (hexa_ros.node.Param): defaults, units, ranges; all read-only (start-up)."""
from __future__ import annotations

from hexa_ros.node import DESCRIPTION, DESCRIPTION_PARAM, Param

#: the scheduler's settings (IsolationScheduler's keyword arguments of the same names)
SCHEDULER = {"background_delay": Param(1.0, "s of frames before the backgrounds", range=(0.0, 60.0)),
             "max_pose_age": Param(0.2, "s; largest gap to interpolate plate poses across", range=(0.0, 5.0)),
             "pose_wait": Param(0.5, "wall s a pair waits for a camera pose at/after its stamp", range=(0.0, 10.0)),
             "pose_expiry": Param(3.0, "wall s after which a pair without a pose is dropped", range=(0.0, 60.0)),
             "max_pending": Param(8, "frame pairs queued while waiting for poses", range=(1, 1000)),
             "eval_period": Param(0.1, "s of frame time between evaluated pairs during a collision",
                                  range=(0.0, 10.0)),
             "onset_pose_wait": Param(0.0, "wall s the onset pair waits for the camera pose of its stamp",
                                      range=(0.0, 10.0)),
             "onset_pose_age": Param(0.05, "s; oldest camera pose the onset pair takes, no estimate",
                                     range=(0.0, 5.0))}
PARAMETERS = {DESCRIPTION: DESCRIPTION_PARAM, **SCHEDULER,
              "debug_image": Param(True, "publish the debug mosaic of onset pairs"),
              "frame_history": Param(6, "images of each topic waiting in the reader between takes", range=(1, 100)),
              "coarse_margin": Param(0.008, "m around the drawn robot when the pose is carried forward",
                                     range=(0.0, 0.1))}
