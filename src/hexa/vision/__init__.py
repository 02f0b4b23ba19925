"""Vision core (ROS-free): image conversion, camera model, rigid registration, markers, detector, isolation."""
